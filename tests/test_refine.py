"""The non-linear refinement of the 5-DOF posture and its uncertainty (calibration.refine).

Called directly, on data made by the camera model (rim points, far-line pixels, the outline
of the camera's reflection): the residual terms vanish at the truth and are in pixels, the
refinement recovers a known posture from a perturbed start, and the stated uncertainty is the
scatter that injected noise really causes.
"""

import math

import cv2
import numpy as np
import pytest
from conftest import RANDOM_RIGS, RIGS, candidates_of

from omnicam import synthetic
from omnicam.calibration import refine, reflection, steps

CAM = RIGS["misaligned"]  # tilt 3 deg, offset a few mm
STEPS = np.array([1e-7, 1e-7, 1e-6, 1e-6, 1e-6])  # radians, then mm
R_C, Z_C = 9.0, 12.0  # a circle of the camera's front, as tests/barrel.py's
#: three straight segments about 20 m from the mirror (mm, mirror frame), below the horizon
SEGMENTS = [
    ((20000.0, -5000.0, -8000.0), (15000.0, 9000.0, -6000.0)),
    ((-3000.0, 25000.0, -2000.0), (-18000.0, 12000.0, -9000.0)),
    ((-20000.0, -20000.0, -15000.0), (5000.0, -30000.0, -12000.0)),
]


def normalized(cam, px):
    Ki = np.linalg.inv(cam.K)
    return px @ Ki[:2, :2].T + Ki[:2, 2]


def start_from(cam, x):
    """``(rvec, tvec)`` of the posture ``x`` away from the truth (axis angles, origin shift)."""
    R, t = refine.perturbed_posture(cam.R, cam.tvec, np.asarray(x, np.float64))
    return cv2.Rodrigues(R)[0].ravel(), t


def offsets(cam, res):
    """The refined posture in the truth's 5 parameters (radians, mm)."""
    return refine.posture_offsets(cam.rvec, cam.tvec, res.rvec, res.tvec)


def far_lines(cam):
    """Pixels of ``SEGMENTS`` (exact projection) and their undistorted normalised coordinates."""
    px = [synthetic.line_pixels(cam, a, b, 30) for a, b in SEGMENTS]
    assert [len(p) for p in px] == [30, 30, 30]
    return px, [normalized(cam, p) for p in px]


def curve_normals(curve):
    """Unit normals of a closed, densely sampled curve (central differences of its samples)."""
    tangent = np.roll(curve, -1, axis=0) - np.roll(curve, 1, axis=0)
    n = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


# -- the residual terms ---------------------------------------------------------------------------
def test_rim_residuals_vanish_at_the_true_posture():
    for cam in RANDOM_RIGS[:10]:
        term = refine.RimTerm(cam.K, cam.mirror, cam.R, cam.tvec, cam.rim_image_points(90))
        assert len(term) == 90 and term.n_nuisance == 0
        assert np.abs(term.residuals(cam.R, cam.tvec)).max() < 1e-9


def test_rim_residual_is_the_signed_pixel_distance_to_the_rim_image():
    # each boundary point moved off the rim image by a known distance along its normal
    dense = CAM.rim_image_points(36000)  # every 100th sample is one of the 360 points
    rim, normal = dense[::100], curve_normals(dense)[::100]
    delta = np.random.default_rng(0).uniform(-2.0, 2.0, len(rim))
    moved = rim + delta[:, None] * normal
    term = refine.RimTerm(CAM.K, CAM.mirror, CAM.R, CAM.tvec, moved)
    r = term.residuals(CAM.R, CAM.tvec)
    sign = np.sign(r[0] / delta[0])
    np.testing.assert_allclose(r, sign * delta, atol=1e-6)
    # the same distance by brute force against the densely sampled rim image
    brute = np.array([np.linalg.norm(dense - p, axis=1).min() for p in moved])
    np.testing.assert_allclose(np.abs(r), brute, atol=1e-4)


