"""Exact synthetic checks of the geometry primitives (DLT, 8-point, errors, sampling)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from slime_match.geometry.fundamental import (
    epipolar_distance,
    fundamental_8point,
    fundamental_8point_batch,
    fundamental_from_homography_and_parallax,
)
from slime_match.geometry.homography import (
    homography_dlt,
    homography_dlt_batch,
    normalize_points,
    plane_side,
    project,
    two_sided_error,
)
from slime_match.geometry.sampling import sample_subsets, sample_subsets_varying

H_TRUE = np.array([[1.1, 0.05, 20.0], [-0.03, 0.95, -10.0], [1e-4, 2e-4, 1.0]])
K_CAM = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
R_CAM = Rotation.from_rotvec([0.05, 0.2, 0.02]).as_matrix()
T_CAM = np.array([1.0, 0.1, 0.2])


def _skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def _f_true():
    kinv = np.linalg.inv(K_CAM)
    f = kinv.T @ _skew(T_CAM) @ R_CAM @ kinv
    return f / np.linalg.norm(f)


def _views(points3d):
    p0 = points3d @ K_CAM.T
    p1 = (points3d @ R_CAM.T + T_CAM) @ K_CAM.T
    return p0[:, :2] / p0[:, 2:], p1[:, :2] / p1[:, 2:]


def _same_up_to_scale(a, b):
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    return min(np.abs(a - b).max(), np.abs(a + b).max())


@pytest.fixture
def rng():
    return np.random.default_rng(0)


def test_normalize_points(rng):
    x = rng.uniform(0, 640, (30, 2))
    xn, t = normalize_points(x)
    assert np.allclose(xn.mean(0), 0, atol=1e-12)
    assert np.isclose(np.linalg.norm(xn, axis=1).mean(), np.sqrt(2))
    assert np.allclose(np.c_[x, np.ones(30)] @ t.T, np.c_[xn, np.ones(30)])


def test_dlt_recovers_h_minimal_and_least_squares(rng):
    x0 = rng.uniform(0, 640, (4, 2))
    h, sigma2 = homography_dlt(x0, project(H_TRUE, x0)[0])
    assert _same_up_to_scale(h, H_TRUE) < 1e-8 and sigma2 > 0.05
    x0 = rng.uniform(0, 640, (200, 2))
    x1 = project(H_TRUE, x0)[0]
    h, _ = homography_dlt(x0, x1)
    assert _same_up_to_scale(h, H_TRUE) < 1e-8
    h_noisy, _ = homography_dlt(x0, x1 + rng.normal(0, 0.5, x1.shape))
    assert np.abs(two_sided_error(h_noisy, x0, x1)).max() < 1.0  # LS averages the noise


def test_dlt_batch_equals_single_and_flags_collinear(rng):
    x0 = rng.uniform(0, 640, (6, 4, 2))
    x1 = rng.uniform(0, 640, (6, 4, 2))
    hb, sb = homography_dlt_batch(x0, x1)
    for i in range(6):
        h, s = homography_dlt(x0[i], x1[i])
        assert _same_up_to_scale(hb[i], h) < 1e-9 and np.isclose(sb[i], s)
    line = np.c_[np.linspace(0, 300, 4), np.linspace(10, 200, 4)]
    _, s = homography_dlt(line, project(H_TRUE, line)[0])
    assert s < 0.05


def test_two_sided_error_hand_computed():
    h = np.diag([2.0, 2.0, 1.0])
    x0 = np.array([[1.0, 1.0], [0.0, 0.0]])
    x1 = np.array([[3.0, 2.0], [0.0, 4.0]])
    # forward |x1 - 2 x0| = 1 and 4; backward |x0 - x1 / 2| = 0.5 and 2
    assert np.allclose(two_sided_error(h, x0, x1), [1.0, 4.0])
    assert np.allclose(two_sided_error(5 * h, x0, x1), [1.0, 4.0])  # scale invariant
    h_inf = np.array([[1.0, 0, 0], [0, 1, 0], [1.0, 0, 0]])  # w = x: points with x = 0 go to infinity
    assert np.isinf(two_sided_error(h_inf, np.array([[0.0, 3.0]]), np.array([[1.0, 1.0]]))[0])


def test_plane_side_flips_behind_vanishing_line():
    h = np.array([[1.0, 0, 0], [0, 1, 0], [0.01, 0, 1]])  # vanishing line x = -100
    x0 = np.array([[-50.0, 0.0], [-150.0, 3.0], [500.0, -7.0]])
    assert np.array_equal(plane_side(h, x0), [1.0, -1.0, 1.0])
    assert np.array_equal(plane_side(-h, x0), [-1.0, 1.0, -1.0])
    _, w = project(h, x0)
    assert np.allclose(w, [0.5, -0.5, 6.0])


def test_eight_point_recovers_f(rng):
    f_true = _f_true()
    x0, x1 = _views(np.c_[rng.uniform(-2, 2, (100, 2)), rng.uniform(4, 8, 100)])
    f, sigma2 = fundamental_8point(x0, x1)
    assert _same_up_to_scale(f, f_true) < 1e-8 and sigma2 > 0.05
    assert abs(np.linalg.det(f)) < 1e-12
    f8, _ = fundamental_8point(x0[:8], x1[:8])
    assert _same_up_to_scale(f8, f_true) < 1e-8
    fb, sb = fundamental_8point_batch(np.stack([x0[:8], x0[8:16]]), np.stack([x1[:8], x1[8:16]]))
    for i in range(2):
        fi, si = fundamental_8point(x0[8 * i : 8 * i + 8], x1[8 * i : 8 * i + 8])
        assert _same_up_to_scale(fb[i], fi) < 1e-9 and np.isclose(sb[i], si)
    assert epipolar_distance(f, x0, x1).max() < 1e-8


def test_eight_point_flags_planar_sample(rng):
    x0, x1 = _views(np.c_[rng.uniform(-2, 2, (8, 2)), np.full(8, 5.0)])
    assert fundamental_8point(x0, x1)[1] < 0.05


def test_epipolar_distance_hand_computed():
    f = np.array([[0.0, 0, 0], [0, 0, -1], [0, 2, 0]])
    # F x0 = (0, -1, 2 y0): line y = 2 y0 in image 1; F^T x1 = (0, 2, -y1): line y = y1 / 2 in image 0
    x0 = np.array([[0.0, 1.0], [4.0, 2.0]])
    x1 = np.array([[0.0, 5.0], [9.0, 4.0]])
    assert np.allclose(epipolar_distance(f, x0, x1), [3.0, 0.0])
    ft = f.T  # roles swapped: the image-0 distance is now the larger one
    assert np.allclose(epipolar_distance(3 * ft, x1, x0), [3.0, 0.0])


def test_plane_plus_parallax(rng):
    f_true = _f_true()
    plane = np.array([0.0, 0.0, 1.0])  # the plane Z = 5
    h = K_CAM @ (R_CAM + np.outer(T_CAM, plane) / 5.0) @ np.linalg.inv(K_CAM)
    x0, x1 = _views(np.c_[rng.uniform(-2, 2, (50, 2)), rng.uniform(3, 9, 50)])
    f = fundamental_from_homography_and_parallax(h, x0[:2], x1[:2])
    assert _same_up_to_scale(f, f_true) < 1e-8
    on0, on1 = _views(np.c_[rng.uniform(-2, 2, (2, 2)), np.full(2, 5.0)])
    with pytest.raises(ValueError):
        fundamental_from_homography_and_parallax(h, on0, on1)


def test_sample_subsets_distinct_and_in_range(rng):
    s = sample_subsets(rng, 10, 4, 5000)
    assert s.shape == (5000, 4) and s.dtype == np.int64
    assert s.min() >= 0 and s.max() < 10
    srt = np.sort(s, axis=1)
    assert (srt[:, 1:] != srt[:, :-1]).all()
    assert np.allclose(np.bincount(s.ravel(), minlength=10) / 5000, 0.4, atol=0.05)  # uniform
    assert (np.sort(sample_subsets(rng, 8, 8, 3), axis=1) == np.arange(8)).all()
    n = np.array([4, 9, 1000])
    v = sample_subsets_varying(rng, np.repeat(n, 100), 4)
    assert (v < np.repeat(n, 100)[:, None]).all()
    with pytest.raises(ValueError):
        sample_subsets(rng, 3, 4, 1)
    a = sample_subsets(np.random.default_rng(7), 50, 8, 20)
    assert np.array_equal(a, sample_subsets(np.random.default_rng(7), 50, 8, 20))
