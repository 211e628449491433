"""Mirrors of revolution as even aspheres: the model, its kernels through the seam, its tables.

Every rule is checked over a sphere, a paraboloid, a prolate ellipsoid and equiangular mirrors
of gain 3, 5, 7 and 11 (``tests/asphere_rigs.py``: misaligned postures, the rim in view), and
the hyperboloid written as an asphere against :class:`HyperbolicMirror`.
"""

import math

import cv2
import numpy as np
import pytest
from asphere_rigs import MIRRORS, equiangular_mirror, rig
from conftest import RIGS, annulus_pixels
from naive import asphere_height, trace_pixel_surface
from test_views import assert_matches_exact, exact, panorama_dirs, perspective_dirs

from omnicam import HyperbolicMirror, K_from_fov, raytrace, rotation_from_ypr, views
from omnicam.asphere import AsphericMirror, equiangular_profile, fit_equiangular

NAMES = sorted(MIRRORS)


@pytest.fixture(scope="module", params=NAMES)
def cam(request):
    return rig(request.param)


def seen_pixels(cam, n=4000, seed=0):
    """Random pixels of the image that see the mirror, with their rays."""
    rng = np.random.default_rng(seed)
    px = rng.uniform([0.0, 0.0], cam.image_size, (n, 2))
    o, d = cam.unproject(px)
    ok = np.isfinite(o[:, 0])
    return px[ok], o[ok], d[ok]