def test_rim_jacobian_is_the_derivative_of_the_residuals():
    noisy = CAM.rim_image_points(120) + np.random.default_rng(1).normal(size=(120, 2)) * 0.5
    term = refine.RimTerm(CAM.K, CAM.mirror, CAM.R, CAM.tvec, noisy)

    def posture(x):
        return refine.perturbed_posture(CAM.R, CAM.tvec, x)

    x0 = np.array([1e-3, -2e-3, 0.1, 0.2, -0.1])
    J, J_nuisance = term.jacobian(posture, x0, np.zeros(0), STEPS)
    assert J.shape == (120, 5) and J_nuisance.shape == (120, 0)
    for k, h in enumerate([1e-6, 1e-6, 1e-5, 1e-5, 1e-5]):
        e = np.eye(5)[k] * h
        fd = (term.residuals(*posture(x0 + e)) - term.residuals(*posture(x0 - e))) / (2 * h)
        np.testing.assert_allclose(J[:, k], fd, rtol=1e-4, atol=1e-4 * np.abs(fd).max())


def test_far_line_residuals_vanish_at_the_truth_and_not_at_the_other_posture():
    cam = RANDOM_RIGS[2]
    _, xn = far_lines(cam)
    term = refine.FarLineTerm(cam.K, cam.mirror, cam.R, cam.tvec, xn, 3e4)
    assert len(term) == 90 and term.n_nuisance == 12
    # the lines started from the true posture's rays (Plucker fit) are the true lines
    at_truth = np.abs(term.residuals(cam.R, cam.tvec, term.x0())).max()
    assert at_truth < 1e-4  # px
    for i, (a, b) in enumerate(SEGMENTS):
        Q, e = term.line(i, term.x0()[4 * i : 4 * i + 4])
        u = (np.subtract(b, a)) / np.linalg.norm(np.subtract(b, a))
        # to round-off of the SVD in the Plucker fit, which the BLAS kernel changes (1.5e-8 rad
        # with OpenBLAS's Haswell kernel, under 1e-8 with the default): the same 5e-8 as the
        # point's 1e-3 mm at 20 m
        assert np.linalg.norm(np.cross(e, u)) < 5e-8
        assert np.linalg.norm(np.cross(Q - a, u)) < 1e-3  # mm, 20 m away
    other = max(
        (c for c in candidates_of(cam) if c.physical),
        key=lambda c: np.linalg.norm(c.tvec - cam.tvec),
    )
    wrong = refine.FarLineTerm(cam.K, cam.mirror, other.R, other.tvec, xn, 3e4)
    assert np.abs(wrong.residuals(other.R, other.tvec, wrong.x0())).max() > 1e3 * at_truth


def test_reflection_residuals_vanish_at_the_truth_and_are_in_pixels():
    dense, _ = reflection.outline_pixels(CAM, R_C, Z_C, 720)
    outline, normal = dense[::10], curve_normals(dense)[::10]
    term = refine.ReflectionTerm(
        CAM.K, CAM.mirror, CAM.R, CAM.tvec, normalized(CAM, outline), R_C, Z_C, True, True
    )
    assert len(term) == 72 and term.n_nuisance == 0 and term.prior is None
    assert np.abs(term.residuals(CAM.R, CAM.tvec, term.x0())).max() < 1e-8
    # an outline 0.02 px off the true one, along its normal, misses the circle by 0.02 px
    moved = outline + 0.02 * normal
    term = refine.ReflectionTerm(
        CAM.K, CAM.mirror, CAM.R, CAM.tvec, normalized(CAM, moved), R_C, Z_C, True, True
    )
    np.testing.assert_allclose(np.abs(term.residuals(CAM.R, CAM.tvec, term.x0())), 0.02, rtol=1e-2)


def test_reflection_term_frees_r_and_z_unless_known_and_pulls_a_free_z_weakly():
    xn = normalized(CAM, reflection.outline_pixels(CAM, R_C, Z_C, 48)[0])
    free = refine.ReflectionTerm(CAM.K, CAM.mirror, CAM.R, CAM.tvec, xn, R_C, Z_C)
    assert free.n_nuisance == 2 and len(free) == 49  # the outline and the pull on z
    np.testing.assert_array_equal(free.x0(), [R_C, Z_C])
    assert free.circle(np.array([8.0, 15.0])) == (8.0, 15.0)
    res = free.residuals(CAM.R, CAM.tvec, np.array([R_C, Z_C + 1.0]))
    assert res[-1] == pytest.approx(1.0 * 1e-2 / CAM.mirror.c)
    known_z = refine.ReflectionTerm(CAM.K, CAM.mirror, CAM.R, CAM.tvec, xn, R_C, Z_C, False, True)
    assert known_z.n_nuisance == 1 and len(known_z) == 48
    assert known_z.circle(np.array([8.5])) == (8.5, Z_C)


