"""Result folders: a run's owned files replaced all at once, other files left alone, nothing on failure."""

import os
import signal

import pytest

from slime_match.output_folder import remove_owned_files, replacing_owned_files

OWNED = ("result.txt", "picture.png", "summary.json", "maps/*/map_*.png")


def _files(folder):
    return {p.relative_to(folder).as_posix(): p.read_text() for p in folder.rglob("*") if p.is_file()}


@pytest.fixture
def earlier(tmp_path):
    """A folder with an earlier run's files and a user's own files beside them."""
    out = tmp_path / "out"
    with replacing_owned_files(out, OWNED, last="summary.json") as staging:
        for name in ("result.txt", "picture.png", "summary.json", "maps/a/map_1.png"):
            (staging / name).parent.mkdir(parents=True, exist_ok=True)
            (staging / name).write_text(f"old {name}")
    (out / "notes.txt").write_text("mine")
    (out / "maps" / "a" / "mine.png").write_text("mine too")
    return out


def test_a_new_folder_gets_the_files_and_no_staging_is_left(earlier):
    assert _files(earlier) == {"result.txt": "old result.txt", "picture.png": "old picture.png",
                               "summary.json": "old summary.json", "maps/a/map_1.png": "old maps/a/map_1.png",
                               "notes.txt": "mine", "maps/a/mine.png": "mine too"}


def test_files_the_new_run_does_not_write_are_removed_and_others_kept(earlier):
    with replacing_owned_files(earlier, OWNED, last="summary.json") as staging:
        (staging / "result.txt").write_text("new")
        (staging / "summary.json").write_text("new summary")
        (staging / "maps" / "b").mkdir(parents=True)
        (staging / "maps" / "b" / "map_2.png").write_text("new map")
    assert _files(earlier) == {"result.txt": "new", "summary.json": "new summary", "maps/b/map_2.png": "new map",
                               "notes.txt": "mine", "maps/a/mine.png": "mine too"}
    assert sorted(p.name for p in earlier.iterdir()) == ["maps", "notes.txt", "result.txt", "summary.json"]


def test_a_sub_folder_emptied_of_owned_files_is_removed(tmp_path):
    out = tmp_path / "out"
    with replacing_owned_files(out, OWNED) as staging:
        (staging / "maps" / "a").mkdir(parents=True)
        (staging / "maps" / "a" / "map_1.png").write_text("map")
    with replacing_owned_files(out, OWNED) as staging:
        (staging / "result.txt").write_text("new")
    assert sorted(p.name for p in out.iterdir()) == ["result.txt"]


@pytest.mark.parametrize("failure", [RuntimeError("disk full"), KeyboardInterrupt()])
def test_a_failed_or_interrupted_run_leaves_the_earlier_result_intact(earlier, failure):
    before = _files(earlier)
    with pytest.raises(type(failure)), replacing_owned_files(earlier, OWNED, last="summary.json") as staging:
        (staging / "result.txt").write_text("half")
        (staging / "summary.json").write_text("half")
        raise failure
    assert _files(earlier) == before
    assert not [p for p in earlier.iterdir() if p.name.startswith(".")]  # the staging folder is gone


def test_a_staged_file_the_command_does_not_own_is_refused_before_anything_moves(earlier):
    before = _files(earlier)
    with (pytest.raises(ValueError, match="not among the owned patterns.*stray.txt"),
          replacing_owned_files(earlier, OWNED) as staging):
        (staging / "result.txt").write_text("new")
        (staging / "stray.txt").write_text("?")
    assert _files(earlier) == before


def test_remove_owned_files_leaves_the_rest(earlier, tmp_path):
    remove_owned_files(earlier, OWNED, last="summary.json")
    assert _files(earlier) == {"notes.txt": "mine", "maps/a/mine.png": "mine too"}
    remove_owned_files(tmp_path / "absent", OWNED)
    assert not (tmp_path / "absent").exists()


def test_a_ctrl_c_while_the_files_move_in_waits_until_they_are_all_in(earlier, monkeypatch):
    moves, replace = [], os.replace

    def replace_then_interrupt(source, target):
        moves.append(target)
        replace(source, target)
        if len(moves) == 1:
            os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(os, "replace", replace_then_interrupt)
    with pytest.raises(KeyboardInterrupt), replacing_owned_files(earlier, OWNED, last="summary.json") as staging:
        (staging / "result.txt").write_text("new")
        (staging / "summary.json").write_text("new summary")
    assert len(moves) == 2  # the interruption came after the first move and was acted on after the last
    assert _files(earlier) == {"result.txt": "new", "summary.json": "new summary", "notes.txt": "mine",
                               "maps/a/mine.png": "mine too"}
