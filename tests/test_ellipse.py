"""Ellipse fitting pieces under the rim (eqs. 20-22): scikit-image's direct fit and the RANSAC."""

import math

import numpy as np
import pytest

from omnicam.calibration.ellipse import (
    conic_distance,
    conic_from_ellipse,
    direct_ellipse,
    ellipse_from_conic,
    hartley_normalization,
    orthogonal_residuals,
    ransac_conic,
)


def ellipse_points(center, axes, theta, t):
    c, s = math.cos(theta), math.sin(theta)
    R = np.array([[c, -s], [s, c]])
    return center + (np.c_[axes[0] * np.cos(t), axes[1] * np.sin(t)]) @ R.T, R


def test_direct_ellipse_exact_points_give_the_conic_with_eq22_sign():
    center, axes, theta = np.array([3.0, -1.5]), (2.5, 1.2), 0.7
    pts, R = ellipse_points(center, axes, theta, np.linspace(0.3, 5.0, 9))
    Q = direct_ellipse(pts)
    truth = conic_from_ellipse(center, R @ np.diag(axes) @ R.T)
    np.testing.assert_allclose(Q, truth, atol=1e-10)
    assert np.linalg.norm(Q) == pytest.approx(1.0)
    ph = np.r_[center, 1.0]
    assert ph @ Q @ ph < 0  # interior negative
    assert np.sum(np.linalg.eigvalsh(Q) < 0) == 1


def test_direct_ellipse_of_a_circle_has_no_preferred_axis():
    # a == c in the conic: the axis angle of scikit-image's conversion is 0 / 0 there
    t = np.linspace(0.0, 2.0 * np.pi, 12, endpoint=False)
    Q = direct_ellipse(np.c_[np.cos(t), np.sin(t)])
    center, S = ellipse_from_conic(Q)
    np.testing.assert_allclose(center, 0.0, atol=1e-12)
    np.testing.assert_allclose(S, np.eye(2), atol=1e-12)


@pytest.mark.parametrize(
    "pts",
    [
        np.ones((6, 2)),  # one point six times
        np.c_[np.arange(7.0), 2.0 * np.arange(7.0) + 1.0],  # collinear
        np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]),  # four points
        np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [np.nan, 0.5]]),
    ],
)
def test_direct_ellipse_returns_none_without_an_ellipse(pts):
    assert direct_ellipse(pts) is None  # and no warning (pytest turns warnings into errors)


def test_direct_ellipse_is_unbiased_enough_on_a_noisy_clipped_rim():
    rng = np.random.default_rng(4)
    center, axes, theta = np.array([960.0, 540.0]), (470.0, 455.0), 0.3
    true, _ = ellipse_points(center, axes, theta, np.linspace(0, 2 * np.pi, 2000))
    pts = true[(true[:, 1] > 100) & (true[:, 1] < 980)][::4]
    pts = pts + rng.normal(0.0, 0.3, pts.shape)
    N = hartley_normalization(pts)
    Q = N.T @ direct_ellipse(pts * N[0, 0] + N[:2, 2]) @ N
    d = conic_distance(Q, true)
    assert np.sqrt(np.mean(d**2)) < 0.1  # px; 0.3 px noise on ~430 points


def test_ransac_conic_separates_a_rim_from_holder_arms_and_clutter():
    rng = np.random.default_rng(5)
    center, axes, theta = np.array([960.0, 540.0]), (470.0, 455.0), 0.3
    rim, _ = ellipse_points(center, axes, theta, rng.uniform(0, 2 * np.pi, 1500))
    rim = rim + rng.normal(0.0, 0.3, rim.shape)
    a = rng.uniform(0, 2 * np.pi, 700)
    clutter = center + 470.0 * rng.uniform(0.7, 1.3, (700, 1)) * np.c_[np.cos(a), np.sin(a)]
    arm = center + np.outer(rng.uniform(330.0, 610.0, 800), [math.cos(1.0), math.sin(1.0)])
    pts = np.concatenate([rim, clutter, arm])
    N = hartley_normalization(pts)
    mask = ransac_conic(pts * N[0, 0] + N[:2, 2], 2.0 * N[0, 0], np.random.default_rng(0), 2000)
    assert mask[:1500].mean() > 0.99
    # about 1.5 % of the clutter and arm points lie within 2 px of the rim by chance
    assert mask[1500:].mean() < 0.03


@pytest.mark.parametrize("axes", [(240.0, 180.0), (150.0, 149.0), (300.0, 40.0)])
def test_orthogonal_residuals_are_the_nearest_points_of_the_ellipse_with_outer_normals(axes):
    """Against a dense sampling of the ellipse (no Newton): the distance to the nearest point,
    positive outside; the foot on the ellipse; the normal along the point's offset from it."""
    centre, theta = np.array([512.0, 384.0]), 0.4
    _, R = ellipse_points(centre, axes, theta, np.zeros(1))
    S = R @ np.diag(axes) @ R.T  # the symmetric S of centre + S (cos t, sin t)
    rng = np.random.default_rng(7)
    t = rng.uniform(0.0, 2 * np.pi, 400)
    pts = ellipse_points(centre, axes, theta, t)[0] + rng.normal(0.0, 8.0, (400, 2))
    d, u, n = orthogonal_residuals(pts, centre, S)
    dense = ellipse_points(centre, axes, theta, np.linspace(0, 2 * np.pi, 200001))[0]
    nearest = np.array([np.min(np.hypot(*(dense - p).T)) for p in pts])
    q = (pts - centre) @ R  # in the axes' frame: outside where (x / a)^2 + (y / b)^2 > 1
    outside = (q[:, 0] / axes[0]) ** 2 + (q[:, 1] / axes[1]) ** 2 > 1
    assert np.abs(np.abs(d) - nearest).max() < 1e-3 * max(axes) / 200
    assert np.array_equal(d > 0, outside)
    foot = centre + u @ S.T
    assert np.abs(np.hypot(*u.T) - 1).max() < 1e-12
    assert np.abs(pts - foot - d[:, None] * n).max() < 1e-9
    assert np.abs(np.hypot(*n.T) - 1).max() < 1e-12