# -- the model ----------------------------------------------------------------------------------
def test_hyperboloid_as_asphere_is_the_same_surface_normal_and_rim():
    m = HyperbolicMirror(23.4, 28.1, 30.0)
    a = m.as_asphere()
    rng = np.random.default_rng(0)
    X, Y = rng.uniform(-36.0, 36.0, (2, 500))
    np.testing.assert_allclose(a.surface_z(X, Y), m.surface_z(X, Y), rtol=0, atol=1e-9)
    P = np.stack([X, Y, m.surface_z(X, Y)], axis=1)
    np.testing.assert_allclose(a.unit_normal(P), m.unit_normal(P), rtol=0, atol=1e-12)
    assert math.isclose(a.z_rim, m.z_rim, rel_tol=0, abs_tol=1e-9)
    np.testing.assert_allclose(a.rim_points(12), m.rim_points(12), rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", ["misaligned", "distorted", "skew"])
def test_hyperboloid_as_asphere_gives_the_same_rays_and_pixels_within_1e_9(name):
    cam = RIGS[name]
    hyp, asp = cam.mirror, cam.mirror.as_asphere()
    pix = annulus_pixels(cam, step=9.0)
    args = (cam.K, cam.D, cam.R, cam.camera_center)
    o1, d1 = raytrace.trace(pix, *args, hyp)
    o2, d2 = raytrace.trace(pix, *args, asp)
    assert np.array_equal(np.isnan(o1), np.isnan(o2))
    np.testing.assert_allclose(o2, o1, rtol=0, atol=1e-9)
    np.testing.assert_allclose(d2, d1, rtol=0, atol=1e-9)
    on = np.isfinite(o1[:, 0])
    for X, inf in ((o1[on] + 700.0 * d1[on], False), (d1[on], True)):
        pose = (cam.K, cam.D, cam.R, cam.tvec, cam.camera_center)
        p1 = raytrace.project(X, inf, *pose, hyp)
        p2 = raytrace.project(X, inf, *pose, asp)
        np.testing.assert_allclose(p2, p1, rtol=0, atol=1e-9)


def test_normal_is_perpendicular_to_the_surface_and_points_to_the_camera(cam):
    m = cam.mirror
    rng = np.random.default_rng(1)
    r = m.rim_radius * np.sqrt(rng.uniform(0.0, 1.0, 200))
    t = rng.uniform(0.0, 2.0 * np.pi, 200)
    X, Y = r * np.cos(t), r * np.sin(t)
    P = np.stack([X, Y, m.surface_z(X, Y)], axis=1)
    h = 1e-6 * m.rim_radius
    tx = (m.surface_z(X + h, Y) - m.surface_z(X - h, Y)) / (2 * h)
    ty = (m.surface_z(X, Y + h) - m.surface_z(X, Y - h)) / (2 * h)
    N = m.normal(P)
    np.testing.assert_allclose(N[:, 0] + N[:, 2] * tx, 0, atol=1e-7)
    np.testing.assert_allclose(N[:, 1] + N[:, 2] * ty, 0, atol=1e-7)
    assert (m.unit_normal(P)[:, 2] < 0).all()


def test_sag_is_the_textbook_even_asphere():
    m = AsphericMirror(20.0, -1.7, 15.0, alpha=(0.3, -0.05, 0.01), rho_n=12.0, vertex_z=5.0)
    for rho in (0.0, 3.0, 9.5, 15.0):
        ref = asphere_height(rho, 20.0, -1.7, (0.3, -0.05, 0.01), 12.0, 5.0)
        assert math.isclose(float(m.surface_z(rho, 0.0)), ref, rel_tol=1e-14, abs_tol=1e-14)


def test_families_have_their_conic_constants():
    assert AsphericMirror.sphere(30.0, 18.0).k == 0.0
    assert AsphericMirror.paraboloid(20.0, 25.0).k == -1.0
    s = AsphericMirror.sphere(30.0, 18.0, vertex_z=40.0)
    # a sphere of radius 30 about (0, 0, 70): |P - centre| = 30 on the surface
    X = np.linspace(0.0, 18.0, 7)
    np.testing.assert_allclose(np.hypot(X, s.surface_z(X, 0.0 * X) - 70.0), 30.0, atol=1e-12)
    p = AsphericMirror.paraboloid(20.0, 25.0)
    np.testing.assert_allclose(p.surface_z(X, 0.0 * X), X**2 / 40.0, atol=1e-12)


@pytest.mark.parametrize("gain", [3.0, 5.0, 7.0, 11.0])
def test_equiangular_fit_reaches_1e_6_of_the_aperture(gain):
    theta = 0.6 * math.pi / (1.0 + gain)
    rim = float(equiangular_profile(gain, 30.0, theta)[0])
    mirror, err = fit_equiangular(gain, 30.0, rim)
    assert err < 1e-6
    assert mirror.vertex_z == 30.0 and len(mirror.alpha) == 5
    # independent check on points of the profile between the fit's samples
    th = np.linspace(0.0, theta, 997)[1:-1] + 1e-4 * theta
    rho, z = equiangular_profile(gain, 30.0, th)
    assert np.abs(mirror.surface_z(rho, 0.0 * rho) - z).max() < 1e-6 * rim


@pytest.mark.parametrize("gain", [3.0, 5.0, 7.0, 11.0])
def test_equiangular_mirror_reflects_polar_angle_theta_to_gain_times_theta(gain):
    """The equiangular property: a ray leaving the camera (at the origin) at ``theta`` from the
    axis leaves the mirror at ``gain * theta`` from the downward axis (the profile's normal
    makes ``psi = (1 + gain) theta / 2`` with the radius, and the ray turns by ``2 psi``)."""
    m = equiangular_mirror(gain)
    theta_rim = math.atan2(m.rim_radius, m.z_rim)
    theta = np.linspace(0.05, 0.95, 19) * theta_rim
    V = np.stack([np.sin(theta), 0.0 * theta, np.cos(theta)], axis=1)
    P = m.intersect(np.zeros(3), V)
    d = m.reflect(V, m.unit_normal(P))
    out = np.arccos(np.clip(-d[:, 2], -1.0, 1.0))
    np.testing.assert_allclose(out, gain * theta, atol=1e-5)


def test_mirror_is_immutable_hashable_and_equal_by_value():
    a = AsphericMirror(20.0, -1.5, 15.0, alpha=[0.1, 0.02], vertex_z=3.0)
    b = AsphericMirror(20.0, -1.5, 15.0, alpha=(0.1, 0.02), rho_n=15.0, vertex_z=3.0)
    assert a == b and hash(a) == hash(b) and a != AsphericMirror(20.0, -1.5, 15.0)
    assert eval(repr(a), {"AsphericMirror": AsphericMirror}) == a
    with pytest.raises(AttributeError):
        a.k = 0.0  # type: ignore[misc]
    assert a.kernel_params()[:10] == (1.0, 15.0, 30.0, 20.0, -1.5, 3.0, 15.0, 2.0, 0.1, 0.02)
    assert len(a.kernel_params()) == 16  # the kernels tell the kinds by length
    assert len(HyperbolicMirror(1.0, 2.0, 3.0).kernel_params()) == 15


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"R": -1.0}, "R"),
        ({"R": float("nan")}, "R"),
        ({"k": "x"}, "k"),
        ({"k": float("inf")}, "k"),
        ({"rim_radius": 0.0}, "rim_radius"),
        ({"rim_radius": 25.0, "k": 0.0}, "rim_radius"),  # a sphere of radius 20 ends at 20
        ({"alpha": (float("nan"),)}, "alpha[0]"),
        ({"alpha": "abc"}, "alpha"),
        ({"alpha": (-5.0,)}, "alpha"),  # not convex near the rim
        ({"alpha": (0.0,) * 9}, "alpha"),  # more terms than the kernels take
        ({"rho_n": -2.0}, "rho_n"),
        ({"vertex_z": float("nan")}, "vertex_z"),
    ],
)
def test_bad_parameters_raise_naming_them(kwargs, name):
    args = {"R": 20.0, "k": -1.5, "rim_radius": 15.0} | kwargs
    with pytest.raises(ValueError, match=name.replace("[", r"\[").replace("]", r"\]")):
        AsphericMirror(**args)


