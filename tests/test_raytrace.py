"""Pixel -> ray and point -> pixel (omnicam.raytrace, eqs. 6-19), called directly.

The references are written out here or in ``naive.py``: the HyperOmni equations 2-5 for the
aligned rig, eq. 1 and its gradient (eq. 14) for the hit point and the normal, the textbook
Brown-Conrady distortion and OpenCV's own point functions for ``D``.
"""

import math

import cv2
import naive
import numpy as np
import pytest
from conftest import RIGS, annulus_pixels

from omnicam import raytrace

MODEL_RIGS = ["misaligned", "max_tilt_offset", "skew", "distorted", "rational"]


def rays(cam, pixels):
    """``raytrace.trace`` with the rig's parameters."""
    return raytrace.trace(pixels, cam.K, cam.D, cam.R, cam.camera_center, cam.mirror)


def project(cam, points, at_infinity=False):
    """``raytrace.project`` with the rig's parameters."""
    args = (cam.K, cam.D, cam.R, cam.tvec, cam.camera_center, cam.mirror)
    return raytrace.project(np.ascontiguousarray(points, np.float64), at_infinity, *args)


def on_hyperboloid(mirror, P):
    """Eq. 1's left side plus one: zero on the mirror's surface."""
    a2, b2 = mirror.a**2, mirror.b**2
    return (P[:, 0] ** 2 + P[:, 1] ** 2) / a2 - P[:, 2] ** 2 / b2 + 1.0


def eq14_normal(mirror, P):
    """Unit normal of eq. 14, ``(f_X, f_Y, -1)`` with ``f = b sqrt(1 + (X^2+Y^2)/a^2)``."""
    a2, b2 = mirror.a**2, mirror.b**2
    N = np.stack(
        [b2 * P[:, 0] / (a2 * P[:, 2]), b2 * P[:, 1] / (a2 * P[:, 2]), -np.ones(len(P))], 1
    )
    return N / np.linalg.norm(N, axis=1, keepdims=True)


def brown_conrady(xn, K, D):
    """OpenCV's 5-coefficient model written out (radial k1, k2, k3; tangential p1, p2), then
    ``K`` with its skew: the pixel of undistorted normalised coordinates."""
    k1, k2, p1, p2, k3 = D
    x, y = xn[:, 0], xn[:, 1]
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=1)


# -- the aligned rig is the HyperOmni model (eqs. 2-5) ------------------------------------------
def test_aligned_rig_traces_the_directions_of_equations_2_to_5():
    cam = RIGS["aligned"]
    m, K = cam.mirror, cam.K
    pix = annulus_pixels(cam, step=23.0)
    pix = pix[np.hypot(*(pix - K[:2, 2]).T) > 1.0]  # eq. 2's azimuth needs a radius
    P, d = rays(cam, pix)
    assert np.isfinite(d).all() and len(pix) > 200
    for (u, v), P_i, d_i in zip(pix, P, d):
        ref, focus = naive.hyperomni_direction(u, v, m.a, m.b, K[0, 0], K[0, 2], K[1, 2])
        np.testing.assert_allclose(d_i, ref, atol=1e-12)
        assert np.linalg.norm(np.cross(P_i - focus, d_i)) < 1e-11  # eq. 3: through (0, 0, c)


def test_aligned_rig_projects_points_where_equation_4_inverted_puts_them():
    # eq. 4 solved for beta: (b^2 + c^2) sin(beta) - (b^2 - c^2) tan(alpha) cos(beta) = 2 b c,
    # i.e. sqrt(A^2 + B^2) sin(beta - phi) = 2 b c; then eq. 5's radius f_C / tan(beta) and
    # eq. 2's azimuth (the point seen from the outer focus (0, 0, c), eq. 3)
    cam = RIGS["aligned"]
    m, K = cam.mirror, cam.K
    b, c = m.b, m.c
    rng = np.random.default_rng(4)
    az = rng.uniform(-math.pi, math.pi, 300)
    alpha = rng.uniform(math.radians(-70), math.radians(-5), 300)  # elevation, seen by the rig
    dist = rng.uniform(50.0, 1e5, 300)
    d = np.stack([np.cos(alpha) * np.cos(az), np.cos(alpha) * np.sin(az), np.sin(alpha)], 1)
    X = np.array([0.0, 0.0, c]) + dist[:, None] * d
    A, B = b * b + c * c, (b * b - c * c) * np.tan(alpha)
    beta = np.arctan2(B, A) + np.arcsin(2 * b * c / np.hypot(A, B))
    rho = K[0, 0] / np.tan(beta)
    expected = K[:2, 2] + rho[:, None] * np.stack([np.cos(az), np.sin(az)], 1)
    np.testing.assert_allclose(project(cam, X), expected, atol=1e-7)
    np.testing.assert_allclose(project(cam, d, at_infinity=True), expected, atol=1e-7)


