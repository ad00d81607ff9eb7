"""Find and load the network weights (AffNet, OriNet, HardNet, HardTFeat, TFeat, Key.Net), as kornia models.

Weights live in kornia's torch-hub cache, ``<TORCH_HOME>/hub/checkpoints`` (``torch.hub.get_dir()``), or in
an explicit ``weights_dir`` (a torch-home-like folder with ``hub/checkpoints``, or the checkpoint folder
itself). Loading goes through kornia's own downloader with kornia's URLs (HardTFeat, which kornia does not
list, from the AffNet repository), so a missing file is fetched into that folder when the network allows it
(e.g. HardNet's ``checkpoint_liberty_with_aug.pth``); when it
does not, :class:`~slime_match.errors.WeightsNotFoundError` names the alternatives. There is
no silent fallback.
"""

from __future__ import annotations

import importlib
import logging
import socket
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlparse

import torch
from torch import nn

from slime_match.errors import ConfigError, WeightsNotFoundError

logger = logging.getLogger("slime_match")


# TFeat's architecture trained with HardNet's loss by the AffNet authors (MIT), at the root of their repository
HARDTFEAT_URL = "https://github.com/ducha-aiki/affnet/raw/master/HardTFeat.pth"


def hardtfeat_as_tfeat(state: dict) -> dict:
    """HardTFeat's state dict as kornia ``TFeat``'s: its two convolutions ``features.0`` and ``features.3`` are
    TFeat's ``features.1`` and ``features.4``, and its 8x8 convolution ``classifier.1`` over the (64, 8, 8) map is
    TFeat's ``Linear(4096, 128)`` (the same products, weights (128, 64, 8, 8) flattened as TFeat flattens the
    map). The per-patch normalisation by mean and std is TFeat's ``InstanceNorm2d``."""
    head = state["classifier.1.weight"]
    return {"features.1.weight": state["features.0.weight"], "features.1.bias": state["features.0.bias"],
            "features.4.weight": state["features.3.weight"], "features.4.bias": state["features.3.bias"],
            "descr.0.weight": head.reshape(head.shape[0], -1), "descr.0.bias": state["classifier.1.bias"]}


@dataclass(frozen=True)
class _Spec:
    """Where a model's weights come from and how kornia loads them."""

    module: str  # kornia module holding the ``urls`` dict and the class
    url_key: str  # key into the URLs dict ("" when the attribute is the URL list itself)
    cls: str
    file: str  # cache file name (basename of kornia's first URL)
    state_key: str | None  # checkpoint entry holding the state dict (None: the checkpoint is the state dict)
    strict: bool
    alternatives: str
    urls_attr: str = "urls"  # module attribute holding the URLs (a dict indexed by url_key, or the URL list)
    own_urls: tuple[str, ...] = ()  # where kornia knows no URL for these weights: ours
    convert: Callable[[dict], dict] | None = None  # the checkpoint's state dict as the kornia class's


SPECS: dict[str, _Spec] = {
    "hardnet": _Spec(
        "kornia.feature.hardnet", "liberty_aug", "HardNet", "checkpoint_liberty_with_aug.pth", "state_dict", True,
        "--descriptor hardtfeat or tfeat (other weights) or rootsift (weight-free)",
    ),
    "tfeat": _Spec(
        "kornia.feature.tfeat", "liberty", "TFeat", "tfeat-liberty.params", None, True,
        "--descriptor rootsift (weight-free), or hardtfeat / hardnet (other weights)",
    ),
    "hardtfeat": _Spec(
        "kornia.feature.tfeat", "", "TFeat", "HardTFeat.pth", "state_dict", True,
        "--descriptor tfeat (other weights) or rootsift (weight-free)",
        own_urls=(HARDTFEAT_URL,), convert=hardtfeat_as_tfeat,
    ),
    "affnet": _Spec(
        "kornia.feature.affine_shape", "affnet", "LAFAffNetShapeEstimator", "AffNet.pth", "state_dict", False,
        "--shape baumberg (weight-free)",
    ),
    "orinet": _Spec(
        "kornia.feature.orientation", "orinet", "OriNet", "OriNet.pth", "state_dict", False,
        "--orientation gradient|upright (weight-free)",
    ),
    "keynet": _Spec(
        "kornia.feature.keynet", "", "KeyNet", "keynet_pytorch.pth", "state_dict", True,
        "the hz+ or rootsift base pipelines", urls_attr="KeyNet_URL",
    ),
}


