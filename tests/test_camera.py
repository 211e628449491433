"""The camera model: ray tracing (eqs. 6-19), the exact inverse, NaN rules, shapes, validation."""

import math

import cv2
import naive
import numpy as np
import pytest
from conftest import RIGS, annulus_pixels

from omnicam import HyperbolicMirror, MisalignedHyperbolicCamera, synthetic

PX_TOL = 1e-6


def point_to_ray_distance(X, P, d):
    w = X - P
    return np.linalg.norm(w - d * np.einsum("ij,ij->i", w, d)[:, None], axis=1)


# -- round trips over the whole visible annulus (one generic test per rig) --------------------
@pytest.mark.parametrize("depth", [20.0, 1000.0, 1e6])
def test_project_of_unproject_returns_the_pixel(rig, depth):
    pix = annulus_pixels(rig)
    P, d = rig.unproject(pix)
    back = rig.project(P + depth * d)
    err = np.linalg.norm(back - pix, axis=1)
    assert np.isfinite(err).all(), f"{np.isnan(err).sum()} visible points gave NaN"
    assert err.max() < PX_TOL


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("layout", [(-1, 2), (-1, 1, 2)], ids=["N2", "N12"])
def test_project_directions_of_unproject_returns_the_pixel(rig, dtype, layout):
    pix = annulus_pixels(rig).astype(dtype).reshape(layout)
    _, d = rig.unproject(pix)
    back = rig.project_directions(d.astype(dtype))
    assert back.shape == pix.shape and back.dtype == np.float64
    if dtype == np.float32:  # directions rounded to float32 move the pixel by ~1e-4 px
        back = rig.project_directions(d)
    err = np.linalg.norm((back - pix).reshape(-1, 2), axis=1)
    assert np.isfinite(err).all()
    assert err.max() < PX_TOL