def test_ellipsoid_refuses_a_conic_constant_that_is_no_ellipsoid():
    with pytest.raises(ValueError, match="k must be"):
        AsphericMirror.ellipsoid(20.0, -1.5, 10.0)


# -- the kernels, through the seam ---------------------------------------------------------------
def test_unproject_then_project_returns_the_pixel_within_1e_6_px(cam):
    px, o, d = seen_pixels(cam)
    assert len(px) > 1000
    for X, project in ((o + 500.0 * d, cam.project), (d, cam.project_directions)):
        back = project(X)
        assert np.isfinite(back).all()
        assert np.abs(back - px).max() < 1e-6


def test_reflection_follows_an_independent_brute_force_tracer(cam):
    m = cam.mirror
    height = lambda rho: asphere_height(rho, m.R, m.k, m.alpha, m.rho_n, m.vertex_z)
    px, o, d = seen_pixels(cam, n=400, seed=3)
    inner = np.hypot(o[:, 0], o[:, 1]) < 0.97 * m.rim_radius  # clear of the rim's sampling
    for (u, v), P, dk in list(zip(px[inner], o[inner], d[inner]))[:40]:
        hit = trace_pixel_surface(u, v, cam.K, cam.R, cam.tvec, height, m.rim_radius)
        assert hit is not None
        np.testing.assert_allclose(P, hit[0], atol=1e-8 * m.rim_radius)
        np.testing.assert_allclose(dk, hit[1], atol=1e-6)


def test_numpy_intersect_agrees_with_the_kernel_grazing_rays_included(cam):
    """Rays through the whole image, those near the rim's image (grazing the cap's edge) too."""
    m = cam.mirror
    w, h = cam.image_size
    u, v = np.meshgrid(np.linspace(0, w - 1, 161), np.linspace(0, h - 1, 121))
    pix = np.stack([u.ravel(), v.ravel()], axis=1)
    rim = cam.rim_image_points(2000)
    pix = np.concatenate([pix, rim * 0.9995 + 0.0005 * rim.mean(axis=0)])  # just inside it
    origins, _ = cam.unproject(pix)
    V = np.linalg.solve(cam.K, np.c_[pix, np.ones(len(pix))].T).T @ cam.R
    P = m.intersect(cam.camera_center, V)
    assert np.array_equal(np.isnan(P[:, 0]), np.isnan(origins[:, 0]))
    np.testing.assert_allclose(P, origins, atol=1e-9 * m.rim_radius)


