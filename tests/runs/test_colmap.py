"""``slime colmap``: keypoints merged across pairs, one-to-one matches, the COLMAP database, reconstruction."""

import json
import shutil

import cv2
import numpy as np
import pytest
from conftest import DATA, export_pairs, require, run_cli, write_run_folder

from slime_match.config import make_config
from slime_match.errors import ConfigError, ImageError
from slime_match.io import load_image
from slime_match.runs.batch import match_pairs, read_pairs
from slime_match.runs.colmap import export_run, to_stored_frame, write_database
from slime_match.runs.export import PairMatches, merge_keypoints

SACRE_COEUR = DATA / "sacre_coeur"
# three views that all overlap (each pair > 4000 weight-free Slime matches) with enough baseline for COLMAP's
# initial pair (the strongest-matched triples are too close); a triple with a weak pair (119 matches) had its
# third view registered or not depending on COLMAP's seed and on rounding-level changes of the matches
TRIPLE = ("60584745_2207571072.jpg", "10265353_3838484249.jpg", "32809961_8274055477.jpg")


@pytest.mark.parametrize("orientation", range(1, 9))
def test_keypoints_go_to_the_stored_frame_of_exif_turned_files(tmp_path, orientation):
    from PIL import Image

    path = tmp_path / "turned.jpg"
    exif = Image.Exif()
    exif[0x0112] = orientation  # EXIF Orientation
    stored_rgb = np.random.default_rng(orientation).integers(0, 255, (40, 56, 3), dtype=np.uint8)
    Image.fromarray(stored_rgb).save(path, exif=exif.tobytes(), quality=100)
    upright = load_image(path)  # what the keypoints of a run refer to
    stored = cv2.imread(str(path), cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)[:, :, ::-1]
    assert upright.shape[:2] == (stored.shape[:2] if orientation <= 4 else stored.shape[1::-1])
    ys, xs = np.mgrid[: upright.shape[0], : upright.shape[1]]
    points = np.stack([xs.ravel(), ys.ravel()], 1).astype(float)
    sx, sy = to_stored_frame(points, path).round().astype(int).T
    np.testing.assert_allclose(upright[ys.ravel(), xs.ravel()] * 255, stored[sy, sx], atol=0.01)


def test_write_database_round_trip(tmp_path, small_images):
    pycolmap = pytest.importorskip("pycolmap")
    pairs = export_pairs()
    keypoints, matches, _ = merge_keypoints(pairs)
    write_database(tmp_path / "db.db", small_images, keypoints, pairs, matches, camera_mode="single")
    with pycolmap.Database.open(tmp_path / "db.db") as db:
        ids = {image.name: image.image_id for image in db.read_all_images()}
        assert sorted(ids) == ["a.png", "b.png", "c.png"] and db.num_cameras() == 1
        for name, points in keypoints.items():  # COLMAP's top-left pixel centre is (0.5, 0.5)
            np.testing.assert_allclose(db.read_keypoints(ids[name])[:, :2], points + 0.5, atol=1e-5)
        np.testing.assert_array_equal(db.read_matches(ids["a.png"], ids["b.png"]), matches[0])
    with pytest.raises(ConfigError, match="camera_mode"):
        write_database(tmp_path / "db2.db", small_images, keypoints, pairs, matches, camera_mode="shared")


def test_export_without_reconstruction_and_an_image_without_matches(tmp_path, small_images):
    pytest.importorskip("pycolmap")
    empty = PairMatches("b.png", "c.png", np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0))
    run = write_run_folder(tmp_path, [export_pairs()[0], empty])  # c.png takes part in no match
    summary = export_run(run, small_images, tmp_path / "out", reconstruct=False)
    assert (summary["images"], summary["pairs"], summary["keypoints"], summary["matches"]) == (3, 2, 5, 2)
    assert summary["verified_pairs"] == 0  # two matches give no two-view geometry (COLMAP lists it as degenerate)
    assert "models" not in summary and json.loads((tmp_path / "out" / "summary.json").read_text()) == summary
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["database.db", "pairs.txt", "summary.json"]
    assert [p.name for p in tmp_path.iterdir() if "staging" in p.name] == []