def test_unproject_of_project_passes_through_the_point(rig):
    rng = np.random.default_rng(1)
    vp, _ = rig.best_fit_viewpoint()
    v = rng.normal(size=(4000, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    X = vp + v * rng.uniform(30.0, 5000.0, size=(len(v), 1))
    pix = rig.project(X)
    seen = np.isfinite(pix[:, 0])
    assert seen.sum() > 1000  # the mirror sees most of the lower hemisphere
    P, d = rig.unproject(pix[seen])
    dist = point_to_ray_distance(X[seen], P, d)
    in_front = np.einsum("ij,ij->i", X[seen] - P, d)
    assert (in_front > 0).all()
    # 1e-6 px at the point's distance, in mm
    f = rig.K[0, 0]
    assert (dist <= PX_TOL * np.linalg.norm(X[seen] - P, axis=1) / f * 10).all()


def test_project_matches_slow_reference_least_squares():
    cam = RIGS["misaligned"]
    rng = np.random.default_rng(2)
    pix = annulus_pixels(cam, step=40.0)[::7]
    P, d = cam.unproject(pix)
    X = P + d * rng.uniform(50, 3000, size=(len(P), 1))
    fast = cam.project(X)
    centre = cam.rim_image_points().mean(axis=0)
    for x, p in zip(X, fast):
        start = p + 0.5 * (centre - p) / np.linalg.norm(centre - p)  # half a pixel off, inside
        ref = naive.project_point(
            x, cam.K, cam.R, cam.tvec, cam.mirror.a, cam.mirror.b, cam.mirror.rim_radius, start
        )
        assert np.linalg.norm(ref - p) < 1e-6


def test_unproject_matches_slow_reference_ray_tracer(rig):
    pix = annulus_pixels(rig, step=25.0)
    pix = np.concatenate([pix, [[0.0, 0.0], [-50.0, 250.0]]])  # two that miss the mirror
    P, d = rig.unproject(pix)
    m = rig.mirror
    pinhole = pix
    if rig.D is not None:  # the reference traces the undistorted (pinhole) pixel
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 500, 1e-16)
        Kn = rig.K.copy()
        Kn[0, 1] = 0.0
        pinhole = cv2.undistortPoints(
            pix.reshape(-1, 1, 2), Kn, rig.D, R=None, P=Kn, criteria=crit
        ).reshape(-1, 2)
    for i, (u, v) in enumerate(pinhole):
        ref = naive.trace_pixel(u, v, rig.K, rig.R, rig.tvec, m.a, m.b, m.rim_radius)
        if ref is None:
            assert np.isnan(P[i]).all() and np.isnan(d[i]).all()
        else:
            np.testing.assert_allclose(P[i], ref[0], atol=1e-9)
            np.testing.assert_allclose(d[i], ref[1], atol=1e-12)


# -- the optics --------------------------------------------------------------------------------
def test_reflected_rays_obey_the_reflection_law(rig):
    pix = annulus_pixels(rig, step=10.0)
    P, d = rig.unproject(pix)
    n = rig.mirror.unit_normal(P)
    incoming = P - rig.camera_center
    incoming /= np.linalg.norm(incoming, axis=1, keepdims=True)
    # equal angles with the normal, on opposite sides
    np.testing.assert_allclose(
        np.einsum("ij,ij->i", d, n), -np.einsum("ij,ij->i", incoming, n), atol=1e-12
    )
    # incoming, normal and reflected ray are coplanar
    np.testing.assert_allclose(np.einsum("ij,ij->i", np.cross(incoming, n), d), 0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1, atol=1e-12)
    # origins lie on the mirror sheet (eq. 1) inside the rim
    np.testing.assert_allclose(P[:, 2], rig.mirror.surface_z(P[:, 0], P[:, 1]), rtol=1e-12)
    assert (np.hypot(P[:, 0], P[:, 1]) <= rig.mirror.rim_radius + 1e-12).all()


def test_aligned_rig_reflected_rays_pass_through_outer_focus():
    cam = RIGS["aligned"]
    P, d = cam.unproject(annulus_pixels(cam))
    focus = np.array([[0.0, 0.0, cam.mirror.c]])
    assert point_to_ray_distance(np.repeat(focus, len(P), 0), P, d).max() < 1e-11
    vp, rms = cam.best_fit_viewpoint()
    np.testing.assert_allclose(vp, focus[0], atol=1e-9)
    assert rms < 1e-9


def test_aligned_rig_agrees_with_hyperomni_equations_2_to_5():
    cam = RIGS["aligned"]
    m, K = cam.mirror, cam.K
    pix = annulus_pixels(cam, step=9.0)
    P, d = cam.unproject(pix)
    for (u, v), P_i, d_i in zip(pix, P, d):
        ref, focus = naive.hyperomni_direction(u, v, m.a, m.b, K[0, 0], K[0, 2], K[1, 2])
        if abs(u - K[0, 2]) + abs(v - K[1, 2]) < 1e-9:
            ref = np.array([0.0, 0.0, -1.0])
        np.testing.assert_allclose(d_i, ref, atol=1e-12)
        # eq. 3: the ray lies on the line through (0, 0, c)
        assert np.linalg.norm(np.cross(P_i - focus, d_i)) < 1e-11


def test_misaligned_rig_is_not_central():
    _, rms = RIGS["misaligned"].best_fit_viewpoint()
    assert rms > 0.05  # mm: no single viewpoint


def test_best_fit_viewpoint_minimises_mean_squared_distance():
    cam = RIGS["misaligned"]
    vp, rms = cam.best_fit_viewpoint()
    P, d = cam.unproject(cam.mirror_pixels())

    def msd(p):
        return np.mean(point_to_ray_distance(np.broadcast_to(p, P.shape), P, d) ** 2)

    assert math.isclose(math.sqrt(msd(vp)), rms, rel_tol=1e-9)
    for step in np.eye(3) * 0.01:
        assert msd(vp + step) > msd(vp) and msd(vp - step) > msd(vp)


# -- NaN rules -------------------------------------------------------------------------------
def test_pixel_outside_rim_gives_nan(rig):
    far = np.array([[-1000.0, -1000.0], [5000.0, 250.0], [np.nan, 3.0]])
    P, d = rig.unproject(far)
    assert np.isnan(P).all() and np.isnan(d).all()


def test_unseen_point_gives_nan(rig):
    m = rig.mirror
    X = np.array(
        [
            [0.0, 0.0, m.z_rim + 1000.0],  # straight above the mirror: behind it
            [1.0, 2.0, m.b + 5.0],  # inside the mirror body
            [np.nan, 0.0, -100.0],  # NaN input
            [0.0, 0.0, np.inf],
        ]
    )
    assert np.isnan(rig.project(X)).all()
    dirs = np.array([[0.0, 0.0, 1.0], [0.2, 0.1, 0.95], [0.0, 0.0, 0.0], [np.nan, 1, 0]])
    assert np.isnan(rig.project_directions(dirs)).all()


def test_directions_above_the_rim_horizon_give_nan_and_below_are_seen():
    cam = RIGS["aligned"]
    m = cam.mirror
    rim_elev = math.atan2(m.z_rim - m.c, m.rim_radius)
    el = np.array([rim_elev - 0.01, rim_elev + 0.01])
    d = np.stack([np.cos(el), np.zeros(2), np.sin(el)], axis=1)
    pix = cam.project_directions(d)
    assert np.isfinite(pix[0]).all() and np.isnan(pix[1]).all()


# -- shapes and dtypes --------------------------------------------------------------------------
def test_opencv_point_layouts_and_float32_are_accepted():
    cam = RIGS["misaligned"]
    pix = annulus_pixels(cam, step=50.0)
    P, d = cam.unproject(pix)
    P3, d3 = cam.unproject(pix.reshape(-1, 1, 2).astype(np.float32))
    assert P3.shape == (len(pix), 1, 3) and P3.dtype == np.float64
    np.testing.assert_allclose(P3.reshape(-1, 3), cam.unproject(pix.astype(np.float32))[0])
    X = (P + 500 * d).reshape(-1, 1, 3)
    x3 = cam.project(X.astype(np.float32))
    assert x3.shape == (len(pix), 1, 2) and x3.dtype == np.float64
    assert cam.project_directions(d.reshape(-1, 1, 3)).shape == (len(pix), 1, 2)
    assert cam.project(np.zeros((0, 3))).shape == (0, 2)


@pytest.mark.parametrize(
    "bad",
    [
        np.zeros((5, 3)),
        np.zeros((5,)),
        np.zeros((5, 2, 2)),
        np.array([["a", "b"]]),
        np.zeros((5, 1, 3)),
    ],
)
def test_wrong_pixel_shape_raises_value_error(bad):
    with pytest.raises(ValueError, match="image_points"):
        RIGS["aligned"].unproject(bad)


def test_wrong_point_shape_raises_value_error():
    with pytest.raises(ValueError, match="object_points"):
        RIGS["aligned"].project(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="directions"):
        RIGS["aligned"].project_directions(np.zeros((4, 1, 2)))


def test_project_with_rvec_tvec_moves_object_points_like_cv2():
    cam = RIGS["misaligned"]
    rvec, tvec = np.array([0.1, -0.2, 0.3]), np.array([10.0, -20.0, -300.0])
    Xo = np.random.default_rng(3).uniform(-200, 200, size=(50, 3))
    Xm = Xo @ cv2.Rodrigues(rvec)[0].T + tvec
    np.testing.assert_array_equal(cam.project(Xo, rvec, tvec), cam.project(Xm))


# -- distortion and skew -------------------------------------------------------------------------
def test_distortion_is_opencvs_model_applied_to_the_pinhole_image():
    cam = RIGS["distorted"]
    pinhole = cam.replace(D=None)
    X = cam.unproject(annulus_pixels(cam, step=20.0))
    X = X[0] + 800 * X[1]
    p_dist, p_pin = cam.project(X), pinhole.project(X)
    # independent: undistorted pixel -> normalised -> cv2.projectPoints with D -> K
    xn = np.linalg.solve(cam.K, np.c_[p_pin, np.ones(len(p_pin))].T).T
    ref, _ = cv2.projectPoints(xn.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.D)
    np.testing.assert_allclose(p_dist, ref.reshape(-1, 2), atol=1e-6)
    assert np.abs(p_dist - p_pin).max() > 2  # the distortion is not negligible


def test_skew_is_honoured():
    cam = RIGS["skew"]
    P, d = cam.unproject(np.array([[300.0, 200.0]]))
    Xc = cam.R @ P[0] + cam.tvec
    np.testing.assert_allclose(cam.K @ (Xc / Xc[2]), [300.0, 200.0, 1.0], atol=1e-9)


# -- the value object --------------------------------------------------------------------------
def test_gauge_rotation_about_the_mirror_axis_is_removed():
    cam = RIGS["misaligned"]
    R_spun = cam.R @ cv2.Rodrigues(np.array([0.0, 0.0, 0.7]))[0]
    spun = MisalignedHyperbolicCamera(cam.K, cam.mirror, cv2.Rodrigues(R_spun)[0], cam.tvec)
    np.testing.assert_allclose(spun.rvec, cam.rvec, atol=1e-12)
    axis = cam.R[:, 2]
    np.testing.assert_allclose(
        cam.rvec,
        np.cross([0, 0, 1], axis) / np.linalg.norm(np.cross([0, 0, 1], axis)) * math.acos(axis[2]),
        atol=1e-12,
    )
    assert not np.any(RIGS["aligned"].rvec)
    # the gauge is idempotent to the last bit: a saved and reloaded camera compares equal
    for cam in RIGS.values():
        assert np.array_equal(
            MisalignedHyperbolicCamera(cam.K, cam.mirror, cam.rvec, cam.tvec).rvec, cam.rvec
        )


def test_camera_is_immutable():
    cam = RIGS["misaligned"]
    with pytest.raises(ValueError):
        cam.K[0, 0] = 1.0
    with pytest.raises(AttributeError):
        cam.K = np.eye(3)


def test_scaled_camera_sees_the_same_rays_at_scaled_pixels():
    cam = RIGS["distorted"]
    big = cam.scaled((1000, 750))
    pix = annulus_pixels(cam, step=30.0)
    scaled_pix = (pix + 0.5) * [2.0, 1.5] - 0.5
    _, d0 = cam.unproject(pix)
    _, d1 = big.unproject(scaled_pix)
    np.testing.assert_allclose(d1, d0, atol=1e-9)
    assert big.image_size == (1000, 750)
    with pytest.raises(ValueError, match="image_size"):
        cam.replace(image_size=None).scaled((10, 10))


def test_the_camera_reflection_is_kept_by_scaled_and_replace_and_compared():
    cam = RIGS["distorted"]
    assert cam.camera_reflection is None
    body = cam.replace(camera_reflection=(9, 12))
    assert body.camera_reflection == (9.0, 12.0) and isinstance(body.camera_reflection.r, float)
    assert body.scaled((1000, 750)).camera_reflection == (9.0, 12.0)  # the body's, any size
    assert body.replace(D=None).camera_reflection == (9.0, 12.0)
    assert body.replace(camera_reflection=None) == cam
    assert body != cam and body != cam.replace(camera_reflection=(9.0, 12.5))
    assert "camera_reflection=(9.0, 12.0)" in repr(body) and "camera_reflection" not in repr(cam)


def test_aligned_constructor_is_the_hyperomni_rig():
    m = synthetic.default_mirror()
    cam = MisalignedHyperbolicCamera.aligned(m, 600.0, 320.0, 240.0)
    np.testing.assert_array_equal(cam.K, [[600, 0, 320], [0, 600, 240], [0, 0, 1]])
    np.testing.assert_allclose(cam.camera_center, [0, 0, -m.c])


@pytest.mark.parametrize(
    "K, match",
    [
        (np.eye(2), "3x3"),
        (np.zeros((3, 3)), "K"),
        (np.full((3, 3), np.nan), "finite"),
        ([[500, 0, 10], [0, 500, 10], [0, 0, 2]], "last row"),
    ],
)
def test_bad_K_raises_value_error(K, match):
    with pytest.raises(ValueError, match=match):
        MisalignedHyperbolicCamera(K, synthetic.default_mirror(), np.zeros(3), [0, 0, 40])


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(D=[0.1, 0.2, 0.3]), "D must have"),
        (dict(D=[0.1] * 6), "D must have"),
        (dict(rvec=[0, 0]), "rvec"),
        (dict(tvec=[0, np.inf, 1]), "tvec"),
        (dict(image_size=(0, 10)), "image_size"),
        (dict(image_size=(10.5, 10)), "image_size"),
        (dict(mirror=(1, 2, 3)), "mirror"),
        (dict(camera_reflection=(0.0, 12.0)), "camera_reflection"),
        (dict(camera_reflection=(9.0, np.nan)), "camera_reflection"),
        (dict(camera_reflection=(9.0, 12.0, 1.0)), "camera_reflection"),
        (dict(camera_reflection=9.0), "camera_reflection"),
    ],
)
def test_bad_parameters_raise_value_error(kwargs, match):
    args = dict(
        K=RIGS["aligned"].K, mirror=synthetic.default_mirror(), rvec=np.zeros(3), tvec=[0, 0, 40.0]
    )
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        MisalignedHyperbolicCamera(**args)


@pytest.mark.parametrize("a, b, r", [(0, 1, 1), (1, -1, 1), (1, 1, np.nan), (1, 1, "x")])
def test_mirror_parameters_must_be_positive_and_finite(a, b, r):
    with pytest.raises(ValueError, match="positive finite"):
        HyperbolicMirror(a, b, r)


def test_numpy_reference_tracer_matches_the_kernel(rig):
    from omnicam import raytrace

    px = annulus_pixels(rig, 200)
    if rig.D is not None:
        xn = raytrace.undistort_normalized(px, rig.K, rig.D)
    else:
        Ki = np.linalg.inv(rig.K)
        xn = px @ Ki[:2, :2].T + Ki[:2, 2]
    P, V = raytrace.trace_normalized(xn, rig.R, rig.camera_center, rig.mirror)
    P0, V0 = rig.unproject(px)
    assert np.allclose(P, P0, atol=1e-9, equal_nan=True)
    assert np.allclose(V, V0, atol=1e-12, equal_nan=True)
