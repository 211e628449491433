"""The hyperboloidal mirror (eqs. 1, 8-15): the numpy reference the kernels are checked against."""

import math

import numpy as np
from conftest import RIGS, annulus_pixels

from omnicam import HyperbolicMirror


def test_foci_and_rim_height_follow_eq_1():
    m = HyperbolicMirror(3.0, 4.0, 6.0)
    assert m.c == 5.0
    assert math.isclose(m.z_rim, 4.0 * math.sqrt(1 + 4.0))
    rim = m.rim_points(12)
    np.testing.assert_allclose((rim[:, 0] ** 2 + rim[:, 1] ** 2) / 9 - rim[:, 2] ** 2 / 16, -1)


def test_normal_is_perpendicular_to_the_surface_and_points_to_the_camera():
    m = HyperbolicMirror(23.4, 28.1, 30.0)
    rng = np.random.default_rng(0)
    X, Y = rng.uniform(-20, 20, (2, 100))
    P = np.stack([X, Y, m.surface_z(X, Y)], axis=1)
    h = 1e-6
    tx = (m.surface_z(X + h, Y) - m.surface_z(X - h, Y)) / (2 * h)
    ty = (m.surface_z(X, Y + h) - m.surface_z(X, Y - h)) / (2 * h)
    N = m.normal(P)
    np.testing.assert_allclose(N[:, 0] + N[:, 2] * tx, 0, atol=1e-8)
    np.testing.assert_allclose(N[:, 1] + N[:, 2] * ty, 0, atol=1e-8)
    assert (m.unit_normal(P)[:, 2] < 0).all()


def test_intersect_agrees_with_the_ray_tracing_kernel():
    cam = RIGS["misaligned"]
    pix = annulus_pixels(cam, step=15.0)
    origins, _ = cam.unproject(pix)
    V = np.linalg.solve(cam.K, np.c_[pix, np.ones(len(pix))].T).T @ cam.R
    P = cam.mirror.intersect(cam.camera_center, V)
    np.testing.assert_allclose(P, origins, atol=1e-9)


def test_intersect_misses_outside_the_rim_and_behind_the_origin():
    m = HyperbolicMirror(23.4, 28.1, 30.0)
    F = np.array([0.0, 0.0, -m.c])
    V = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.1], [0.0, 0.0, -1.0]])
    P = m.intersect(F, V)
    np.testing.assert_allclose(P[0], [0, 0, m.b])
    assert np.isnan(P[1:]).all()


def test_reflect_keeps_the_tangential_part_and_flips_the_normal_part():
    n = np.array([0.0, 0.6, -0.8])
    V = np.array([0.3, -0.2, 0.9])
    out = HyperbolicMirror.reflect(V, n)
    np.testing.assert_allclose(out @ n, -(V @ n))
    np.testing.assert_allclose(out - (out @ n) * n, V - (V @ n) * n)
