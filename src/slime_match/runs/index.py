"""A run folder's bookkeeping: its configuration (run.json), one record file per finished pair (records/) and
the index of every pair (pairs.json), rebuilt from the records.

Each record is written atomically (a temporary file, then a rename) by the process that finished its pair, so
processes matching different pairs of one run folder at once (shards of a job array) never overwrite each
other's records; each rebuilds the index at its end, and the last rebuild lists every record.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

from .. import __version__
from ..config import MatchConfig
from ..errors import ConfigError
from ..io import jsonable, save_json
from .outputs import is_complete, remove_pair_outputs
from .pair_tasks import PairJob, finished_counts, pair_record

INDEX_FILE = "pairs.json"
RUN_FILE = "run.json"
RECORDS_FOLDER = "records"
REBUILDS = 10  # at most, by one call of write_index


def claim_run_folder(out: Path, config: MatchConfig, overwrite: bool) -> bool:
    """Record the configuration in ``out/run.json``; refuse to resume a run made with another one.

    The file is created only where none exists (a hard link of a complete file), so that of processes starting
    one run folder at once with different configurations, all but the first are refused.

    Returns:
        Whether ``overwrite`` replaced the record of a run made with another configuration.

    Raises:
        ConfigError: ``out`` holds a run made with another configuration (and ``overwrite`` is False).
    """
    current = {"slime_match_version": __version__, "config": jsonable(config.to_dict())}
    run_file = out / RUN_FILE
    if overwrite:
        previous = json.loads(run_file.read_text()).get("config") if run_file.is_file() else current["config"]
        save_json(run_file, current)
        return previous != current["config"]
    if _create(run_file, current):
        return False
    previous = json.loads(run_file.read_text()).get("config")
    if previous != current["config"]:
        changed = sorted(_differences(previous or {}, current["config"]))
        raise ConfigError(f"{out} holds a run made with another configuration (differs in: "
                          f"{', '.join(changed) or 'everything'}): use another output folder or --overwrite")
    return False


def _create(path: Path, content: dict[str, Any]) -> bool:
    """Write ``content`` to ``path`` as JSON unless the file exists; whether it was written."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, staged = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".new")
    os.close(fd)
    try:
        save_json(staged, content)
        try:
            os.link(staged, path)
        except FileExistsError:
            return False
        except OSError:  # a file system without hard links: not exclusive, still never half-written
            if path.exists():
                return False
            os.replace(staged, path)
        return True
    finally:
        Path(staged).unlink(missing_ok=True)


def _differences(a: dict, b: dict, prefix: str = "") -> list[str]:
    """Dotted keys whose values differ between two nested dicts."""
    keys = []
    for key in sorted(set(a) | set(b)):
        va, vb = a.get(key), b.get(key)
        if isinstance(va, dict) and isinstance(vb, dict):
            keys += _differences(va, vb, f"{prefix}{key}.")
        elif va != vb:
            keys.append(prefix + key)
    return keys


def drop_other_pairs(out: Path, jobs: list[PairJob]) -> list[str]:
    """Remove the pairs of ``out`` that are not among ``jobs``: their records and their folders' result files
    (the folder itself when that empties it). Returns their folder names, sorted."""
    keep = {f"{job.folder}.json" for job in jobs}
    dropped = []
    for name in sorted(_records_state(out)):
        if name in keep:
            continue
        folder = out / name[: -len(".json")]
        remove_pair_outputs(folder)
        if folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()
        (out / RECORDS_FOLDER / name).unlink(missing_ok=True)
        dropped.append(folder.name)
    return dropped


def write_record(out: Path, record: dict[str, Any]) -> None:
    """Write a finished pair's record (done or failed) to ``out/records/<folder>.json``, atomically."""
    save_json(out / RECORDS_FOLDER / f"{record['folder']}.json", record)


def write_index(out: Path, jobs: list[PairJob]) -> dict[str, Any]:
    """Rebuild ``out/pairs.json`` from the records of ``jobs``, and return it.

    The index lists, in ``jobs`` order, the record of every pair that has one, else (a pair folder finished
    but its record not written) a "done" record made from the folder's summary.json; ``finished`` says
    whether every pair is listed. The index is written again while records change during its writing (at
    most ``REBUILDS`` times: a process still writing records rebuilds the index after its last one), so that
    the last of several processes finishing at once lists all their records.
    """
    read: dict[str, tuple[tuple[int, int, int], dict[str, Any]]] = {}  # file -> its state and record
    state = _records_state(out)
    for _ in range(REBUILDS):
        index = _index(out, jobs, state, read)
        save_json(out / INDEX_FILE, index)
        state, before = _records_state(out), state
        if state == before:
            break
    return index


def _records_state(out: Path) -> dict[str, tuple[int, int, int]]:
    """Each record file's name -> (inode, mtime ns, size): a rename of a new record changes it."""
    try:
        entries = list(os.scandir(out / RECORDS_FOLDER))
    except FileNotFoundError:
        return {}
    state = {}
    for entry in entries:
        if entry.name.endswith(".json") and not entry.name.startswith("."):
            try:
                stat = entry.stat()
            except FileNotFoundError:
                continue
            state[entry.name] = (stat.st_ino, stat.st_mtime_ns, stat.st_size)
    return state


def _index(out: Path, jobs: list[PairJob], state: dict[str, tuple[int, int, int]],
           read: dict[str, tuple[tuple[int, int, int], dict[str, Any]]]) -> dict[str, Any]:
    """The index of ``jobs`` from the record files in ``state``; ``read`` keeps the records read, by file, for
    the next call (a file of the same state is not read again)."""
    records = []
    for job in jobs:
        name, record = f"{job.folder}.json", None
        if name in state:
            if name not in read or read[name][0] != state[name]:
                read[name] = state[name], json.loads((out / RECORDS_FOLDER / name).read_text())
            record = read[name][1]
            if (record.get("image0"), record.get("image1")) != (job.name0, job.name1):
                record = None  # a record of another pairs file's images with the same folder name
        if record is None and is_complete(out / job.folder):
            record = pair_record(job, "done", **finished_counts(out / job.folder))
        if record is not None:
            records.append(record)
    return {"pairs": records, "finished": len(records) == len(jobs)}
