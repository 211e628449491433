"""calibrate_pattern on renders as hostile as real rigs (issue 17, item 9).

The ground truth is ``tests/quadric_rig.py``, a forward model that shares nothing with omnicam
(its own pinhole and distortion, quadric mirrors, reflection and Newton projection): unknown
hyperbolic mirrors, small boards, a wide-angle camera, swapped ``a, b``, a sphere and a
paraboloid. Every rig is misaligned (3 deg, 3.1 mm), the corners carry 0.15 px of noise, the rim
points 0.1 px; no mirror data and no ``K`` are given unless a case says so. Directions are
compared in the mirror frame of the truth, whose posture is in omnicam's gauge (the smallest
turn from the camera's +z to the mirror axis).
"""

import functools
import math
import warnings

import cv2
import numpy as np
import pytest
import quadric_rig as qr

import omnicam

SIZE = (1024, 768)
PATTERN, SQUARE = (7, 5), 60.0
NOISE_PX, RIM_NOISE_PX = 0.15, 0.1
N_VIEWS = 12
TILT_DEG, TILT_AZIMUTH_DEG, OFFSET = 3.0, 30.0, (1.5, -2.0, 1.9)
#: "within a few times the stated uncertainty": a ray error at most this many times the
#: report's ray standard deviation (median against median, worst against worst).
RAY_SIGMAS = 3.0
#: The held-out corner RMS of omnicam at most this times cv2.omnidir's (issue 17, item 5).
HELDOUT_RATIO = 1.05


def _misaligned(mirror, camera_z, size=SIZE, **kw):
    """The camera near ``(0, 0, camera_z)`` of the mirror frame, the mirror tilted and moved."""
    R, t = qr.posture(TILT_DEG, TILT_AZIMUTH_DEG, OFFSET, -camera_z)
    return qr.rig_filling(mirror, size, camera_z, R=R, t=t, **kw)


def _hyperbolic(a, b, rim_radius, **kw):
    """A misaligned rig of the hyperboloid ``a, b``, the camera near its lower focus."""
    return _misaligned(qr.hyperboloid(a, b, rim_radius), -math.hypot(a, b), **kw)


class Fit:
    """A rig, its boards, and what calibrate_pattern made of their noisy corners."""

    def __init__(
        self,
        rig,
        pattern=PATTERN,
        square=SQUARE,
        distance=(250.0, 1200.0),
        seed=0,
        mirror=None,
        lens=None,
        **kw,
    ):
        rng = np.random.default_rng(seed)
        self.rig, self.pattern, self.square = rig, pattern, square
        self.views = qr.place_boards(rig, N_VIEWS, pattern, square, distance, rng)
        self.corners = [q + rng.normal(0.0, NOISE_PX, q.shape) for _, _, q in self.views]
        self.rim = rig.rim_pixels(720) + rng.normal(0.0, RIM_NOISE_PX, (720, 2))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # (report.warnings and .dropped say it all)
            self.camera, self.report = omnicam.calibrate_pattern(
                None,
                pattern,
                square,
                mirror,
                image_size=rig.image_size,
                image_points=self.corners,
                boundary_points=self.rim,
                lens=lens,
                **kw,
            )

    def ray_errors_deg(self):
        """Angles between the calibrated and the true viewing directions of a grid of pixels
        inside the rim (none of them a corner), deg; NaN where the calibration sees nothing."""
        px = self.rig.mirror_pixels(step=8.0, outer=0.95)
        _, d_true = self.rig.trace(px)
        _, d = self.camera.unproject(px)
        return np.degrees(np.arccos(np.clip(np.sum(d * d_true, axis=1), -1.0, 1.0)))

    def warned(self, text):
        return [w for w in self.report.warnings if text in w]


def _assert_rays_within_their_uncertainty(fit):
    err = fit.ray_errors_deg()
    med, worst = fit.report.ray_std_deg
    assert np.isfinite(err).all()
    assert np.median(err) <= RAY_SIGMAS * med, (np.median(err), med)
    assert err.max() <= RAY_SIGMAS * worst, (err.max(), worst)


def _rays_within_their_uncertainty(fit):
    try:
        _assert_rays_within_their_uncertainty(fit)
    except AssertionError:
        return False
    return True


#: Warnings that tell the user a calibration is not to be trusted (the plausibility checks of
#: the single-image route, the solver's and the misfit's), as opposed to notes on weak
#: parameters whose rays are fine.
DISTRUST = (
    "from the mirror's lower focus",
    "the mirror axis is tilted",
    "fx / fy",
    "predict",
    "did not converge",
    "may not be a hyperboloid",
)


