"""The rig start any mirror's calibration begins from (chessboard.central_start)."""

import math

import numpy as np
import pytest
import test_pattern as tp

from omnicam import HyperbolicMirror, synthetic
from omnicam.chessboard.board_pose import object_points
from omnicam.chessboard.central_start import (
    RIM_HALF_ANGLE_DEG,
    central_start,
    elevations_along_radii,
    unified_directions,
)
from omnicam.chessboard.taylor import fit_taylor
from omnicam.synthetic import boards


def _rim_px(rig, centre):
    rim = rig.rim_image_points(360)
    return float(np.exp(np.mean(np.log(np.linalg.norm(rim - centre, axis=1)))))


def test_mei_model_of_a_hyperbolic_rig_gives_its_mirror_focal_length_and_posture():
    mirror = HyperbolicMirror(23.4, 28.1, 30.0)
    rig = synthetic.aligned_rig((800, 800), mirror=mirror)
    a, b, c = mirror.a, mirror.b, mirror.c
    xi = 2 * c / math.sqrt(4 * c * c + (a * a / b) ** 2)
    f = rig.K[0, 0]
    K_u = rig.K.copy()
    K_u[:2, :2] *= math.sqrt(1 - xi * xi)
    start = central_start(
        unified_directions(K_u, xi),
        rig.K[:2, 2],
        _rim_px(rig, rig.K[:2, 2]),
        30.0,
        f=f,
        max_terms=0,
    )
    assert start.f_given and np.allclose(start.K, rig.K)
    assert start.mirror.R == pytest.approx(a * a / b, rel=1e-6)
    assert start.mirror.k == pytest.approx(-1 - a * a / (b * b), rel=1e-6)
    assert start.mirror.vertex_z == 0.0 and np.allclose(start.rvec, 0)
    np.testing.assert_allclose(start.tvec, [0, 0, b + c], rtol=1e-8)  # the vertex, b + c above
    assert start.mirror_kwargs()["alpha"] == () and np.max(start.alpha_spread) < 1e-9
    assert start.direction_error_deg < 1e-6
    shifted = central_start(
        unified_directions(K_u, xi), rig.K[:2, 2], 340.0, 30.0, f=f, max_terms=0, vertex_z=b
    )
    np.testing.assert_allclose(shifted.tvec, [0, 0, c], rtol=1e-8)  # eq. 1's frame: camera at -c


def test_taylor_fit_of_an_aligned_rigs_boards_gives_the_hyperboloid():
    rig = synthetic.aligned_rig((800, 800))
    m = rig.mirror
    poses = boards.random_board_poses(
        rig, 10, tp.PATTERN, tp.SQUARE, distance=(300.0, 900.0), max_tilt_deg=40.0, rng=5
    )
    pts = [boards.board_corners(rig, tp.PATTERN, tp.SQUARE, *p) for p in poses]
    fit = fit_taylor(pts, object_points(tp.PATTERN, tp.SQUARE), rig.image_size)
    start = central_start(fit.directions, fit.centre, _rim_px(rig, fit.centre), 30.0, f=rig.K[0, 0])
    z_true = m.b * np.sqrt(1 + start.profile.r**2 / m.a**2) + m.c
    # the rim (340 px) lies beyond the corners (255 px): the polynomial is extrapolated there
    assert np.max(np.abs(start.profile.z - z_true)) < 1e-3
    assert start.tvec[2] == pytest.approx(m.b + m.c, rel=1e-5)
    assert start.mirror.max_error < 1e-4 and start.direction_error_deg < 1e-3
    exact = central_start(fit.directions, fit.centre, 340.0, 30.0, f=rig.K[0, 0], max_terms=0)
    assert exact.mirror.R == pytest.approx(m.a**2 / m.b, rel=1e-4)
    assert exact.mirror.k == pytest.approx(-1 - m.a**2 / m.b**2, rel=1e-4)


def test_without_f_the_rim_subtends_the_default_angle():
    directions = unified_directions(np.diag([300.0, 300.0, 1.0]), 0.9)
    start = central_start(directions, (0.0, 0.0), 250.0, 20.0)
    assert not start.f_given
    assert math.degrees(math.atan(250.0 / start.f)) == pytest.approx(RIM_HALF_ANGLE_DEG)
    assert start.profile.r[-1] == 20.0 and np.all(np.diff(start.profile.slope_angles) > 0)


def test_a_model_that_sees_nothing_inside_the_rim_is_refused():
    # Mei with xi = 1.4: nothing past its horizon r^2 = 1 / (xi^2 - 1), 1.02 gamma
    directions = unified_directions(np.diag([100.0, 100.0, 1.0]), 1.4)
    with pytest.raises(ValueError, match="sees nothing"):
        elevations_along_radii(directions, (0.0, 0.0), 150.0)
