"""The rim ellipse Q_I (eqs. 20-22): fit to given points, and detection in images."""
import numpy as np
import pytest

from omnicam import synthetic
from omnicam.calibration.rim import RimFit, conic_from_ellipse, ellipse_from_conic, fit_rim


def _conic_residual(Q, pts):
    ph = np.c_[pts, np.ones(len(pts))]
    return np.einsum("ni,ij,nj->n", ph, Q, ph)


# -- fit_rim on given points ---------------------------------------------------------------------
@pytest.mark.parametrize("robust", [True, False])
def test_fit_rim_exact_points_recovers_conic(robust):
    cam = synthetic.misaligned_rig()
    truth = cam.rim_image_points(360)
    fit = fit_rim(truth, robust=robust)
    assert isinstance(fit, RimFit)
    assert fit.rms < 1e-9
    assert np.abs(fit.distance(cam.rim_image_points(1000))).max() < 1e-9
    Q = fit.conic
    assert Q.shape == (3, 3) and Q.dtype == np.float64
    np.testing.assert_allclose(Q, Q.T, atol=0)
    assert np.linalg.norm(Q) == pytest.approx(1.0)
    # interior negative (eq. 21 sign convention): exactly one negative eigenvalue
    assert _conic_residual(Q, fit.center[None])[0] < 0
    assert np.sum(np.linalg.eigvalsh(Q) < 0) == 1
    assert fit.points.shape == (360, 2) and fit.inliers.all()


def test_fit_rim_accepts_opencv_shape_and_float32():
    truth = synthetic.aligned_rig().rim_image_points(100)
    fit = fit_rim(truth[:, None, :].astype(np.float32))
    assert fit.points.shape == (100, 2) and fit.points.dtype == np.float64
    assert fit.rms < 1e-3  # float32 rounding of ~250 px coordinates


def test_fit_rim_conic_matches_geometry():
    center, S = np.array([250.3, 240.7]), np.array([[200.0, 7.0], [7.0, 180.0]])
    Q = conic_from_ellipse(center, S)
    c2, S2 = ellipse_from_conic(-3.0 * Q)  # scale and sign do not matter
    np.testing.assert_allclose(c2, center, atol=1e-9)
    np.testing.assert_allclose(S2, S, atol=1e-9)
    t = np.linspace(0, 2 * np.pi, 50)
    pts = center + np.c_[np.cos(t), np.sin(t)] @ S.T
    fit = fit_rim(pts)
    np.testing.assert_allclose(fit.conic, Q, atol=1e-12)
    np.testing.assert_allclose(fit.axes[0] * fit.axes[1], np.linalg.det(S), rtol=1e-9)


def test_fit_rim_partial_arc():
    """A rim clipped by the image border leaves an arc; the fit still recovers the ellipse."""
    cam = synthetic.misaligned_rig()
    arc = cam.rim_image_points(360)[30:150]
    fit = fit_rim(arc)
    assert np.abs(fit.distance(cam.rim_image_points(720))).max() < 1e-8


def test_fit_rim_rejects_outliers_and_is_geometric_under_noise():
    cam = synthetic.misaligned_rig()
    rng = np.random.default_rng(5)
    truth = cam.rim_image_points(400)
    noisy = truth + rng.normal(0.0, 0.3, truth.shape)
    outliers = rng.uniform(0, 500, (200, 2))  # a third of the points
    fit = fit_rim(np.r_[noisy, outliers])
    assert fit.inliers[:400].all()
    far = np.abs(fit.distance(outliers)) > 3.0
    assert not (fit.inliers[400:] & far).any()
    assert fit.rms == pytest.approx(0.3, rel=0.15)
    # the true rim lies within a small fraction of the noise of the fitted one
    assert np.sqrt(np.mean(fit.distance(cam.rim_image_points(720)) ** 2)) < 0.05


def test_fit_rim_without_robust_uses_every_point():
    cam = synthetic.aligned_rig()
    pts = np.r_[cam.rim_image_points(50), [[10.0, 10.0]]]
    fit = fit_rim(pts, robust=False)
    assert fit.inliers.all() and len(fit.points) == 51 and fit.rms > 0.1


@pytest.mark.parametrize("points, match", [
    (np.zeros((4, 2)), "at least 6"),
    (np.zeros((10, 3)), "shape"),
    (np.full((10, 2), np.nan), "finite"),
    (np.c_[np.arange(10.0), 2 * np.arange(10.0)], "ellipse"),
    (np.c_[np.arange(10.0), np.arange(10.0) ** 2], "ellipse"),
    (np.zeros((10, 2)), "ellipse"),
    ("rim", "array"),
])
def test_fit_rim_bad_input_raises_value_error(points, match):
    with pytest.raises(ValueError, match=match):
        fit_rim(points)


def test_fit_rim_too_few_points_non_robust():
    pts = synthetic.aligned_rig().rim_image_points(5)
    assert fit_rim(pts, robust=False).rms < 1e-9
    with pytest.raises(ValueError, match="at least 5"):
        fit_rim(pts[:4], robust=False)