# -- refine_posture -------------------------------------------------------------------------------
@pytest.mark.parametrize("i", range(4))
def test_rim_refinement_recovers_the_posture_from_a_perturbed_start(i):
    cam = RANDOM_RIGS[i]
    rim = cam.rim_image_points(200)
    x = np.random.default_rng(i).uniform(-1, 1, 5) * [0.005, 0.005, 0.5, 0.5, 0.5]
    res = refine.refine_posture(cam.K, cam.mirror, *start_from(cam, x), rim)
    assert res.accepted and res.cost_final < 1e-20 < res.cost_initial
    assert np.abs(offsets(cam, res)).max() < 1e-9
    assert res.rim_rms < 1e-9 and res.n_rim == 200
    assert math.isnan(res.line_rms) and res.lines == []
    assert math.isnan(res.reflection_rms) and math.isnan(res.r) and math.isnan(res.z)


def test_at_the_truth_the_refinement_keeps_the_start_and_reports_it_not_accepted():
    rim = CAM.rim_image_points(200)
    res = refine.refine_posture(CAM.K, CAM.mirror, CAM.rvec, CAM.tvec, rim)
    assert not res.accepted and res.nfev == 0  # stage 2 skipped: the start is exact
    assert res.cost_final == res.cost_initial < 1e-20
    np.testing.assert_allclose(res.rvec, CAM.rvec, atol=1e-15)
    np.testing.assert_array_equal(res.tvec, CAM.tvec)


def test_a_start_turned_about_the_mirror_axis_comes_back_in_the_gauge():
    # X_cam = R Rz(theta) X_mirror is the same rig (a body of revolution): the result is the
    # gauge of conventions.md, the smallest rotation taking +z to the mirror axis
    rim = CAM.rim_image_points(200)
    turned = CAM.R @ cv2.Rodrigues(np.array([0.0, 0.0, 0.7]))[0]
    res = refine.refine_posture(CAM.K, CAM.mirror, cv2.Rodrigues(turned)[0].ravel(), CAM.tvec, rim)
    np.testing.assert_allclose(res.rvec, CAM.rvec, atol=1e-12)
    assert res.rvec[2] == pytest.approx(0.0, abs=1e-15)


def test_far_lines_and_rim_recover_the_posture_and_lines_in_the_planes_of_the_segments():
    _, xn = far_lines(CAM)
    start = start_from(CAM, [3e-4, -2e-4, 0.03, -0.02, 0.04])
    res = refine.refine_posture(
        CAM.K, CAM.mirror, *start, CAM.rim_image_points(200), xn, max_nfev=steps.LINES_MAX_NFEV
    )  # the budget calibrate() gives far lines (15, the rim's, stopped short on one BLAS kernel)
    assert res.accepted
    assert np.abs(offsets(CAM, res)).max() < 1e-5  # rad, mm (forward differences)
    assert res.line_rms < 1e-5 and res.rim_rms < 1e-6
    # a nearly central rig does not fix a line's distance within the plane of its rays
    # (eq. 31), only that plane: each fitted line lies in the plane of its segment and the
    # viewpoint
    assert len(res.lines) == 3
    vp, _ = CAM.best_fit_viewpoint()
    for (Q, e), (a, b) in zip(res.lines, SEGMENTS):
        N = np.cross(np.subtract(a, vp), np.subtract(b, vp))
        N /= np.linalg.norm(N)
        assert np.linalg.norm(e) == pytest.approx(1.0)
        assert abs(e @ N) < 1e-5 and abs((Q - vp) @ N) < 1e-5 * np.linalg.norm(Q - vp)


def test_known_z_reflection_and_rim_recover_the_posture_and_the_circle():
    xn = normalized(CAM, reflection.outline_pixels(CAM, R_C, Z_C, 64)[0])
    start = start_from(CAM, [0.003, -0.002, 0.3, -0.2, 0.4])
    spec = (xn, 8.0, Z_C, False, True)  # r started 1 mm off, z known
    res = refine.refine_posture(
        CAM.K, CAM.mirror, *start, CAM.rim_image_points(200), reflection=spec, max_nfev=100
    )
    assert res.accepted
    assert np.abs(offsets(CAM, res)).max() < 1e-9
    assert res.r == pytest.approx(R_C, abs=1e-9) and res.z == Z_C
    assert res.reflection_rms < 1e-9


