"""The folders ``slime web`` may read (and the few it may write): every path the API takes is a folder's
name and a path relative to it, resolved here and refused when it leaves the folder."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from ..io import IMAGE_EXTS

MAX_LISTED = 5000  # image files listed per folder


class FolderError(Exception):
    """A path the server refuses or cannot find; ``status`` is the HTTP status to answer with."""

    def __init__(self, message: str, status: int = 400) -> None:
        super().__init__(message)
        self.status = status


@dataclass(frozen=True)
class Root:
    """A folder the server serves: its name in the API, its path, and what it holds ("images",
    "uploads" or "annotations")."""

    name: str
    path: Path
    kind: str

    def resolve(self, relative: str, must_exist: bool = True) -> Path:
        """The file at ``relative`` (a path inside this folder, ``/``-separated).

        Raises:
            FolderError: an absolute path, one that leaves the folder (``..``, a link to outside), or a missing
                file (404).
        """
        if not isinstance(relative, str) or not relative.strip() or "\0" in relative:
            raise FolderError("give a file path relative to the folder")
        if relative.startswith(("/", "\\")) or Path(relative).is_absolute() or ":" in Path(relative).parts[0]:
            raise FolderError(f"{relative!r} is an absolute path: give a path relative to the folder "
                              f"{self.name!r}", 403)
        try:
            base = self.path.resolve()
            target = (base / relative).resolve()
        except (OSError, RuntimeError, ValueError) as error:
            raise FolderError(f"cannot resolve {relative!r}: {error}") from None
        if not target.is_relative_to(base):
            raise FolderError(f"{relative!r} lies outside the folder {self.name!r}: the server serves only the "
                              "files under the folders it was given", 403)
        if must_exist and not target.is_file():
            raise FolderError(f"no file {relative!r} in the folder {self.name!r}", 404)
        return target

    def images(self) -> tuple[list[str], bool]:
        """The image files under the folder (relative, sorted, sub-folders included; hidden ones skipped) and
        whether the list was cut at :data:`MAX_LISTED`."""
        found: list[str] = []
        base = self.path.resolve()
        if not base.is_dir():
            return found, False
        for folder, subfolders, files in os.walk(base):
            subfolders[:] = sorted(d for d in subfolders if not d.startswith("."))
            for name in sorted(files):
                if not name.startswith(".") and Path(name).suffix.lower() in IMAGE_EXTS:
                    found.append((Path(folder) / name).relative_to(base).as_posix())
                    if len(found) >= MAX_LISTED:
                        return found, True
        return found, False


class Roots:
    """The served folders by name."""

    def __init__(self, roots: list[Root]) -> None:
        self.by_name = {root.name: root for root in roots}

    def __iter__(self):
        return iter(self.by_name.values())

    def get(self, name: str) -> Root:
        root = self.by_name.get(name)
        if root is None:
            raise FolderError(f"unknown folder {name!r}: the server serves {', '.join(self.by_name) or 'none'}",
                              404)
        return root

    def file(self, ref: dict | None) -> Path:
        """The existing file of a ``{"root": name, "path": relative}`` reference."""
        if not isinstance(ref, dict) or not isinstance(ref.get("root"), str) or not isinstance(ref.get("path"), str):
            raise FolderError('an image is {"root": folder name, "path": path relative to it}')
        return self.get(ref["root"]).resolve(ref["path"])

    def find(self, name: str, kinds: tuple[str, ...] = ("images",)) -> dict | None:
        """The first ``{"root", "path"}`` of ``kinds`` folders holding ``name`` (a run's image name)."""
        for root in self:
            if root.kind in kinds:
                try:
                    root.resolve(name)
                except FolderError:
                    continue
                return {"root": root.name, "path": Path(name).as_posix()}
        return None

    def reference(self, path: Path) -> dict | None:
        """``{"root", "path"}`` of a file under one of the folders, None when it is under none."""
        path = path.resolve()
        for root in self:
            base = root.path.resolve()
            if path.is_relative_to(base):
                return {"root": root.name, "path": path.relative_to(base).as_posix()}
        return None


def unique_names(paths: list[Path], prefix: str) -> list[str]:
    """Short API names for folders: their base names, made unique with a number (``prefix`` when empty)."""
    names: list[str] = []
    for path in paths:
        stem = Path(path).resolve().name or prefix
        name, k = stem, 2
        while name in names or name in ("uploads", "annotations"):
            name, k = f"{stem}-{k}", k + 1
        names.append(name)
    return names
