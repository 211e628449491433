"""The held-out check's folds check the rays' stated uncertainty (omnicam.chessboard.fold_rays):
a delete-d jackknife of the folds' calibrations, which rejects a linearised uncertainty the
folds' spread does not allow."""

import dataclasses
import math

import numpy as np
import pytest

from omnicam.chessboard.fold_rays import fold_check, jackknife_ray_std, rejection_ratio
from omnicam.chessboard.report import FOLDS_STATED

SIZE = (320, 240)


class _Pinhole:
    """A camera whose rays are a pinhole's, each turned by ``deg`` towards ``side`` (all a fold
    check looks at), and which sees nothing right of ``blind_u``."""

    def __init__(self, deg=0.0, side=(1.0, 0.0, 0.0), blind_u=math.inf):
        self.a, self.side, self.blind_u = math.radians(deg), np.asarray(side, np.float64), blind_u

    def unproject(self, px):
        d = np.column_stack([px[:, 0] - 160.0, px[:, 1] - 120.0, np.full(len(px), 200.0)])
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        e = self.side - (d @ self.side)[:, None] * d  # the side, square to each ray
        e /= np.linalg.norm(e, axis=1, keepdims=True)
        d = math.cos(self.a) * d + math.sin(self.a) * e
        d[px[:, 0] > self.blind_u] = np.nan
        return np.zeros_like(d), d


@dataclasses.dataclass(frozen=True)
class _Report:
    ray_std_deg: tuple
    warnings: tuple = ()


def _turned(deg, side):
    return _Pinhole(deg, side)


def test_jackknife_of_folds_turned_by_one_angle_is_sqrt_k_minus_1_times_it():
    """Every fold's rays 1 deg from the full fit's: (k - 1) / k * k * 1^2 = k - 1 deg^2."""
    folds = [_turned(1.0, a) for a in ([1, 0, 0], [0, 1, 0], [1, 1, 0])]
    med, worst = jackknife_ray_std(_Pinhole(), folds, SIZE)
    assert med == pytest.approx(math.sqrt(2.0), rel=1e-6)
    assert worst == pytest.approx(math.sqrt(2.0), rel=1e-6)


def test_a_pixel_a_fold_does_not_see_is_judged_by_the_folds_that_do():
    folds = [_turned(1.0, [1, 0, 0]), _Pinhole(blind_u=200.0), _turned(1.0, [0, 1, 0])]
    full = jackknife_ray_std(_Pinhole(), folds, SIZE)
    # where all three see: (2 / 3) * 2 deg^2; where one is blind: (2 / 3) * 2 * 3 / 2
    assert full[0] == pytest.approx(math.sqrt(4.0 / 3.0), rel=1e-6)
    assert full[1] == pytest.approx(math.sqrt(2.0), rel=1e-6)


def test_rejection_ratio_is_chi_square_at_p_0_001():
    assert rejection_ratio(3) == pytest.approx(math.sqrt(13.8155 / 2), rel=1e-4)
    assert rejection_ratio(5) < rejection_ratio(3)  # more folds, a tighter test


def test_folds_far_beyond_the_stated_uncertainty_replace_it_with_a_note():
    folds = [_turned(2.0, a) for a in ([1, 0, 0], [0, 1, 0], [1, 1, 0])]
    report, found = fold_check(_Report((0.3, 0.5)), _Pinhole(), folds, SIZE)
    assert found.rejected
    assert report.ray_std_deg == pytest.approx((2 * math.sqrt(2.0), 2 * math.sqrt(2.0)))
    (w,) = report.warnings
    assert w.startswith(FOLDS_STATED)
    assert "3 folds' (a delete-d jackknife of their calibrations: 2.828 deg" in w
    assert "linearised 0.300 deg" in w


def test_folds_within_chance_of_the_stated_uncertainty_leave_the_report_as_it_is():
    """2 deg of jackknife against 1 deg stated: below the 2.63 times chance allows (k = 3)."""
    folds = [_turned(math.sqrt(2.0), a) for a in ([1, 0, 0], [0, 1, 0], [1, 1, 0])]
    given = _Report((1.0, 1.5))
    report, found = fold_check(given, _Pinhole(), folds, SIZE)
    assert not found.rejected
    assert found.ray_std_deg[0] == pytest.approx(2.0, rel=1e-6)
    assert report is given


def test_fewer_than_two_folds_check_nothing():
    given = _Report((0.1, 0.2))
    assert fold_check(given, _Pinhole(), [_turned(5.0, [1, 0, 0])], SIZE) == (given, None)


def test_the_folds_note_is_a_note_not_an_alarm():
    """The stated uncertainty is then the data's own figure: stated, not doubted."""
    from omnicam.chessboard.report import PatternReport

    folds = [_turned(2.0, a) for a in ([1, 0, 0], [0, 1, 0], [1, 1, 0])]
    fields = dict.fromkeys(
        ("rms", "view_rms", "corners_used", "board_poses", "image_points", "reprojected"), None
    )
    fields.update(rim_points=None, rim_rms=0.1, std={}, dropped={}, nfev=1, camera=None)
    given = PatternReport(
        **fields, warnings=("something else",), start=None, ray_std_deg=(0.3, 0.5)
    )
    report, _ = fold_check(given, _Pinhole(), folds, SIZE)
    (note,) = report.notes
    assert note.startswith(FOLDS_STATED)
    assert report.alarms == ("something else",)
