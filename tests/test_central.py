"""The central start (chessboard.central): cv2.omnidir's unified model and its hyperbolic rig."""

import math
import warnings

import numpy as np
import pytest
import test_pattern as tp

import omnicam
from omnicam import HyperbolicMirror, synthetic
from omnicam.chessboard import central
from omnicam.chessboard.board_pose import object_points
from omnicam.synthetic import boards

MIRRORS = [
    HyperbolicMirror(23.4, 28.1, 30.0),
    HyperbolicMirror(28.1, 23.4, 30.0),
    HyperbolicMirror(10, 30, 22),
]


def _unified(rig):
    """The unified model of an aligned rig by the closed form (Mei and Rives, table 1)."""
    a, b, c = rig.mirror.a, rig.mirror.b, rig.mirror.c
    xi = 2 * c / math.sqrt(4 * c * c + a**4 / b**2)
    K = rig.K.copy()
    K[0, 0] *= math.sqrt(1 - xi * xi)
    K[1, 1] *= math.sqrt(1 - xi * xi)
    return K, xi


@pytest.mark.parametrize("mirror", MIRRORS, ids=["vmr", "swapped", "narrow"])
def test_the_aligned_rig_is_recovered_from_its_unified_model_and_rim(mirror):
    rig = synthetic.aligned_rig((500, 500), mirror=mirror)
    K_u, xi = _unified(rig)
    r_px = float(np.linalg.norm(rig.rim_image_points(360) - rig.K[:2, 2], axis=1).mean())
    K, m = central.hyperbolic_start(K_u, xi, r_px, mirror.rim_radius)
    assert np.allclose(K, rig.K, atol=1e-9 * rig.K[0, 0])
    assert m.a == pytest.approx(mirror.a, rel=1e-9) and m.b == pytest.approx(mirror.b, rel=1e-9)


def test_closed_form_agrees_with_the_unified_model_fitted_to_the_exact_rig():
    from omnicam.formats.central_fit import fit_omnidir

    rig = synthetic.aligned_rig((500, 500))
    fit = fit_omnidir(rig, skew=False, distortion=False)
    K_u, xi = _unified(rig)
    assert fit.xi == pytest.approx(xi, abs=1e-9)
    assert fit.K[0, 0] == pytest.approx(K_u[0, 0], rel=1e-9)


def test_cv2_omnidir_on_an_aligned_rigs_corners_gives_its_xi_and_focal_length():
    rig = synthetic.aligned_rig((800, 800))
    poses = boards.random_board_poses(
        rig, 8, tp.PATTERN, tp.SQUARE, distance=(300.0, 900.0), max_tilt_deg=40.0, rng=5
    )
    pts = [boards.board_corners(rig, tp.PATTERN, tp.SQUARE, *p) for p in poses]
    fit = central.fit_central(pts, object_points(tp.PATTERN, tp.SQUARE), rig.image_size)
    K_u, xi = _unified(rig)
    assert fit.rms < 0.01 and len(fit.views) == 8
    assert fit.xi == pytest.approx(xi, abs=2e-3)
    assert fit.K[0, 0] == pytest.approx(K_u[0, 0], rel=2e-3)


def test_xi_outside_the_hyperbolic_range_is_refused():
    for xi in (0.0, 1.0, 1.08, -0.2):
        with pytest.raises(ValueError, match="xi"):
            central.mirror_shape_from_xi(xi)
    with pytest.raises(ValueError, match="3 views"):
        central.fit_central([np.zeros((35, 2))] * 2, np.zeros((35, 3)), (800, 800))


def _fit(mirror, **kw):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cam, report = omnicam.calibrate_pattern(
            None,
            tp.PATTERN,
            tp.SQUARE,
            mirror,
            image_points=tp._corners(noise=0.2, seed=1),
            boundary_points=tp._rim(0.1),
            image_size=tp.RIG.image_size,
            lens=None,
            **kw,
        )
    return cam, report, [str(w.message) for w in caught]


def _ray_error_deg(cam):
    rig = tp.RIG
    rim = rig.rim_image_points(360)
    c = rim.mean(axis=0)
    r = np.linalg.norm(rim - c, axis=1).min()
    g = np.stack(np.meshgrid(np.linspace(-1, 1, 30), np.linspace(-1, 1, 30)), -1).reshape(-1, 2)
    px = g[np.linalg.norm(g, axis=1) < 0.95] * r + c
    d1, d2 = rig.unproject(px)[1], cam.unproject(px)[1]
    ok = np.isfinite(d1).all(axis=1) & np.isfinite(d2).all(axis=1)
    return np.degrees(np.arccos(np.clip(np.sum(d1[ok] * d2[ok], axis=1), -1, 1)))


def test_no_mirror_calibrates_from_the_boards_alone_and_says_the_scale_is_assumed():
    _, given, _ = _fit(tp.RIG.mirror)
    cam, report, caught = _fit(None)
    assert report.central is not None and 0 < report.central.xi < 1
    # a hyperbolic rig's family is the hyperboloid's (the generic start is not run)
    assert isinstance(cam.mirror, HyperbolicMirror)
    assert not any("even asphere" in w for w in report.warnings)
    assert report.rms < 1.05 * given.rms  # the corners fit as with the data sheet's mirror
    assert np.median(_ray_error_deg(cam)) < 0.5  # 0.2 px noise, 10 views
    scale = [w for w in report.warnings if "scale is assumed" in w]
    assert len(scale) == 1 and scale[0] in caught
    _, report_r, _ = _fit(None, rim_radius=30.0)
    assert not any("scale is assumed" in w for w in report_r.warnings)
    assert report_r.camera.mirror.rim_radius == 30.0
