"""Ray intersections of the synthetic generator's primitives against hand-computed hits."""

import numpy as np
import pytest

from dataset_tools.synth.primitives import Box, Cylinder, Plane, Sphere


def rays(*pairs):
    o = np.array([p[0] for p in pairs], dtype=float)
    d = np.array([p[1] for p in pairs], dtype=float)
    return o, d / np.linalg.norm(d, axis=1, keepdims=True)


def test_sphere_hit_distance_and_normal():
    o, d = rays(((0, 0, 5), (0, 0, -1)), ((3, 0, 1), (-1, 0, 0)), ((0, 5, 5), (0, 0, -1)))
    t, n = Sphere((0, 0, 1), 1.0).intersect(o, d)
    assert t[:2] == pytest.approx([3.0, 2.0])
    assert np.allclose(n[:2], [[0, 0, 1], [1, 0, 0]])
    assert np.isinf(t[2])


def test_turned_box_hits_its_corner_edge():
    # a unit cube turned by 45 degrees presents an edge at x = -sqrt(2) * 0.5 towards -x
    o, d = rays(((-5, 0, 0.5), (1, 0, 0)), ((-5, 0.8, 0.5), (1, 0, 0)))
    t, n = Box((0, 0, 0.5), (0.5, 0.5, 0.5), np.pi / 4).intersect(o, d)
    assert t[0] == pytest.approx(5 - np.sqrt(0.5))
    assert np.isinf(t[1])  # passes beside the turned cube (its half-diagonal is 0.707)
    assert np.linalg.norm(n[0]) == pytest.approx(1.0)


def test_cylinder_side_and_cap():
    o, d = rays(((-5, 0, 1), (1, 0, 0)), ((0, 0, 10), (0, 0, -1)), ((-5, 0, 3), (1, 0, 0)))
    t, n = Cylinder((0, 0, 0), 0.5, 2.0).intersect(o, d)
    assert t[:2] == pytest.approx([4.5, 8.0])
    assert np.allclose(n[:2], [[-1, 0, 0], [0, 0, 1]])
    assert np.isinf(t[2])  # above the top


def test_plane_is_one_sided():
    o, d = rays(((0, 0, 2), (0, 0, -1)), ((0, 0, -2), (0, 0, 1)))
    t, _ = Plane((0, 0, 1), 0.0).intersect(o, d)
    assert t[0] == pytest.approx(2.0) and np.isinf(t[1])