def _says_it_is_wrong(fit):
    return any(fit.warned(text) for text in DISTRUST)


def _assert_heldout_no_worse_than_omnidir(fit):
    held = fit.report.heldout
    assert sorted(held.rms) == sorted(held.omnidir) == sorted(fit.report.view_rms)
    assert held.median <= HELDOUT_RATIO * np.median(list(held.omnidir.values()))


# -- the forward model keeps its own promises ---------------------------------------------------
def test_own_pinhole_is_opencvs_projection_with_radial_distortion():
    rig = _misaligned(
        qr.hyperboloid(20.0, 8.0, 80.0),
        -math.hypot(20.0, 8.0),
        size=(1280, 1080),
        k1=-0.27,
        k2=0.06,
        f=180.0,
    )
    X = np.random.default_rng(0).uniform(-1.0, 1.0, (200, 3)) * [1.5, 1.5, 0.0] + [0, 0, 1.0]
    ref, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), rig.K, rig.D)
    assert np.abs(rig.pixels_of_camera_points(X) - ref.reshape(-1, 2)).max() < 1e-9
    xy = X[:, :2] / X[:, 2:]
    assert np.abs(qr.undistort(qr.distort(xy, rig.k1, rig.k2), rig.k1, rig.k2) - xy).max() < 1e-12


def test_aligned_hyperboloid_seen_from_its_lower_focus_reflects_every_ray_through_the_upper():
    a, b = 23.4, 28.1
    c = math.hypot(a, b)
    rig = qr.rig_filling(qr.hyperboloid(a, b, 30.0), SIZE, -c)
    P, d = rig.trace(rig.mirror_pixels(step=5.0))
    assert len(P) > 10000 and np.isfinite(d).all()
    e = np.array([0.0, 0.0, c]) - P  # the single viewpoint of the central camera
    miss = np.linalg.norm(e - np.sum(e * d, axis=1)[:, None] * d, axis=1)
    assert miss.max() < 1e-9 * c
    assert np.all(np.sum(e * d, axis=1) < 0)  # it lies behind the mirror, on the reflected line


def test_paraboloid_reflects_rays_parallel_to_its_axis_through_its_focus():
    h, z0 = 30.0, 5.0
    mirror = qr.paraboloid(h, z0, 30.0)
    xy = np.random.default_rng(1).uniform(-20.0, 20.0, (300, 2))
    O = np.column_stack([xy, np.full(len(xy), -40.0)])
    V = np.tile([0.0, 0.0, 1.0], (len(xy), 1))
    P, _ = qr.intersect(mirror, O, V)
    d = qr.reflect(mirror, P, V)
    e = np.array([0.0, 0.0, z0 + h / 2.0]) - P
    miss = np.linalg.norm(e - np.sum(e * d, axis=1)[:, None] * d, axis=1)
    assert np.abs(mirror.value(P)).max() < 1e-9 * h**2 and miss.max() < 1e-9 * h


def test_sphere_sends_rays_aimed_at_its_centre_straight_back():
    mirror = qr.sphere(40.0, 10.0, 30.0)
    V = np.random.default_rng(2).normal([0.0, 0.0, 1.0], 0.2, (300, 3))
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    O = np.array([0.0, 0.0, 10.0]) - 90.0 * V  # 90 mm before the centre along each ray
    P, _ = qr.intersect(mirror, O, V)
    ok = np.isfinite(P).all(axis=1)
    assert ok.sum() > 200  # (the others pass outside the rim)
    assert np.abs(qr.reflect(mirror, P[ok], V[ok]) + V[ok]).max() < 1e-12
    assert np.abs(np.linalg.norm(P[ok] - [0.0, 0.0, 10.0], axis=1) - 40.0).max() < 1e-9


@pytest.mark.parametrize(
    "mirror",
    [qr.hyperboloid(25.0, 21.0, 28.0), qr.sphere(40.0, 0.0, 30.0), qr.paraboloid(30.0, 0.0, 30.0)],
    ids=lambda m: m.name,
)
def test_projected_corners_trace_back_onto_the_board_corners(mirror):
    rig = _misaligned(mirror, mirror.height(0.0) - 60.0, k1=-0.05, k2=0.01)
    ((Rb, tb, q),) = qr.place_boards(
        rig, 1, PATTERN, SQUARE, (300.0, 900.0), np.random.default_rng(3)
    )
    P, d = rig.trace(q)
    n = Rb[:, 2]
    on_board = P + (((tb - P) @ n) / (d @ n))[:, None] * d
    X = qr.board_object_points(PATTERN, SQUARE) @ Rb.T + tb
    assert np.abs(on_board - X).max() < 1e-6  # mm, at 300-900 mm


