"""Helpers shared by the Slime stage tests: a synthetic image of squares, hand-built match tables and tile
sets."""

import math

import cv2
import numpy as np
import scipy.sparse as sp

from slime_match.geometry.fundamental import epipolar_distance
from slime_match.slime.match_table import MatchTable
from slime_match.slime.tile_sets import TileSets

WEIGHT_FREE = {"shape": "baumberg", "orientation": "gradient", "descriptor": "rootsift"}
SIZE = (240, 320)  # (H, W) of ``squares``


def squares() -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 3) grey image of bright 20 px squares on a dark ground, and their (4 S, 2) corners in px."""
    h, w = SIZE
    img = np.full((h, w), 0.2, np.float32)
    corners = []
    for y in range(30, 210, 50):
        for x in range(30, 290, 55):
            img[y:y + 20, x:x + 20] = 0.9
            corners += [(x - 0.5, y - 0.5), (x + 19.5, y - 0.5), (x - 0.5, y + 19.5), (x + 19.5, y + 19.5)]
    img = cv2.GaussianBlur(img, (0, 0), 1.0)
    return np.repeat(img[:, :, None], 3, axis=2), np.array(corners)


def nearest(points: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per point (P, 2), the distance to its nearest row of ``xy`` (N, 2) and that row's index."""
    d = np.linalg.norm(points[:, None] - xy[None], axis=2)
    return d.min(axis=1), d.argmin(axis=1)


def make_table(xy0, xy1, angle0=None, angle1=None, scale0=None, scale1=None) -> MatchTable:
    """A match table of unit weight, source 0 and score 0; orientations 0 and scales 1 unless given."""
    m = len(xy0)
    zeros, ones = np.zeros(m), np.ones(m)
    angle0, angle1 = (zeros if a is None else a for a in (angle0, angle1))
    scale0, scale1 = (ones if s is None else s for s in (scale0, scale1))
    return MatchTable(xy0, xy1, angle0, angle1, scale0, scale1, ones, zeros, zeros)


def make_sets(rows, n_matches, tile0, tile1, plane=None) -> TileSets:
    """Tile sets over ``n_matches`` matches: set i holds the matches ``rows[i]``, on tile pair
    (tile0[i], tile1[i]) and plane ``plane[i]`` (i when None)."""
    r = np.concatenate([np.full(len(m), i) for i, m in enumerate(rows)])
    c = np.concatenate([np.asarray(m) for m in rows])
    mat = sp.csr_matrix((np.ones(len(c), bool), (r, c)), shape=(len(rows), n_matches))
    plane = np.arange(len(rows)) if plane is None else plane
    return TileSets.from_csr(mat, plane, tile0, tile1)


def set_members(ts: TileSets) -> list[set[int]]:
    """The matches of each set, as Python sets."""
    return [set(ts.members(s).tolist()) for s in range(len(ts))]


def two_plane_scene(seed=0, n=200):
    """Matches (2 n + 60, 2) <-> (2 n + 60, 2) in a 640 x 480 stereo pair with a known F: n on each of two
    planes (0.5 px noise), then up to 60 on a wrong plane, consistent with a homography but over 30 px from
    the epipolar lines; and F."""
    rng = np.random.default_rng(seed)
    k = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    a = 0.15
    r = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    t = np.array([-1.0, 0.1, 0.05])

    def on_plane(normal, d):
        uv = rng.uniform([20, 20], [620, 460], (n, 2))
        ray = np.linalg.inv(k) @ np.vstack([uv.T, np.ones(n)])
        return (ray * (d / (normal @ ray))).T

    x3 = np.vstack([on_plane(np.array([0, 0, 1.0]), 6.0), on_plane(np.array([0.29, 0, 0.96]), 3.0)])
    p0 = (k @ x3.T).T
    p1 = (k @ (r @ x3.T + t[:, None])).T
    x0 = p0[:, :2] / p0[:, 2:] + rng.normal(0, 0.5, (2 * n, 2))
    x1 = p1[:, :2] / p1[:, 2:] + rng.normal(0, 0.5, (2 * n, 2))
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    f = np.linalg.inv(k).T @ tx @ r @ np.linalg.inv(k)
    # a wrong plane: matches consistent with a homography but far from the true epipolar lines
    hw = np.array([[0.9, 0.1, 60], [-0.1, 0.9, -40], [0, 0, 1.0]])
    w0 = rng.uniform([0, 0], [640, 480], (400, 2))
    w1 = w0 @ hw[:2, :2].T + hw[:2, 2]
    far = epipolar_distance(f, w0, w1) > 30
    return np.vstack([x0, w0[far][:60]]), np.vstack([x1, w1[far][:60]]), f
