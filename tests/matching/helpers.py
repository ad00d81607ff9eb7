"""Helpers shared by the DTM mesh tests."""


def cross(u, v):
    return u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