def _spec(name: str) -> _Spec:
    if name not in SPECS:
        raise ConfigError(f"unknown weights {name!r}; known: {', '.join(SPECS)}")
    return SPECS[name]


def checkpoint_dir(weights_dir: str | Path | None = None) -> Path:
    """Folder holding the checkpoint files.

    Args:
        weights_dir: a torch-home-like folder (``hub/checkpoints`` inside) or a checkpoint folder;
            None for kornia's cache, ``torch.hub.get_dir()/checkpoints`` (follows ``TORCH_HOME``).

    Returns:
        The checkpoint folder (may not exist yet).
    """
    if weights_dir is None:
        return Path(torch.hub.get_dir()) / "checkpoints"
    root = Path(weights_dir).expanduser()
    for sub in (root / "hub" / "checkpoints", root / "checkpoints"):
        if sub.is_dir():
            return sub
    return root


def weights_path(name: str, weights_dir: str | Path | None = None) -> Path:
    """Path where the checkpoint of model ``name`` is (or would be) cached."""
    return checkpoint_dir(weights_dir) / _spec(name).file


def is_cached(name: str, weights_dir: str | Path | None = None) -> bool:
    """Whether the checkpoint of model ``name`` is on disk (no network access)."""
    return weights_path(name, weights_dir).is_file()


def _download_urls(spec: _Spec) -> list[str]:
    if spec.own_urls:
        return list(spec.own_urls)
    """kornia's URLs for a model, in the order its downloader tries them."""
    urls = getattr(importlib.import_module(spec.module), spec.urls_attr)
    urls = urls[spec.url_key] if spec.url_key else urls
    return [urls] if isinstance(urls, str) else list(urls)


def unresolved_hosts(urls: list[str]) -> list[str] | None:
    """The URLs' host names when none of them resolves (no network or no DNS), else None."""
    hosts = list(dict.fromkeys(urlparse(url).hostname or "" for url in urls))
    for host in hosts:
        try:
            socket.getaddrinfo(host, 443)
            return None
        except (OSError, UnicodeError):
            continue
    return hosts


def load_state_dict(name: str, weights_dir: str | Path | None = None, retry_offline: bool = True) -> dict:
    """Checkpoint of model ``name`` through kornia's downloader (cache hit, else download).

    Args:
        name: "hardnet", "hardtfeat", "tfeat", "affnet", "orinet" or "keynet".
        weights_dir: see :func:`checkpoint_dir`.
        retry_offline: when no download host resolves, still let kornia try (it retries such failures for
            up to about 10 s, in case the network is back); False fails at once.

    Returns:
        The loaded checkpoint (CPU tensors).

    Raises:
        WeightsNotFoundError: not cached and not downloadable; the message names the alternatives.
    """
    spec = _spec(name)
    folder = checkpoint_dir(weights_dir)
    download = importlib.import_module("kornia.core.download")
    urls = _download_urls(spec)
    if not (folder / spec.file).is_file():
        hosts = None if retry_offline else unresolved_hosts(urls)
        if hosts is not None:
            raise _not_found(name, spec, folder, f"no download host resolves: {', '.join(hosts)}; offline?")
        logger.info("%s weights not in %s: trying to download them", name, folder)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return download.load_state_dict_from_url(
                urls, model_dir=str(folder), file_name=spec.file, map_location=torch.device("cpu")
            )
    except Exception as exc:
        why = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
        raise _not_found(name, spec, folder, why) from exc


def _not_found(name: str, spec: _Spec, folder: Path, why: str) -> WeightsNotFoundError:
    return WeightsNotFoundError(
        f"{name} weights '{spec.file}' are not in {folder} and could not be downloaded ({why}). Put the file "
        f"there (or set TORCH_HOME / weights_dir), or use an alternative: {spec.alternatives}")


def load_model(name: str, weights_dir: str | Path | None = None, device: str | torch.device = "cpu") -> nn.Module:
    """Kornia model ``name`` with its pretrained weights, in eval mode on ``device``.

    Raises:
        WeightsNotFoundError: see :func:`load_state_dict`.
    """
    spec = _spec(name)
    checkpoint = load_state_dict(name, weights_dir)
    model = getattr(importlib.import_module(spec.module), spec.cls)(pretrained=False)
    state = checkpoint[spec.state_key] if spec.state_key is not None else checkpoint
    state = spec.convert(state) if spec.convert is not None else state
    model.load_state_dict(state, strict=spec.strict)
    return model.eval().to(device)