def test_ray_from_the_side_meets_the_cap_only_from_below():
    """A level ray from beside the mirror below the rim's height enters the rim's cylinder
    under the cap and hits it; above the rim's height it meets the mirror's body (the back of
    the cap), not the cap; from inside the body nothing is seen. Kernel and numpy agree."""
    m = AsphericMirror.paraboloid(20.0, 25.0, vertex_z=45.0)  # z = 45 + rho^2 / 40, rim 60.6
    F = np.array([[-60.0, 0.0, 55.0], [-60.0, 0.0, 62.0], [0.0, 0.0, 50.0]])
    V = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.3, 0.0, -1.0]])
    P = m.intersect(F, V)
    np.testing.assert_allclose(P[0], [-20.0, 0.0, 55.0], atol=1e-12)
    assert np.isnan(P[1:]).all()
    for f, v, p in zip(F, V, P):
        R = cv2.Rodrigues(_look_along(v))[0]
        xn = (R @ v)[:2] / (R @ v)[2]
        o, _ = raytrace.trace(xn[None], np.eye(3), None, R, f, m)
        np.testing.assert_allclose(o[0], p, atol=1e-12)


def _look_along(v):
    """A Rodrigues vector of a rotation taking v to the camera's +z (R v ~ (0, 0, 1))."""
    v = v / np.linalg.norm(v)
    axis = np.cross(v, [0.0, 0.0, 1.0])
    s = np.linalg.norm(axis)
    angle = math.atan2(s, v[2])
    return axis / s * angle if s > 0 else np.zeros(3)


def test_unseen_points_give_nan(cam):
    """Inside the mirror's body, and straight above it (hidden by the mirror itself)."""
    m = cam.mirror
    inside = [0.0, 0.0, m.vertex_z + 0.5 * (m.z_rim - m.vertex_z)]
    above = [0.0, 0.0, m.z_rim + 500.0]
    xy = cam.project(np.array([inside, above]))
    assert np.isnan(xy).all()
    assert np.isnan(cam.project_directions(np.array([[0.0, 0.0, 1.0]]))).all()
    assert np.isfinite(cam.project_directions(np.array([[1.0, 0.0, -0.3]]))).all()  # seen


# -- the tables ---------------------------------------------------------------------------------
@pytest.mark.parametrize("depth", [None, 600.0])
@pytest.mark.parametrize("projection", ["cylindrical", "equirectangular"])
def test_panorama_table_within_tolerance_of_exact_projection(cam, projection, depth):
    size = (384, 96)
    mapx, mapy = views.init_panorama_maps(
        cam, size, projection=projection, m1type=cv2.CV_32FC1, depth=depth, yaw=0.0
    )
    lo, hi = views.visible_elevation_range(cam)
    lo = max(lo, views.CYLINDRICAL_MIN_ELEVATION)
    assert_matches_exact(
        cam, mapx, mapy, exact(cam, panorama_dirs(size, lo, hi, projection), depth)
    )


@pytest.mark.parametrize("depth", [None, 600.0])
def test_perspective_table_within_tolerance_of_exact_projection(cam, depth):
    size = (240, 180)
    K = K_from_fov(100.0, size)
    R = rotation_from_ypr(25.0, -20.0, 10.0)
    mapx, mapy = views.init_perspective_maps(cam, K, size, R=R, m1type=cv2.CV_32FC1, depth=depth)
    assert_matches_exact(cam, mapx, mapy, exact(cam, perspective_dirs(K, size, R), depth))


def test_fixed_point_table_is_cv2_convertMaps_of_the_float_table(cam):
    size = (256, 64)
    fx, fy = views.init_panorama_maps(cam, size, m1type=cv2.CV_32FC1)
    m1, m2 = views.init_panorama_maps(cam, size, m1type=cv2.CV_16SC2)
    r1, r2 = cv2.convertMaps(fx, fy, cv2.CV_16SC2)
    np.testing.assert_array_equal(m1, r1)
    np.testing.assert_array_equal(m2, r2)