def test_robust_weights_keep_outliers_on_the_rim_from_pulling_the_posture():
    rng = np.random.default_rng(1)
    rim = CAM.rim_image_points(200)
    centre = rim.mean(axis=0)
    bad = rim + rng.normal(size=rim.shape) * 0.05
    idx = rng.choice(200, 20, replace=False)  # 10 % of the points 5 px outside the rim
    out = rim[idx] - centre
    bad[idx] += 5.0 * out / np.linalg.norm(out, axis=1, keepdims=True)
    err = {}
    for robust in (True, False):
        res = refine.refine_posture(CAM.K, CAM.mirror, CAM.rvec, CAM.tvec, bad, robust=robust)
        assert res.accepted and res.cost_final < res.cost_initial
        err[robust] = math.degrees(float(np.linalg.norm(offsets(CAM, res)[:2])))
    # what the 180 good points allow (RMS axis error): the robust fit stays at that level
    good = np.delete(bad, idx, axis=0)
    noise = refine.posture_uncertainty(CAM.K, CAM.mirror, CAM.rvec, CAM.tvec, good, 0.05)
    assert err[True] < 2.5 * noise.axis_std_deg, (err, noise)
    assert err[False] > 5.0 * noise.axis_std_deg, (err, noise)  # least squares is pulled


# -- correlation_factor ---------------------------------------------------------------------------
def ar1(rng, rho, n, m=1):
    """``m`` stationary AR(1) sequences of length ``n`` (unit marginal variance)."""
    x = np.empty((m, n))
    x[:, 0] = rng.standard_normal(m)
    e = rng.standard_normal((m, n)) * math.sqrt(1 - rho * rho)
    for i in range(1, n):
        x[:, i] = rho * x[:, i - 1] + e[:, i]
    return x


def test_correlation_factor_is_the_inflation_of_a_standard_deviation_by_correlation():
    # the standard deviation of the mean of N correlated residuals against sigma / sqrt(N)
    rng = np.random.default_rng(2)
    rho, n = 0.6, 400
    x = ar1(rng, rho, n, 600)
    inflation = x.mean(axis=1).std() / (1.0 / math.sqrt(n))
    factors = [refine.correlation_factor(s) for s in x[:50]]
    # both are sqrt((1 + rho) / (1 - rho)) = 2
    assert inflation == pytest.approx(2.0, rel=0.1)
    assert np.median(factors) == pytest.approx(2.0, rel=0.05)


def test_correlation_factor_of_independent_or_anticorrelated_residuals_is_one():
    rng = np.random.default_rng(3)
    assert refine.correlation_factor(rng.standard_normal(2000)) == pytest.approx(1.0, abs=0.05)
    alternating = np.tile([1.0, -1.0], 100) + 0.01 * rng.standard_normal(200)
    assert refine.correlation_factor(alternating) == 1.0  # rho clipped at 0
    # the mean is not a correlation (what is left of it is round-off, far below the floor)
    assert refine.correlation_factor(np.full(50, 0.3), 0.02) == 1.0
    assert refine.correlation_factor(np.arange(8.0)) == 1.0  # too few to say (<= 8)
    assert refine.correlation_factor([]) == 1.0


def test_correlation_factor_sums_the_correlation_over_every_lag():
    # a moving average of 25 white values: rho_k = 1 - k / 25, tau = 25; the standard deviation
    # of the mean is 5x sigma / sqrt(N), which lag 1 alone calls sqrt(1.96 / 0.04) = 7
    rng = np.random.default_rng(3)
    width, n = 25, 4000
    kernel = np.ones(width) / math.sqrt(width)
    x = np.array(
        [np.convolve(rng.standard_normal(n + width - 1), kernel, "valid") for _ in range(400)]
    )
    assert x.mean(axis=1).std() * math.sqrt(n) == pytest.approx(5.0, rel=0.1)
    assert np.median([refine.correlation_factor(s) for s in x[:50]]) == pytest.approx(5.0, rel=0.1)
    # a smooth misfit of k periods along the contour is worth about pi k points, whatever N
    for periods, points in ((6, 720), (12, 720), (6, 360), (20, 2000)):
        wave = np.sin(np.linspace(0, 2 * math.pi * periods, points, endpoint=False))
        n_eff = points / refine.correlation_factor(wave) ** 2
        assert n_eff == pytest.approx(math.pi * periods, rel=0.02)