def omnicam_truth(rig):
    """The hyperbolic ``rig`` as omnicam's camera (``qr.hyperboloid``: ``alpha = -a^2 / b^2``,
    ``gamma = a^2``), for what is evaluated at the truth (the benchmark's bound)."""
    m = rig.mirror
    a = math.sqrt(m.gamma)
    return omnicam.MisalignedHyperbolicCamera(
        rig.K,
        omnicam.HyperbolicMirror(a, a / math.sqrt(-m.alpha), m.rim_radius),
        cv2.Rodrigues(rig.R)[0].ravel(),
        rig.t,
        D=rig.D,
        image_size=rig.image_size,
    )


def test_the_hyperbolic_model_is_omnicams_too():
    """Not the ground truth's source, a cross-check: both models trace the same rays."""
    a, b, R = 25.0, 21.0, 28.0
    rig = _hyperbolic(a, b, R, k1=-0.05, k2=0.01)
    cam = omnicam_truth(rig)
    assert np.allclose((cam.mirror.a, cam.mirror.b, cam.mirror.rim_radius), (a, b, R))
    px = rig.mirror_pixels(step=10.0)
    P0, d0 = rig.trace(px)
    P1, d1 = cam.unproject(px)
    assert np.abs(d1 - d0).max() < 1e-9 and np.abs(P1 - P0).max() < 1e-9


# -- 1. unknown hyperbolic mirrors, nothing given ------------------------------------------------
def _drawn_mirrors(n=3, seed=17):
    rng = np.random.default_rng(seed)
    return [
        tuple(float(v) for v in (rng.uniform(15, 40), rng.uniform(15, 40), rng.uniform(20, 40)))
        for _ in range(n)
    ]


MIRRORS = _drawn_mirrors()
#: Draw 2 (a / b = 0.85, xi = 0.964: the HyperOmni kind): cv2.omnidir.calibrate (distortion
#: fixed) gives xi = 1.006 on this misaligned rig; the start takes it (clamped below 1).
DRAWS = [
    pytest.param(
        i,
        id="a={:.1f},b={:.1f},R={:.1f}".format(*m),
    )
    for i, m in enumerate(MIRRORS)
]


@functools.cache
def _unknown_mirror_fit(i):
    return Fit(_hyperbolic(*MIRRORS[i]), seed=i, heldout=3)


@pytest.mark.parametrize("i", DRAWS)
def test_unknown_mirror_rays_agree_with_the_truth_within_their_stated_uncertainty(i):
    fit = _unknown_mirror_fit(i)
    assert fit.report.rms < 1.2 * math.sqrt(2) * NOISE_PX  # at the noise floor
    _assert_rays_within_their_uncertainty(fit)


@pytest.mark.parametrize("i", DRAWS)
def test_unknown_mirror_heldout_corners_are_no_worse_than_omnidirs(i):
    _assert_heldout_no_worse_than_omnidir(_unknown_mirror_fit(i))


def test_unknown_mirror_held_shape_is_not_rejected_where_its_rays_are_right():
    """The check of the held shape costs a refinement only where it is needed."""
    for i in range(len(MIRRORS)):
        assert not _unknown_mirror_fit(i).warned("is rejected by the corners")


def test_unknown_hyperbolic_mirror_keeps_its_family_by_the_likelihood_ratio_test():
    """The data choose the family (issue 28 item 4): a hyperboloid's corners do not ask for a
    polynomial term, and the report says so and why."""
    for i in range(len(MIRRORS)):
        fit = _unknown_mirror_fit(i)
        assert isinstance(fit.camera.mirror, omnicam.HyperbolicMirror)
        assert fit.report.family.startswith("the mirror's family: a hyperboloid")
        assert "not above" in fit.report.family


# -- 2. small boards covering little of the mirror ---------------------------------------------
# (a mirror whose central start is accepted, so the case tells what small boards do)
SMALL_PATTERN, SMALL_SQUARE = (7, 6), 20.0


@functools.cache
def _small_boards_fit():
    return Fit(
        _hyperbolic(30.0, 23.0, 30.0),
        SMALL_PATTERN,
        SMALL_SQUARE,
        (300.0, 900.0),
        seed=1,
        heldout=3,
    )


def test_small_boards_cover_little_of_the_mirror():
    fit = _small_boards_fit()
    c, r = fit.rig.rim_centre_and_radius()
    areas = [cv2.contourArea(cv2.convexHull(q.astype(np.float32))) for q in fit.corners]
    assert max(areas) < 0.03 * math.pi * r * r