def test_aligned_rig_sees_the_point_below_on_the_axis_at_the_principal_point():
    cam = RIGS["aligned"]
    got = project(cam, np.array([[0.0, 0.0, -500.0], [0.0, 0.0, -1.0]]))
    np.testing.assert_allclose(got, [cam.K[:2, 2]] * 2, atol=1e-9)


# -- the optics at the hit point (eqs. 8-15) ----------------------------------------------------
@pytest.mark.parametrize("name", MODEL_RIGS)
def test_hit_point_is_on_the_mirror_and_on_the_pixels_camera_ray(name):
    cam = RIGS[name]
    pix = annulus_pixels(cam, step=12.0)
    P, d = rays(cam, pix)
    assert np.isfinite(P).all()
    m = cam.mirror
    np.testing.assert_allclose(on_hyperboloid(m, P), 0.0, atol=1e-12)  # eq. 1
    assert (P[:, 2] > 0).all() and (np.hypot(P[:, 0], P[:, 1]) <= m.rim_radius + 1e-9).all()
    # on the camera ray of the undistorted pixel (eqs. 6, 16, 17), in front of the camera
    Kn = cam.K.copy()
    Kn[0, 1] = 0.0  # cv2 ignores skew: undo the skew on the pixels ourselves
    und = pix.copy()
    und[:, 0] -= cam.K[0, 1] * (pix[:, 1] - cam.K[1, 2]) / cam.K[1, 1]
    if cam.D is not None:
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 500, 1e-16)
        und = cv2.undistortPoints(und.reshape(-1, 1, 2), Kn, cam.D, R=None, P=Kn, criteria=crit)
        und = und.reshape(-1, 2)
    V_C = np.concatenate([und, np.ones((len(und), 1))], 1) @ np.linalg.inv(Kn).T
    V_M = V_C @ cam.R  # R^T V_C
    w = P - cam.camera_center
    assert (np.einsum("ij,ij->i", w, V_M) > 0).all()
    sin = np.linalg.norm(np.cross(w, V_M), axis=1) / np.linalg.norm(w, axis=1)
    assert (sin / np.linalg.norm(V_M, axis=1) < 1e-10).all()


@pytest.mark.parametrize("name", ["aligned", *MODEL_RIGS])
def test_reflection_law_at_the_hit_point(name):
    cam = RIGS[name]
    P, d = rays(cam, annulus_pixels(cam, step=12.0))
    n = eq14_normal(cam.mirror, P)
    v = P - cam.camera_center
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    # the incident and the reflected angle about the normal are equal (on opposite sides) ...
    incident = np.arccos(np.clip(-np.einsum("ij,ij->i", v, n), -1, 1))
    reflected = np.arccos(np.clip(np.einsum("ij,ij->i", d, n), -1, 1))
    np.testing.assert_allclose(incident, reflected, atol=1e-7)
    assert (np.einsum("ij,ij->i", v, n) < 0).all()  # eq. 12: the camera sees the front
    # ... and incident ray, normal and reflected ray lie in one plane
    np.testing.assert_allclose(np.einsum("ij,ij->i", np.cross(v, n), d), 0.0, atol=1e-12)


@pytest.mark.parametrize("name", ["skew", "distorted", "rational"])
def test_trace_normalized_is_the_same_model_as_trace(name):
    cam = RIGS[name]
    pix = np.concatenate([annulus_pixels(cam, step=20.0), [[-900.0, 40.0]]])
    P0, V0 = rays(cam, pix)
    if cam.D is None:
        Ki = np.linalg.inv(cam.K)
        xn = pix @ Ki[:2, :2].T + Ki[:2, 2]
    else:
        xn = raytrace.undistort_normalized(pix, cam.K, cam.D)
    P, V = raytrace.trace_normalized(xn, cam.R, cam.camera_center, cam.mirror)
    np.testing.assert_allclose(P, P0, atol=1e-9)  # NaN rows in the same places
    np.testing.assert_allclose(V, V0, atol=1e-12)


# -- the exact inverse: project(trace(px)) is px -------------------------------------------------
@pytest.mark.parametrize("name", ["aligned", *MODEL_RIGS])
def test_project_of_traced_rays_returns_the_pixels(name):
    cam = RIGS[name]
    pix = annulus_pixels(cam, step=9.0)
    P, d = rays(cam, pix)
    for depth in (25.0, 3e3, 1e6):
        err = np.linalg.norm(project(cam, P + depth * d) - pix, axis=1)
        assert err.max() < 1e-6, (depth, err.max())
    assert np.linalg.norm(project(cam, d, at_infinity=True) - pix, axis=1).max() < 1e-6


