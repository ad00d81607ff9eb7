"""Helpers shared by the eval tests: rotations, a fixed homography, two-view points, textures."""

import math

import cv2
import numpy as np

H_GT = np.array([[1.1, 0.05, 20.0], [-0.03, 0.95, -10.0], [1e-4, -5e-5, 1.0]])


def rot(axis, deg):
    return cv2.Rodrigues(np.asarray(axis, np.float64) / np.linalg.norm(axis) * math.radians(deg))[0]


def two_view_points(K0, K1, R, t, rng, n=50, w=640, h=480):
    """Pixels of image 0 back-projected at random depths and projected into image 1."""
    x0 = rng.uniform([0, 0], [w, h], (n, 2))
    rays = np.concatenate([x0, np.ones((n, 1))], 1) @ np.linalg.inv(K0).T
    X = rays * rng.uniform(1, 10, (n, 1))
    p = (X @ R.T + t) @ K1.T
    return x0, p[:, :2] / p[:, 2:]


def same_up_to_scale(a, b):
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    return min(np.abs(a - b).max(), np.abs(a + b).max())


def texture(h=60, w=80, seed=0):
    return np.random.default_rng(seed).integers(0, 255, (h, w, 3), dtype=np.uint8)