def test_small_boards_rays_agree_with_the_truth_within_their_stated_uncertainty():
    _assert_rays_within_their_uncertainty(_small_boards_fit())


def test_small_boards_heldout_corners_are_no_worse_than_omnidirs():
    _assert_heldout_no_worse_than_omnidir(_small_boards_fit())


# -- 2b. the camera's reflection: a circle of the camera body seen in the mirror ----------------
def _outline(rig, radius, z, off_axis, n=120, seed=3):
    """Pixels of the reflection of a circle of ``radius`` at ``z`` along the optical axis, its
    centre ``off_axis`` from it (camera frame), 0.1 px of noise."""
    th = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    P = np.stack([radius * np.cos(th) + off_axis, radius * np.sin(th), np.full(n, z)], 1)
    px = rig.project((P - rig.t) @ rig.R)  # X_cam = R X + t
    px = px[np.isfinite(px).all(axis=1)]
    return px + np.random.default_rng(seed).normal(0.0, 0.1, px.shape)


def test_camera_reflection_with_its_plane_known_keeps_the_rays_within_their_uncertainty():
    rig = _hyperbolic(*MIRRORS[1])
    fit = Fit(rig, seed=1, lens=_outline(rig, 12.0, 10.0, 0.0), lens_z=10.0)
    assert fit.report.lens_note.startswith("used") and fit.report.lens_rms < 0.2
    _assert_rays_within_their_uncertainty(fit)


def test_camera_reflection_with_its_plane_unknown_is_refused():
    """With ``z`` free the outline trades against the tilt: 1 mm off the axis it left these
    rays 3.2 times their stated uncertainty off, at 0.1 px RMS, without a word."""
    rig = _hyperbolic(*MIRRORS[1])
    with pytest.raises(ValueError, match="lens_z"):
        Fit(rig, seed=1, lens=_outline(rig, 12.0, 10.0, 1.0))


# -- 3. a wide-angle camera: f = 180 px at 1280x1080, k1 = -0.27 -------------------------------
# The rim's image 243 px in radius: the mirror must fill a cone of 125 deg, a flat hyperboloid
# (a / b = 3, xi = 0.57) close to the camera.
WIDE_SIZE = (1280, 1080)


@functools.cache
def _wide_fit():
    rig = _hyperbolic(18.0, 6.0, 100.0, size=WIDE_SIZE, k1=-0.27, k2=0.06, f=180.0)
    return Fit(rig, SMALL_PATTERN, 30.0, (300.0, 1500.0), seed=1)


def test_wide_angle_rays_agree_with_the_truth_within_their_stated_uncertainty():
    _assert_rays_within_their_uncertainty(_wide_fit())


def test_wide_angle_rig_is_started_with_k1_k2_and_its_held_shape_rejected():
    """The central fit with k1, k2 free starts it (the distortion-free one takes k1 into its
    aspect), and the check of the held shape rejects the central fit's a / b (3.18 for 3.00)."""
    fit = _wide_fit()
    assert fit.report.central.D[0] < 0
    assert fit.warned("is rejected by the corners") and fit.warned("a, b were estimated")


def test_wide_angle_rig_whose_distortion_free_central_fit_fails_is_started_with_k1_k2():
    """Seed 5: cv2.omnidir without distortion gives fx < 0 (refused), with k1, k2 free a fit."""
    rig = _hyperbolic(18.0, 6.0, 100.0, size=WIDE_SIZE, k1=-0.27, k2=0.06, f=180.0)
    fit = Fit(rig, SMALL_PATTERN, 30.0, (300.0, 1500.0), seed=5)
    assert fit.report.central.D[0] < 0
    _assert_rays_within_their_uncertainty(fit)


def test_wide_angle_rig_whose_k1_k2_central_fit_fails_is_started_with_its_whole_distortion():
    """Seed 0: cv2.omnidir with k1, k2 free fails too (fx < 0), with its whole distortion free
    it fits; its k1, k2 start the rig, which ends right."""
    rig = _hyperbolic(18.0, 6.0, 100.0, size=WIDE_SIZE, k1=-0.27, k2=0.06, f=180.0)
    fit = Fit(rig, SMALL_PATTERN, 30.0, (300.0, 1500.0), seed=0)
    assert fit.report.central.D[0] < 0
    _assert_rays_within_their_uncertainty(fit)