def test_correlation_factor_counts_a_floor_as_independent_noise_and_10_points_at_least():
    # a floor of the residuals' own RMS halves every rho_k: an AR(1) sequence of rho = 0.5
    # (tau = 3) then has rho_k = 0.5^(k+1), tau = 1 + 2 * 0.5 = 2
    rng = np.random.default_rng(4)
    x = ar1(rng, 0.5, 2000, 50)
    floors = np.sqrt(np.mean((x - x.mean(axis=1, keepdims=True)) ** 2, axis=1))
    tau = [refine.correlation_factor(s) ** 2 for s in x]
    tau_floor = [refine.correlation_factor(s, f) ** 2 for s, f in zip(x, floors)]
    assert np.median(tau) == pytest.approx(3.0, rel=0.05)
    assert np.median(tau_floor) == pytest.approx(2.0, rel=0.05)
    # three periods on 360 points would be worth 3 pi < 10 points: 10 (the posture has 5)
    smooth = np.sin(np.linspace(0, 6 * math.pi, 360))
    assert refine.MIN_EFFECTIVE_POINTS == 10
    assert refine.correlation_factor(smooth) == pytest.approx(math.sqrt(360 / 10))


def test_correlation_factor_skips_non_finite_residuals():
    x = ar1(np.random.default_rng(5), 0.5, 300)[0]
    with_nan = np.concatenate([[np.nan], x, [np.inf, np.nan]])
    assert refine.correlation_factor(with_nan, 0.1) == refine.correlation_factor(x, 0.1)


# -- posture_uncertainty --------------------------------------------------------------------------
def test_stated_uncertainty_is_the_scatter_of_the_refined_posture_under_noise():
    """Monte Carlo: rim points with Gaussian noise of sigma px (independent of the estimator),
    refined from the truth, each run's uncertainty from its own residual RMS."""
    rim = CAM.rim_image_points(120)
    empirical, stated = {}, {}
    for sigma in (0.05, 0.2):
        rng = np.random.default_rng(11)
        errs, axis_std, chi2 = [], [], []
        for _ in range(60):
            noisy = rim + rng.normal(size=rim.shape) * sigma
            res = refine.refine_posture(CAM.K, CAM.mirror, CAM.rvec, CAM.tvec, noisy, robust=False)
            u = refine.posture_uncertainty(
                CAM.K, CAM.mirror, res.rvec, res.tvec, noisy, res.rim_rms
            )
            e = refine.posture_offsets(res.rvec, res.tvec, CAM.rvec, CAM.tvec)
            errs.append(e)
            axis_std.append(u.axis_std_deg)
            chi2.append(float(e @ np.linalg.solve(u.cov, e)))
        errs = np.array(errs)
        empirical[sigma] = math.degrees(math.sqrt(np.mean(errs[:, 0] ** 2 + errs[:, 1] ** 2)))
        stated[sigma] = float(np.mean(axis_std))
        assert 0.8 < empirical[sigma] / stated[sigma] < 1.25, (sigma, empirical, stated)
        assert 3.5 < np.mean(chi2) < 6.8  # chi-square with 5 degrees of freedom: mean 5
    assert stated[0.2] / stated[0.05] == pytest.approx(4.0, rel=0.05)
    assert 3.0 < empirical[0.2] / empirical[0.05] < 5.3


def test_uncertainty_is_linear_in_the_rim_sigma_above_the_floor():
    rim = CAM.rim_image_points(200)

    def unc(sigma, floor=0.02):
        return refine.posture_uncertainty(
            CAM.K, CAM.mirror, CAM.rvec, CAM.tvec, rim, sigma, floor=floor
        )

    one, three = unc(0.1), unc(0.3)
    assert three.axis_std_deg == pytest.approx(3 * one.axis_std_deg, rel=1e-9)
    assert three.origin_std == pytest.approx(3 * one.origin_std, rel=1e-9)
    np.testing.assert_allclose(three.cov, 9 * one.cov, rtol=0, atol=1e-9 * np.abs(three.cov).max())
    # exact data: the residuals' own RMS is ~0, and the floor (the edge location limit) counts
    assert unc(0.0).axis_std_deg == unc(0.02).axis_std_deg == pytest.approx(one.axis_std_deg / 5)
    assert unc(0.0, floor=0.04).axis_std_deg == pytest.approx(2 * unc(0.0).axis_std_deg)


