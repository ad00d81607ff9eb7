"""The `slime` command's fast paths and talk: a parser that loads no heavy module, one definition of every
option's choices, `-q`, `slime warmup`, and the error of a command whose extra is missing."""

import json
import socket
import subprocess
import sys

import pytest
from conftest import run_cli

from slime_match import __version__, choices
from slime_match.cli import build_parser
from slime_match.cli.match_options import config_of

HEAVY = ("torch", "numba", "cv2", "kornia", "scipy", "matplotlib", "numpy", "ray")
WEIGHT_FREE = ["--shape", "baumberg", "--orientation", "gradient", "--descriptor", "rootsift"]


def test_building_the_parser_and_the_version_load_no_heavy_module():
    code = ("import sys; from slime_match.cli import build_parser; build_parser(); "
            f"print(','.join(m for m in {HEAVY!r} if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == ""
    version = subprocess.run([sys.executable, "-m", "slime_match.cli", "--version"], capture_output=True, text=True,
                             check=False)
    assert version.returncode == 0 and version.stdout.strip() == f"slime-match {__version__}"


@pytest.mark.parametrize("command", [[], ["match"], ["pairs"], ["bench"], ["warmup"], ["demo"]])
def test_help_of_every_command(capsys, command):
    with pytest.raises(SystemExit) as stop:
        build_parser().parse_args([*command, "--help"])
    assert stop.value.code == 0 and "usage: slime" in capsys.readouterr().out


def test_the_parser_offers_what_the_code_accepts():
    from slime_match.config import methods
    from slime_match.features.descriptors import DESCRIPTOR_METHODS
    from slime_match.geometry.backends import estimate_geometry  # noqa: F401  (the backends load)
    from slime_match.pipelines.registry import BASE_NAMES

    assert (*choices.BUILTIN_BASES, *choices.LEARNED_BASES) == BASE_NAMES and ("slime", *BASE_NAMES) == methods()
    assert choices.DESCRIPTOR_CHOICES == ("auto", *DESCRIPTOR_METHODS)
    match = build_parser()._subparsers._group_actions[0].choices["match"]
    offered = {action.dest: tuple(action.choices) for action in match._actions if action.choices}
    from slime_match.config import PRESETS

    assert offered["ransac"] == choices.RANSAC_CHOICES and offered["method"] == ("auto", *PRESETS)
    assert set(methods()) <= set(PRESETS)  # Slime and every base alone, by its name
    assert offered["base"] == BASE_NAMES
    assert offered["detection"] == choices.DETECTIONS and offered["tile_test"] == choices.TILE_TESTS
    assert offered["quarter_turns"] == ("auto", "off")
    assert offered["rotation_fallback"] == ("auto", "edge-on", "off")
    for mode in ("off", "edge-on"):
        args = build_parser().parse_args(["match", "a.png", "b.png", "-o", "out", "--method", "slime-aliked",
                                          "--rotation-fallback", mode])
        assert config_of(args).rotation_fallback == mode


def test_bench_names_no_development_folder(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["bench", "--help"])
    assert "shared" not in capsys.readouterr().out


def test_quiet_prints_nothing_and_still_writes_the_outputs(pair, tmp_path, capsys):
    code, out, err = run_cli(capsys, "match", *pair, "-o", tmp_path, "--method", "rootsift", "--no-plot", "-q")
    assert code == 0 and out == "" and err == ""
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["counts"]["matches"] > 0
    assert 0 <= summary["seconds"]["numba_compile"] <= summary["seconds"]["total"]  # compiling, within the call


def test_quiet_and_verbose_together_are_a_usage_error(pair, tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        run_cli(capsys, "match", *pair, "-o", tmp_path, "-q", "-v")
    assert stop.value.code == 2 and "not allowed with argument" in capsys.readouterr().err


def test_demo_without_scikit_image_names_the_extra(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "skimage.data", None)  # what a missing package looks like to an import
    code, _, err = run_cli(capsys, "demo", "-o", tmp_path / "demo", *WEIGHT_FREE)
    assert code == 2 and "pip install 'slime-match[demo]'" in err and not (tmp_path / "demo").exists()


def test_pairs_on_ray_without_ray_names_the_extra(pair, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # what a missing package looks like to an import
    pairs = tmp_path / "pairs.txt"
    pairs.write_text(f"{pair[0]} {pair[1]}\n")
    code, _, err = run_cli(capsys, "pairs", pairs, "-o", tmp_path / "run", "--method", "rootsift", "--ray")
    assert code == 2 and "pip install 'slime-match[ray]'" in err and not (tmp_path / "run").exists()


def test_pairs_on_ray_at_an_address_where_nothing_answers(pair, tmp_path, capsys):
    pytest.importorskip("ray", reason="needs Ray, the ray extra (pip install 'slime-match[ray]')")
    with socket.socket() as probe:  # a port that was free a moment ago
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    pairs = tmp_path / "pairs.txt"
    pairs.write_text(f"{pair[0]} {pair[1]}\n")
    code, _, err = run_cli(capsys, "pairs", pairs, "-o", tmp_path / "run", "--method", "rootsift", "--ray",
                           f"127.0.0.1:{port}")
    assert code == 2 and f"no Ray cluster answers at 127.0.0.1:{port}" in err and not (tmp_path / "run").exists()


def test_warmup_compiles_the_loops_and_says_where_they_are_cached(capsys, monkeypatch, tmp_path):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    code, out, err = run_cli(capsys, "warmup")
    assert code == 0, err
    assert out.startswith("compiled loops ready in ") and "a Slime match of a synthetic pair with" in out
    assert "cache: numba's default" in out
    matches = int(out.split("synthetic pair with ")[1].split()[0])
    assert matches > 100  # the synthetic pair goes through every stage
