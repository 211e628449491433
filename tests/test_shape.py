"""What one image tells of the mirror's shape: far lines a wrong mirror cannot make straight.

The rigs come from tests/quadric_rig.py, an independent tracer of mirrors of revolution (a
hyperboloid, a paraboloid, a sphere), which shares nothing with omnicam's ray tracer.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import quadric_rig as q

import omnicam
from omnicam.calibration.shape import BOWED_FACTOR, far_line_scatter
from omnicam.mirror import HyperbolicMirror

A, B, RIM = 28.095, 23.4125, 30.0
C = math.hypot(A, B)
MIRRORS = {
    "hyperboloid": q.hyperboloid(A, B, RIM),
    "paraboloid": q.paraboloid(20.0, 8.0, RIM),
}


def _calibrate(shape, click_px, seed=0):
    rng = np.random.default_rng(seed)
    R, t = q.posture(1.0, 30.0, [0.5, -0.3, 0.0], C)
    rig = q.rig_filling(MIRRORS[shape], (640, 480), -C, R=R, t=t)
    rim = rig.rim_pixels(360) + rng.normal(0.0, 0.1, (360, 2))
    lines = [x + rng.normal(0.0, click_px, x.shape) for x in q.far_line_pixels(rig)]
    _, report = omnicam.MisalignedHyperbolicCamera.calibrate(
        boundary_points=rim,
        K=rig.K,
        mirror=HyperbolicMirror(A, B, RIM),
        far_lines=lines,
        image_size=(640, 480),
    )
    return report, lines


def _bowed(report):
    return [w for w in report.warnings if "do not come out straight" in w]


@pytest.mark.parametrize("click_px", [0.0, 0.3])
def test_far_lines_under_the_right_hyperboloid_are_not_called_bowed(click_px):
    report, lines = _calibrate("hyperboloid", click_px)
    assert not _bowed(report)
    if click_px:
        assert report.refinement.line_rms < BOWED_FACTOR * far_line_scatter(lines)


@pytest.mark.parametrize("click_px", [0.0, 0.3])
def test_a_paraboloid_calibrated_as_a_hyperboloid_is_said_to_bow_its_far_lines(click_px):
    report, _ = _calibrate("paraboloid", click_px)
    (warning,) = _bowed(report)
    assert "may not be the hyperboloid a 28.095, b 23.4125" in warning


def test_the_scatter_of_noisy_pixels_about_a_smooth_curve_is_their_noise():
    rng = np.random.default_rng(3)
    t = np.linspace(0.2, 2.2, 60)
    arcs = [np.c_[300 + 180 * np.cos(t + k), 240 + 150 * np.sin(t + k)] for k in range(3)]
    noisy = [a + rng.normal(0.0, 0.5, a.shape) for a in arcs]
    assert far_line_scatter(arcs) < 0.05  # the curve, not the method, leaves nothing
    assert far_line_scatter(noisy) == pytest.approx(0.5, rel=0.15)
    assert math.isnan(far_line_scatter([arcs[0][:3]]))  # too few pixels to tell