@pytest.mark.parametrize("name", ["misaligned", "distorted"])
def test_traced_ray_of_a_projected_point_passes_through_it(name):
    cam = RIGS[name]
    rng = np.random.default_rng(6)
    X = rng.normal(size=(500, 3)) * [800.0, 800.0, 300.0] + [0.0, 0.0, -400.0]
    px = project(cam, X)
    seen = np.isfinite(px).all(axis=1)
    assert seen.sum() > 300
    P, d = rays(cam, px[seen])
    w = X[seen] - P
    assert (np.einsum("ij,ij->i", w, d) > 0).all()
    # the angle between the ray and the point is the angle of ~1e-9 px
    sin = np.linalg.norm(np.cross(w, d), axis=1) / np.linalg.norm(w, axis=1)
    assert sin.max() < 1e-9


# -- distortion: OpenCV's model, tightly inverted ----------------------------------------------
@pytest.mark.parametrize("name", ["distorted", "rational"])
def test_distort_normalized_is_cv2_project_points(name):
    cam = RIGS[name]
    K = cam.K.copy()
    K[0, 1] = 0.0  # cv2.projectPoints has no skew
    xn = np.random.default_rng(2).uniform(-0.5, 0.5, (300, 2))
    ref, _ = cv2.projectPoints(
        np.concatenate([xn, np.ones((300, 1))], 1).reshape(-1, 1, 3),
        np.zeros(3),
        np.zeros(3),
        K,
        cam.D,
    )
    np.testing.assert_allclose(
        raytrace.distort_normalized(xn, K, cam.D), ref.reshape(-1, 2), atol=1e-9
    )


def test_distort_normalized_applies_skew_after_opencvs_distortion():
    cam = RIGS["skew"]  # K with skew 0.8 and fy != fx
    D = np.array([-0.12, 0.05, 0.001, -0.0015, -0.01])
    xn = np.random.default_rng(3).uniform(-0.5, 0.5, (300, 2))
    got = raytrace.distort_normalized(xn, cam.K, D)
    np.testing.assert_allclose(got, brown_conrady(xn, cam.K, D), atol=1e-9)


@pytest.mark.parametrize("name", ["distorted", "rational"])
def test_undistort_normalized_inverts_distort_and_agrees_with_cv2(name):
    cam = RIGS[name]
    xn = np.random.default_rng(5).uniform(-0.5, 0.5, (300, 2))
    px = raytrace.distort_normalized(xn, cam.K, cam.D)
    back = raytrace.undistort_normalized(px, cam.K, cam.D)
    np.testing.assert_allclose(back, xn, atol=1e-12)
    if cam.K[0, 1] == 0.0:
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 500, 1e-16)
        ref = cv2.undistortPoints(px.reshape(-1, 1, 2), cam.K, cam.D, R=None, P=None, criteria=crit)
        np.testing.assert_allclose(back, ref.reshape(-1, 2), atol=1e-12)


def test_undistortion_is_tight_where_opencvs_default_is_not():
    # conventions.md: OpenCV's default iterations leave a visible error on a strong lens
    K = np.array([[500.0, 0.0, 250.0], [0.0, 500.0, 250.0], [0.0, 0.0, 1.0]])
    D = np.array([-0.35, 0.12, 0.002, -0.001, -0.02])
    xn = np.random.default_rng(1).uniform(-0.6, 0.6, (500, 2))
    px = raytrace.distort_normalized(xn, K, D)
    default = cv2.undistortPoints(px.reshape(-1, 1, 2), K, D).reshape(-1, 2)
    assert 500.0 * np.abs(default - xn).max() > 0.1  # px
    assert 500.0 * np.abs(raytrace.undistort_normalized(px, K, D) - xn).max() < 1e-9


def test_undistort_and_distort_keep_nan_rows_nan_and_the_others_exact():
    cam = RIGS["distorted"]
    xn = np.array([[0.1, -0.2], [np.nan, 0.3], [0.0, np.inf], [-0.3, 0.25]])
    px = raytrace.distort_normalized(xn, cam.K, cam.D)
    assert np.isnan(px[1:3]).all() and np.isfinite(px[[0, 3]]).all()
    np.testing.assert_allclose(px[[0, 3]], raytrace.distort_normalized(xn[[0, 3]], cam.K, cam.D))
    back = raytrace.undistort_normalized(px, cam.K, cam.D)
    assert np.isnan(back[1:3]).all()
    np.testing.assert_allclose(back[[0, 3]], xn[[0, 3]], atol=1e-12)
    assert np.isnan(raytrace.undistort_normalized(np.full((2, 2), np.nan), cam.K, cam.D)).all()