def test_export_refuses_bad_output_and_missing_images(tmp_path, small_images):
    pytest.importorskip("pycolmap")
    run = write_run_folder(tmp_path, export_pairs())
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "notes.txt").write_text("mine")
    with pytest.raises(ConfigError, match="holds no COLMAP export"):
        export_run(run, small_images, tmp_path / "busy")
    assert (tmp_path / "busy" / "notes.txt").read_text() == "mine"
    (small_images / "c.png").unlink()
    with pytest.raises(ImageError, match="c.png"):
        export_run(run, small_images, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    with pytest.raises(ConfigError, match="seed"):
        export_run(run, small_images, tmp_path / "out", seed=-1)
    (tmp_path / "afile").write_text("")
    with pytest.raises(ConfigError, match="is a file"):
        export_run(run, small_images, tmp_path / "afile")


def test_missing_pycolmap_is_a_clear_error(tmp_path, small_images, monkeypatch):
    monkeypatch.setitem(__import__("sys").modules, "pycolmap", None)  # `import pycolmap` raises ImportError
    with pytest.raises(ConfigError, match="pip install 'slime-match\\[colmap\\]'"):
        export_run(write_run_folder(tmp_path, export_pairs()), small_images, tmp_path / "out")


@pytest.fixture(scope="module")
def sacre_coeur(tmp_path_factory):
    """The photos of TRIPLE, the second stored turned by 90° with an EXIF orientation that turns it back (as
    phones save portrait photos), and Slime's matches of their three pairs (weight-free), as `slime pairs`
    writes them: (image folder, run folder)."""
    from PIL import Image

    require(SACRE_COEUR)
    folder = tmp_path_factory.mktemp("sacre_coeur")
    images = folder / "images"
    images.mkdir()
    for name in TRIPLE:
        shutil.copy(SACRE_COEUR / name, images / name)
    exif = Image.Exif()
    exif[0x0112] = 6  # shown turned 90° clockwise
    Image.open(SACRE_COEUR / TRIPLE[1]).transpose(Image.Transpose.ROTATE_90).save(
        images / TRIPLE[1], exif=exif.tobytes(), quality=95)
    (folder / "pairs.txt").write_text(f"{TRIPLE[0]} {TRIPLE[1]}\n{TRIPLE[0]} {TRIPLE[2]}\n{TRIPLE[1]} {TRIPLE[2]}\n")
    config = make_config("slime", shape="baumberg", orientation="gradient", descriptor="rootsift")
    records = match_pairs(config, read_pairs(folder / "pairs.txt", images), folder / "run")
    assert all(r["status"] == "done" for r in records)
    return images, folder / "run"


def test_slime_colmap_reconstructs_real_photos(sacre_coeur, tmp_path, capsys):
    pycolmap = pytest.importorskip("pycolmap")
    images, run = sacre_coeur
    out = tmp_path / "sfm"
    code, stdout, _ = run_cli(capsys, "colmap", run, "--images", images, "-o", out)
    assert code == 0, stdout
    assert "3 of 3 pairs verified" in stdout and "model 0: 3 of 3 images registered" in stdout
    summary = json.loads((out / "summary.json").read_text())
    model = summary["models"][0]
    assert sorted(model["images"]) == sorted(TRIPLE)
    assert model["points3D"] >= 50 and model["mean_reprojection_error"] < 2.0
    assert {p.name for p in (out / "sparse" / "0").iterdir()} >= {"cameras.bin", "images.bin", "points3D.bin"}
    model = pycolmap.Reconstruction(out / "sparse" / "0")
    turned = next(image for image in model.images.values() if image.name == TRIPLE[1])
    camera = model.cameras[turned.camera_id]
    assert (camera.width, camera.height) == (694, 1068)  # COLMAP reads the stored pixels
    xy = np.array([point.xy for point in turned.points2D])
    assert len(xy) > 100 and (xy >= 0).all() and (xy <= [camera.width, camera.height]).all()

    code, _, stderr = run_cli(capsys, "colmap", run, "--images", images, "-o", out, "--no-reconstruct")
    assert code == 2 and "--overwrite" in stderr
    code, stdout, _ = run_cli(capsys, "colmap", run, "--images", images, "-o", out, "--no-reconstruct",
                              "--overwrite")
    assert code == 0 and "model" not in stdout and not (out / "sparse").exists()


def test_slime_colmap_cli_errors(tmp_path, capsys):
    pytest.importorskip("pycolmap")  # without it, the missing package is the error reported first
    code, _, stderr = run_cli(capsys, "colmap", tmp_path, "-o", tmp_path / "out")
    assert code == 2 and "not a `slime pairs` run folder" in stderr
