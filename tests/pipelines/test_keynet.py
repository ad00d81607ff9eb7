"""The Key.Net base pipeline (kornia's Key.Net + AffNet + OriNet + TFeat + AdaLAM) and Slimed Key.Net."""

import numpy as np
import pytest
import torch
from conftest import DATA, require, require_weights

from slime_match.config import make_config
from slime_match.errors import ConfigError
from slime_match.eval.metrics import correct_matches_homography
from slime_match.io import load_image
from slime_match.matcher import Matcher
from slime_match.pipelines import BaseConfig, KeyNetPipeline
from slime_match.slime import refine as slime_refine


@pytest.fixture(scope="module")
def graf_small():
    """graf 1 -> 3 at 0.4x resolution (320 x 256) with its exact GT homography."""
    import cv2

    require_weights("keynet", "affnet", "orinet", "tfeat")
    folder = require(DATA / "oxford_graf")
    a, b = load_image(folder / "img1.png"), load_image(folder / "img3.png")
    s = np.diag([0.4, 0.4, 1.0])
    s[:2, 2] = -0.3  # pixel-centre convention of a 0.4x downscale
    small = [cv2.resize(im, (320, 256), interpolation=cv2.INTER_AREA) for im in (a, b)]
    return small[0], small[1], s @ np.loadtxt(folder / "H1to3p") @ np.linalg.inv(s)


@pytest.mark.parametrize(
    "options", [{"descriptor": "rootsift"}, {"shape": "baumberg"}, {"orientation": "gradient"}]
)
def test_keynet_rejects_options_it_cannot_honour(options):
    config = BaseConfig(name="keynet", **{"descriptor": "tfeat", **options})
    with pytest.raises(ConfigError, match="keynet"):
        KeyNetPipeline(config, torch.device("cpu"))


def test_keynet_features_and_fixed_orientation(graf_small):
    a, _, _ = graf_small
    pipeline = KeyNetPipeline(BaseConfig(name="keynet", descriptor="tfeat"), torch.device("cpu"))
    context = pipeline.prepare(a)
    features = pipeline.detect(context)
    assert 50 < len(features) < 8000  # kornia's zero padding up to max_keypoints is dropped
    assert (features.response > 0).all() and features.descriptors.shape == (len(features), 128)
    assert not torch.equal(features.laf, features.shape_laf)  # OriNet turned the upright frames
    fixed = pipeline.describe_fixed(context, features, 0.7)
    assert torch.allclose(fixed.angle, torch.full((len(features),), 0.7), atol=1e-5)
    assert torch.allclose(fixed.xy, features.xy) and torch.isfinite(fixed.descriptors).all()
    regions = pipeline.detect_regions(context)
    assert torch.equal(regions.shape_laf, features.shape_laf) and regions.descriptors.shape == (len(features), 0)
    assert not pipeline.own_frames_upright()


def test_upright_keynet_fixed_descriptors_at_angle_0_are_its_own(graf_small):
    """What lets Slime reuse an upright base's first block-pair run for Sec. 3.3 (``own_frames_upright``)."""
    pipeline = KeyNetPipeline(BaseConfig(name="keynet", descriptor="tfeat", upright=True), torch.device("cpu"))
    context = pipeline.prepare(graf_small[0])
    features = pipeline.detect(context)
    fixed = pipeline.describe_fixed(context, features, 0.0)
    assert pipeline.own_frames_upright() and len(features) > 50
    assert torch.equal(fixed.laf, features.laf) and torch.equal(fixed.descriptors, features.descriptors)


def test_keynet_descriptors_follow_kornia_patch_convention(graf_small):
    """Our patch stages on Key.Net's frames describe what kornia's LAFDescriptor does (magnification 1 on
    kornia's LAFs); a wrong magnification (1.5) drops the median cosine to ~0.7."""
    import kornia.feature as KF

    from slime_match.features.weights import load_model

    a, _, _ = graf_small
    pipeline = KeyNetPipeline(BaseConfig(name="keynet", descriptor="tfeat"), torch.device("cpu"))
    context = pipeline.prepare(a)
    features = pipeline.detect(context)
    kornia_descriptor = KF.LAFDescriptor(load_model("tfeat"), patch_size=32, grayscale_descriptor=True).eval()
    with torch.no_grad():
        reference = torch.nn.functional.normalize(kornia_descriptor(context.grey, features.laf[None])[0], dim=1)
    cosine = (reference * features.descriptors).sum(1)
    assert cosine.median() > 0.98 and (cosine > 0.9).float().mean() > 0.9, (cosine.median(), cosine.min())


def test_keynet_and_slimed_keynet_on_a_real_pair(graf_small, monkeypatch):
    a, b, h = graf_small
    base = Matcher(make_config("keynet", descriptor="tfeat", device="cpu"))(a, b)
    ok_base = correct_matches_homography(base.keypoints0, base.keypoints1, h)
    assert ok_base.sum() > 50 and ok_base.mean() > 0.9, (int(ok_base.sum()), ok_base.mean())

    calls = []
    monkeypatch.setattr(slime_refine, "global_dtm", lambda *args, **kw: calls.append(1))
    slime = Matcher(make_config("slime-keynet", descriptor="tfeat", device="cpu"))(a, b)
    assert not calls  # the paper's Slimed Key.Net has no final global filter
    ok = correct_matches_homography(slime.keypoints0, slime.keypoints1, h)
    assert ok.mean() > 0.9 and ok.sum() > ok_base.sum(), (int(ok.sum()), ok.mean(), int(ok_base.sum()))
    counts = slime.summary["counts"]
    assert counts["block_planes"] > 0 and counts["tile_matches"] > 0 and counts["final"] == len(slime)
    assert len(np.unique(np.hstack([slime.keypoints0, slime.keypoints1]), axis=0)) == len(slime)