def test_correlated_rim_residuals_widen_the_uncertainty_by_the_correlation_factor():
    dense = CAM.rim_image_points(36000)
    rim, normal = dense[::100], curve_normals(dense)[::100]
    phi = np.linspace(0, 2 * math.pi, 360, endpoint=False)
    wavy = rim + (0.05 * np.cos(7 * phi))[:, None] * normal  # a smooth misfit, not noise
    res = refine.RimTerm(CAM.K, CAM.mirror, CAM.R, CAM.tvec, wavy).residuals(CAM.R, CAM.tvec)
    f = refine.correlation_factor(res, 0.02)
    assert f > 2.0
    args = (CAM.K, CAM.mirror, CAM.rvec, CAM.tvec)
    wide = refine.posture_uncertainty(*args, wavy, 0.1)
    plain = refine.posture_uncertainty(*args, rim, 0.1)
    assert wide.axis_std_deg == pytest.approx(f * plain.axis_std_deg, rel=1e-2)


def test_a_known_z_reflection_pins_the_axis_the_rim_leaves_loose():
    rim = CAM.rim_image_points(200)
    xn = normalized(CAM, reflection.outline_pixels(CAM, R_C, Z_C, 64)[0])
    args = (CAM.K, CAM.mirror, CAM.rvec, CAM.tvec, rim, 0.05)
    alone = refine.posture_uncertainty(*args)
    joint = refine.posture_uncertainty(*args, (xn, R_C, Z_C, False, True), 0.05)
    assert joint.axis_std_deg < 0.25 * alone.axis_std_deg
    # a reflection without its sigma is not used
    assert refine.posture_uncertainty(*args, (xn, R_C, Z_C, False, True)) == alone


# -- profile_uncertainty ------------------------------------------------------------------------
#: Nearly aligned: the two physical postures of a noisy rim 2-3 deg apart, their midway posture
#: within the chi-square of the noise
NEAR = synthetic.misaligned_rig(0.3, 50.0, (0.2, -0.1, 0.0), image_size=(640, 480))


def refined_with_twin(cam, noisy):
    """The rim-only refinement of ``noisy`` from the physical Chen posture nearest the truth,
    the arguments of ``posture_uncertainty`` at it, and the other physical posture."""
    from omnicam.calibration import chen
    from omnicam.calibration.rim import fit_rim

    conic = chen.normalized_conic(fit_rim(noisy).conic, cam.K)
    own, twin = sorted(
        (c for c in chen.chen_candidates(conic, cam.mirror) if c.physical),
        key=lambda c: -float(c.axis @ cam.R[:, 2]),
    )
    res = refine.refine_posture(cam.K, cam.mirror, own.rvec, own.tvec, noisy, robust=False)
    return (cam.K, cam.mirror, res.rvec, res.tvec, noisy, res.rim_rms), (twin.rvec, twin.tvec)


def test_profile_uncertainty_is_the_first_order_one_where_the_rim_is_linear_in_the_posture():
    rim = CAM.rim_image_points(200)
    noisy = rim + np.random.default_rng(12).normal(size=rim.shape) * 0.05
    args, twin = refined_with_twin(CAM, noisy)
    first = refine.posture_uncertainty(*args)
    u = refine.profile_uncertainty(*args, twin=twin)
    assert not u.widened and u.first_order_axis_std_deg == first.axis_std_deg
    assert u.axis_std_deg == first.axis_std_deg and np.array_equal(u.cov, first.cov)
    # the aligned posture midway to the twin is far outside the region of the noise
    assert u.aligned_chi2 > 5 * refine.PROFILE_CHI2
    gap = math.degrees(np.linalg.norm(refine.posture_offsets(*args[2:4], *twin)[:2]))
    assert u.twin_deg == pytest.approx(gap) and 2.0 < gap < 3.0


def test_profile_uncertainty_widens_the_tilt_and_its_compensating_shift_near_alignment():
    rim = NEAR.rim_image_points(1200)
    for seed in range(4):
        noisy = rim + np.random.default_rng(seed).normal(size=rim.shape) * 0.3
        args, twin = refined_with_twin(NEAR, noisy)
        first = refine.posture_uncertainty(*args)
        u = refine.profile_uncertainty(*args, twin=twin)
        assert u.aligned_chi2 < refine.PROFILE_CHI2  # the postures' regions merge there
        assert u.widened and u.axis_std_deg > 1.1 * first.axis_std_deg
        # the axis block scaled, the origin's shift given the tilt as the first order has it
        scale = (u.axis_std_deg / first.axis_std_deg) ** 2
        np.testing.assert_allclose(u.cov[:2, :2], scale * first.cov[:2, :2], rtol=1e-9)

        def given_tilt(c):
            return c[2:, 2:] - c[2:, :2] @ np.linalg.solve(c[:2, :2], c[:2, 2:])

        np.testing.assert_allclose(given_tilt(u.cov), given_tilt(first.cov), atol=1e-9)
        # without the twin the region spans both postures and the midway one
        assert refine.profile_uncertainty(*args).axis_std_deg > 2 * u.axis_std_deg