# -- NaN rules (conventions.md) -------------------------------------------------------------------
@pytest.mark.parametrize("name", ["aligned", "misaligned", "distorted"])
def test_pixels_that_miss_the_mirror_give_nan_rays(name):
    cam = RIGS[name]
    centre = cam.rim_image_points(360).mean(axis=0)
    outside = cam.rim_image_points(360)
    outside = centre + 1.02 * (outside - centre)  # just beyond the rim image
    far = np.array([[-1000.0, -1000.0], [5000.0, 250.0], [np.nan, 3.0], [3.0, np.nan]])
    inside = annulus_pixels(cam, step=60.0)
    P, d = rays(cam, np.concatenate([outside, far, inside]))
    n_out = len(outside) + len(far)
    assert np.isnan(P[:n_out]).all() and np.isnan(d[:n_out]).all()
    assert np.isfinite(P[n_out:]).all() and np.isfinite(d[n_out:]).all()


@pytest.mark.parametrize("name", ["aligned", "misaligned", "distorted"])
def test_an_infinite_pixel_gives_nan_rays_silently(name):
    cam = RIGS[name]
    P, d = rays(cam, np.array([[3.0, np.inf], [-np.inf, 250.0]]))
    assert np.isnan(P).all() and np.isnan(d).all()


@pytest.mark.parametrize("name", ["aligned", "misaligned", "distorted"])
def test_points_and_directions_the_rig_cannot_see_give_nan(name):
    cam = RIGS[name]
    m = cam.mirror
    X = np.array(
        [
            [0.0, 0.0, m.z_rim + 1000.0],  # above the mirror: behind its sheet
            [1.0, 2.0, m.b + 5.0],  # inside the mirror's body
            [np.nan, 0.0, -100.0],
            [0.0, 0.0, np.inf],
            [0.0, 0.0, -300.0],  # seen: stays finite beside the others
        ]
    )
    px = project(cam, X)
    assert np.isnan(px[:4]).all() and np.isfinite(px[4]).all()
    rim_elev = math.atan2(m.z_rim - m.c, m.rim_radius)  # the aligned rig's horizon
    dirs = np.array(
        [
            [0.0, 0.0, 1.0],  # straight up
            [math.cos(rim_elev + 0.2), 0.0, math.sin(rim_elev + 0.2)],  # above the rim
            [0.0, 0.0, 0.0],
            [np.nan, 1.0, 0.0],
            [0.0, 0.6, -0.8],  # seen
        ]
    )
    px = project(cam, dirs, at_infinity=True)
    assert np.isnan(px[:4]).all() and np.isfinite(px[4]).all()


# -- as_points: the one door for point arrays -----------------------------------------------------
@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.int32])
@pytest.mark.parametrize("layout", [(-1, 2), (-1, 1, 2)], ids=["N2", "N12"])
def test_as_points_gives_float64_rows_and_restores_the_callers_layout(dtype, layout):
    raw = np.arange(12).reshape(6, 2).astype(dtype).reshape(layout)
    pts, restore = raytrace.as_points(raw, "pixels", 2)
    assert pts.shape == (6, 2) and pts.dtype == np.float64 and pts.flags.c_contiguous
    np.testing.assert_array_equal(pts, np.arange(12).reshape(6, 2))
    out = restore(np.zeros((6, 3)))
    assert out.shape == ((6, 3) if len(layout) == 2 else (6, 1, 3))


@pytest.mark.parametrize(
    "bad, match",
    [
        (np.zeros((4, 3)), r"pixels must have shape \(N, 2\) or \(N, 1, 2\), got \(4, 3\)"),
        (np.zeros((4, 2, 2)), r"got \(4, 2, 2\)"),
        (np.zeros(8), r"got \(8,\)"),
        (np.array([["a", "b"]]), "pixels must be a float array"),
        (np.array([[1, None]], dtype=object), "got dtype object"),
        (np.zeros((3, 2), complex), "got dtype complex128"),
    ],
    ids=["3 columns", "(N, 2, 2)", "flat", "strings", "object", "complex"],
)
def test_as_points_rejects_what_is_not_a_point_array(bad, match):
    with pytest.raises(ValueError, match=match):
        raytrace.as_points(bad, "pixels", 2)


def test_as_points_names_the_argument_and_the_dimension():
    with pytest.raises(ValueError, match=r"points must have shape \(N, 3\) or \(N, 1, 3\)"):
        raytrace.as_points(np.zeros((5, 2)), "points", 3)