def test_wide_angle_rejected_shape_is_estimated_from_the_start_where_that_fits_better():
    """Seed 4, no distortion: the held shape is rejected, and the fit with a, b free carried on
    from the held solution ends in a minimum of its own (rays 6 times their stated uncertainty
    off); the same fit from the start camera ends lower, and right."""
    rig = _hyperbolic(18.0, 6.0, 100.0, size=WIDE_SIZE, f=180.0)
    fit = Fit(rig, SMALL_PATTERN, 30.0, (300.0, 1500.0), seed=4)
    assert fit.warned("is rejected by the corners")
    _assert_rays_within_their_uncertainty(fit)


def test_wide_angle_calibration_is_right_or_says_it_is_not():
    fit = _wide_fit()
    assert _rays_within_their_uncertainty(fit) or _says_it_is_wrong(fit)


def test_wide_angle_undistorted_calibration_is_right_or_says_it_is_not():
    rig = _hyperbolic(18.0, 6.0, 100.0, size=WIDE_SIZE, f=180.0)
    fit = Fit(rig, SMALL_PATTERN, 30.0, (300.0, 1500.0), seed=1)
    assert _rays_within_their_uncertainty(fit) or _says_it_is_wrong(fit)


# -- 4. swapped a, b given as the mirror ---------------------------------------------------------
A, B, RIM = 23.4, 28.1, 30.0  # the HyperOmni mirror


@functools.cache
def _data_sheet_fit(a, b):
    return Fit(_hyperbolic(A, B, RIM), seed=1, mirror=omnicam.HyperbolicMirror(a, b, RIM))


def test_swapped_mirror_parameters_are_named_as_a_possible_cause():
    assert _data_sheet_fit(B, A).warned("(swapped?)")
    assert not _data_sheet_fit(A, B).warned("(swapped?)")


# -- 5. mirrors that are not hyperboloids ------------------------------------------------------
NOT_HYPERBOLIC = {
    "sphere": (qr.sphere(40.0, 0.0, 30.0), -90.0),  # vertex at -40, camera 50 below it
    "paraboloid": (qr.paraboloid(30.0, 0.0, 30.0), -50.0),
}


@functools.cache
def _unknown(name):
    mirror, camera_z = NOT_HYPERBOLIC[name]
    return Fit(_misaligned(mirror, camera_z), seed=1)


@pytest.mark.parametrize("name", sorted(NOT_HYPERBOLIC))
def test_unknown_mirror_that_is_no_hyperboloid_is_calibrated_as_an_asphere(name):
    # Mei's xi (2.25, 1.56) rejects the hyperboloid: the generic start (Taylor model ->
    # aligned aspheric rig), the shape and f free in the adjustment
    fit = _unknown(name)
    assert isinstance(fit.camera.mirror, omnicam.AsphericMirror)
    assert fit.warned("which no hyperboloid has") and fit.warned("even asphere")
    assert fit.report.rms < 1.6 * NOISE_PX * math.sqrt(2)
    _assert_rays_within_their_uncertainty(fit)


def test_unknown_sphere_and_paraboloid_get_their_conic_constants():
    assert _unknown("sphere").camera.mirror.k == pytest.approx(0.0, abs=0.3)
    assert _unknown("paraboloid").camera.mirror.k == pytest.approx(-1.0, abs=0.3)


def test_sphere_given_as_an_asphere_is_a_start_and_its_shape_is_refined_on_request():
    mirror, camera_z = NOT_HYPERBOLIC["sphere"]
    sheet = omnicam.AsphericMirror.sphere(41.0, RIM)  # a data sheet 2.5 % off
    fit = Fit(_misaligned(mirror, camera_z), seed=1, mirror=sheet, refine_mirror_shape=True)
    assert isinstance(fit.camera.mirror, omnicam.AsphericMirror)
    assert fit.camera.mirror.R == pytest.approx(40.0, rel=0.03)
    _assert_rays_within_their_uncertainty(fit)


@functools.cache
def _taken_for_hyperbolic(name):
    mirror, camera_z = NOT_HYPERBOLIC[name]
    return Fit(_misaligned(mirror, camera_z), seed=1, mirror=omnicam.HyperbolicMirror(A, B, RIM))


@pytest.mark.parametrize("name", sorted(NOT_HYPERBOLIC))
def test_mirror_taken_for_a_hyperboloid_is_flagged_as_implausible(name):
    assert _taken_for_hyperbolic(name).warned("from the mirror's lower focus")


@pytest.mark.parametrize("name", sorted(NOT_HYPERBOLIC))
def test_mirror_taken_for_a_hyperboloid_is_said_to_may_not_be_one(name):
    assert _taken_for_hyperbolic(name).warned("may not be a hyperboloid")