# -- Uncertainty, uncertainty_from_cov, the 5 parameters ----------------------------------------
def test_uncertainty_from_a_diagonal_covariance():
    cov = np.diag([1e-6, 4e-6, 0.01, 0.04, 0.09])
    u = refine.uncertainty_from_cov(cov, CAM.tvec)
    assert u.axis_std_deg == pytest.approx(math.degrees(math.sqrt(5e-6)))
    assert u.origin_std == pytest.approx(math.sqrt(0.14))
    assert u.cov is not None and np.array_equal(u.cov, cov)


def test_uncertainty_names_the_weak_direction_of_a_tilt_with_a_compensating_shift():
    v = np.array([2e-3, 0.0, -0.5, 0.0, 0.1])  # one standard deviation along it
    cov = np.outer(v, v) + 1e-12 * np.eye(5)
    u = refine.uncertainty_from_cov(cov, CAM.tvec)
    assert u.weak_tilt_deg == pytest.approx(math.degrees(2e-3), rel=1e-4)
    assert u.weak_shift == pytest.approx(math.hypot(0.5, 0.1), rel=1e-4)
    assert u.weak_share == pytest.approx(1.0, abs=1e-4)
    text = u.describe()
    assert text.startswith(f"a tilt of {u.weak_tilt_deg:.3g} deg with a compensating shift")
    assert "100 % of the posture's variance" in text
    assert refine.Uncertainty(math.inf, math.inf).describe() == "unknown"


def test_posture_offsets_inverts_perturbed_posture():
    rng = np.random.default_rng(9)
    for cam in RANDOM_RIGS[:5]:
        for _ in range(5):
            x = rng.uniform(-1, 1, 5) * [0.1, 0.1, 3.0, 3.0, 3.0]
            R, t = refine.perturbed_posture(cam.R, cam.tvec, x)
            assert np.linalg.det(R) == pytest.approx(1.0)
            got = refine.posture_offsets(cam.rvec, cam.tvec, cv2.Rodrigues(R)[0].ravel(), t)
            np.testing.assert_allclose(got, x, atol=1e-12)
            # the axis turned by |x[:2]|
            angle = math.atan2(
                np.linalg.norm(np.cross(R[:, 2], cam.R[:, 2])), R[:, 2] @ cam.R[:, 2]
            )
            assert angle == pytest.approx(math.hypot(x[0], x[1]), rel=1e-12)


def test_a_turn_about_the_mirror_axis_is_no_offset():
    turned = cv2.Rodrigues(CAM.R @ cv2.Rodrigues(np.array([0.0, 0.0, 1.1]))[0])[0].ravel()
    np.testing.assert_allclose(
        refine.posture_offsets(CAM.rvec, CAM.tvec, turned, CAM.tvec), 0.0, atol=1e-15
    )
    R, t = refine.perturbed_posture(cv2.Rodrigues(turned)[0], CAM.tvec, np.zeros(5))
    np.testing.assert_allclose(R, CAM.R, atol=1e-15)  # back in the gauge


def test_gauge_rotation_is_the_smallest_rotation_taking_z_to_the_axis():
    rng = np.random.default_rng(10)
    for _ in range(20):
        axis = rng.normal(size=3) + [0, 0, 3.0]
        R = refine.gauge_rotation(axis)
        np.testing.assert_allclose(R[:, 2], axis / np.linalg.norm(axis), atol=1e-15)
        assert np.linalg.det(R) == pytest.approx(1.0)
        rvec = cv2.Rodrigues(R)[0].ravel()
        assert abs(rvec[2]) < 1e-15 and abs(rvec @ axis) < 1e-12  # about e_z x axis
        angle = math.acos(axis[2] / np.linalg.norm(axis))
        assert np.linalg.norm(rvec) == pytest.approx(angle, rel=1e-12)
