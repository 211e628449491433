"""Scaramuzza's central model (chessboard.taylor) on renders of known central cameras."""

import cv2
import numpy as np
import pytest

from omnicam.chessboard.board_pose import object_points
from omnicam.chessboard.heldout import fold_of, heldout_rms, unified_predictor
from omnicam.chessboard.taylor import fit_taylor

SIZE = (800, 600)


def render_mei(xi, gamma=300.0, n_views=10, noise=0.0, seed=0):
    """Corners of a 7x11 board in ``n_views`` poses around Mei's model ``(K, xi)``
    (``cv2.omnidir.projectPoints``), all inside the image; returns ``(views, obj, K)``."""
    rng = np.random.default_rng(seed)
    obj = object_points((7, 11), 30.0)
    K = np.array([[gamma, 0, SIZE[0] / 2 - 3.5], [0, gamma, SIZE[1] / 2 + 2.5], [0, 0, 1]])
    views = []
    while len(views) < n_views:
        az, polar = rng.uniform(0, 2 * np.pi), np.radians(rng.uniform(45, 105))
        d = np.array([np.sin(polar) * np.cos(az), np.sin(polar) * np.sin(az), np.cos(polar)])
        x = np.cross([0.3, 0.7, 0.2], -d)
        x /= np.linalg.norm(x)
        R = np.c_[x, np.cross(-d, x), -d] @ cv2.Rodrigues(rng.uniform(-0.4, 0.4, 3))[0]
        t = d * rng.uniform(400, 700) - R @ obj.mean(0)
        q, _ = cv2.omnidir.projectPoints(
            obj.reshape(-1, 1, 3), cv2.Rodrigues(R)[0], t.reshape(3, 1), K, xi, np.zeros((1, 4))
        )
        q = q.reshape(-1, 2)
        if np.isfinite(q).all() and (q > 5).all() and (q < np.array(SIZE) - 5).all():
            views.append(q + rng.normal(0, noise, q.shape))
    return views, obj, K


def _ray_errors_deg(fit, K, xi, pixels):
    """Angles between the fit's rays and Mei's, whose z axis is the fit's reversed (Mei's
    principal point sees +z, OCamCalib's gauge a0 < 0 puts it on -z)."""
    truth = unified_predictor(K, xi, np.zeros(4))[1](pixels)[1] * [1, 1, -1]
    c = np.clip(np.sum(fit.directions(pixels) * truth, axis=1), -1, 1)
    return np.degrees(np.arccos(c))


def test_taylor_recovers_a_parabolic_cameras_rays():
    # xi = 1 (a paraboloid seen orthographically) is f(rho) = a0 + a2 rho^2 exactly
    views, obj, K = render_mei(1.0, gamma=150.0)
    fit = fit_taylor(views, obj, SIZE, degrees=(2, 4))
    pixels = np.vstack(views)
    assert fit.rms < 1e-3
    assert _ray_errors_deg(fit, K, 1.0, pixels).max() < 1e-3
    np.testing.assert_allclose(fit.centre, K[:2, 2], atol=1e-2)
    assert fit.coefficients[0] < 0 and fit.coefficients[1] == 0


def test_taylor_approximates_mei_xi_1_4_rays_within_a_fraction_of_a_degree():
    # beyond a paraboloid Mei's elevation is not a polynomial in rho: on these boards degree 5
    # comes within 0.13 deg (0.04 px RMS); boards nearer the horizon need more (next test)
    views, obj, K = render_mei(1.4, seed=1)
    fit = fit_taylor(views, obj, SIZE)
    assert fit.degree == 5 and fit.rms < 0.1
    assert _ray_errors_deg(fit, K, 1.4, np.vstack(views)).max() < 0.3


def test_taylor_higher_degree_never_fits_worse_than_the_lower():
    # seed 0: degree 5 from the linear start falls into a valley (RMS 96 px); the lower
    # degree's fit extended by a zero coefficient is the second start that avoids it
    views, obj, _ = render_mei(1.4, seed=0)
    low = fit_taylor(views, obj, SIZE, degrees=(4,))
    both = fit_taylor(views, obj, SIZE, degrees=(4, 5))
    assert both.degree == 5 and both.rms <= low.rms


def test_taylor_project_inverts_directions():
    views, obj, _ = render_mei(1.4, noise=0.1, n_views=6)
    fit = fit_taylor(views, obj, SIZE, degrees=(4,))
    pixels = np.vstack(views)
    back = fit.project(fit.directions(pixels) * 500.0)
    np.testing.assert_allclose(back, pixels, atol=1e-6)
    rvec, tvec = fit.poses[0]
    assert np.sqrt(np.mean(np.sum((fit.project_board(obj, rvec, tvec) - views[0]) ** 2, 1))) < 0.5


def _rays_of(fit):
    return lambda px: (np.zeros((len(px), 3)), fit.directions(px))


def test_taylor_predicts_held_out_views_of_a_central_camera():
    # 5-fold, each held-out view's pose alone fitted (the shared held-out protocol)
    views, obj, _ = render_mei(1.0, gamma=150.0, noise=0.1)
    rms = []
    for fold in fold_of(len(views), 5):
        fit = fit_taylor([v for i, v in enumerate(views) if i not in fold], obj, SIZE, degrees=(4,))
        rms += [heldout_rms(fit.project_board, _rays_of(fit), views[i], obj) for i in fold]
    assert np.median(rms) < 0.2 and max(rms) < 0.3


def test_taylor_needs_three_views():
    views, obj, _ = render_mei(1.0, n_views=3)
    with pytest.raises(ValueError, match="3 views"):
        fit_taylor(views[:2], obj, SIZE)
