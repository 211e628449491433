"""Other starts (omnicam.chessboard.other_starts): where the views determine the rays weakly,
the rig is fitted from other starts (along the focal length, the mirror turned), the fit of the
lowest cost taken, and the rays' stated uncertainty is at least the spread of the fits as good."""

import dataclasses
import math
import types

import cv2
import numpy as np
import pytest
from asphere_rigs import rig

import omnicam.chessboard.other_starts as starts
from omnicam.chessboard.report import STARTS_STATED

SIZE = (320, 240)
N_RESIDUALS = 1000
GLOBALS = ("fx", "fy", "cx", "cy", "k1", "k2", "R", "k")


class _Pinhole:
    """A camera whose rays are a pinhole's, each turned by ``deg`` towards the x axis."""

    def __init__(self, deg=0.0):
        self.a = math.radians(deg)

    def unproject(self, px):
        d = np.column_stack([px[:, 0] - 160.0, px[:, 1] - 120.0, np.full(len(px), 200.0)])
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        e = np.array([1.0, 0.0, 0.0]) - d[:, :1] * d  # the x axis, square to each ray
        e /= np.linalg.norm(e, axis=1, keepdims=True)
        return np.zeros_like(d), math.cos(self.a) * d + math.sin(self.a) * e


@dataclasses.dataclass(frozen=True)
class _Report:
    ray_std_deg: tuple
    warnings: tuple = ()


def _fitted(chi2=0.0, deg=0.0, ray=(1.0, 2.0), used=(0, 1, 2)):
    """A fit whose robust cost is ``chi2`` residual variances (of a fit of cost 1000 over
    1000 residuals) above that fit's, its rays turned by ``deg``."""
    sol = types.SimpleNamespace(
        cost=N_RESIDUALS / 2.0 * (1.0 + chi2 / N_RESIDUALS),
        fun=np.zeros(N_RESIDUALS),
        x=np.zeros(len(GLOBALS)),
    )
    adj = types.SimpleNamespace(names=GLOBALS, fixed=set())
    fit = types.SimpleNamespace(sol=sol, adj=adj, used=list(used))
    rounds = types.SimpleNamespace(fit=fit, boards=None)
    return starts.Fitted(rounds, "", None, _Pinhole(deg), _Report(ray))


def _options():
    return types.SimpleNamespace(image_size=SIZE)


#: The starts asked for, in order: the rim's angles, then the turns (deg, side).
STARTS = [*starts.RIM_ANGLES_DEG, *((d, s) for d in starts.TURN_DEG for s in starts._SIDES)]


def _run(first, others, monkeypatch, turned_from=None):
    """``other_starts_step`` with the other starts' fits ``others`` (an exception: that start
    fails; the rest fail too), and the starts it asked for; the fits the turns start from are
    appended to ``turned_from``."""
    asked = []
    monkeypatch.setattr(starts, "_start_at", lambda first, rim, options, angle: angle)

    def turned(fit, deg, side):
        if turned_from is not None:
            turned_from.append(fit)
        return deg, side

    monkeypatch.setattr(starts, "_turned_start", turned)

    def fit_from(start):
        asked.append(start)
        got = others[len(asked) - 1] if len(asked) <= len(others) else ValueError("no rig")
        if isinstance(got, Exception):
            raise got
        return got

    return starts.other_starts_step(first, fit_from, None, _options()), asked


def test_rays_determined_well_enough_are_not_fitted_again(monkeypatch):
    first = _fitted(ray=(starts.RAYS_WEAK_DEG, 1.0))
    out, asked = _run(first, [], monkeypatch)
    assert out is first and asked == []


def test_weak_rays_are_fitted_from_every_other_start_and_the_lowest_cost_taken(monkeypatch):
    first = _fitted(chi2=5.0)
    better = _fitted(chi2=0.0, deg=2.0, ray=(0.9, 1.5))
    out, asked = _run(first, [_fitted(chi2=400.0), better, _fitted(chi2=900.0)], monkeypatch)
    assert asked == STARTS
    assert out.camera is better.camera
    assert out.report.warnings[-1].startswith(STARTS_STATED)
    assert "(from the rim at 35 deg)" in out.report.warnings[-1]


def test_the_mirror_is_turned_from_the_lowest_cost_along_the_focal_length(monkeypatch):
    """The turns start from the best fit of the focal length's starts, and a turned fit of
    lower cost still is taken."""
    along_f = _fitted(chi2=0.0, deg=1.0)
    turned = _fitted(chi2=-10.0, deg=4.0)
    others = [_fitted(chi2=50.0), along_f, ValueError(), ValueError(), turned]
    turned_from = []
    out, _ = _run(_fitted(chi2=30.0), others, monkeypatch, turned_from)
    assert turned_from and all(f is along_f for f in turned_from)
    assert out.camera is turned.camera
    assert f"(from the mirror turned {starts.TURN_DEG[0]:g} deg)" in out.report.warnings[-1]


def test_a_fit_as_good_elsewhere_widens_the_stated_uncertainty_to_its_spread(monkeypatch):
    """The first fit's rays 3 deg from the best's, its cost within chi-square (8 dof, p =
    0.001: 26.1) of it: stated 3 deg, not the linearised 1."""
    first = _fitted(chi2=20.0, deg=3.0)
    out, _ = _run(first, [_fitted(chi2=0.0)], monkeypatch)
    assert out.report.ray_std_deg == pytest.approx((3.0, 3.0), abs=1e-6)


def test_a_fit_worse_beyond_chance_or_on_other_views_does_not_widen_it(monkeypatch):
    first = _fitted(chi2=0.0)
    others = [_fitted(chi2=30.0, deg=5.0), _fitted(chi2=-50.0, deg=9.0, used=(0, 1)), ValueError()]
    out, _ = _run(first, others, monkeypatch)
    assert out.camera is first.camera
    assert out.report.ray_std_deg == pytest.approx((1.0, 2.0))
    assert "0 other fit(s) end within chi-square 26.1" in out.report.warnings[-1]


def test_a_first_fit_that_is_no_rig_is_replaced_by_the_other_starts(monkeypatch):
    """The first start's adjustment ran off to a rig that cannot be: the other starts are
    fitted all the same, and the lowest of theirs is taken, the note saying why."""
    first = starts.NoRig(_fitted().rounds, "", None, ValueError("the camera centre is above it"))
    other = _fitted(chi2=0.0)
    out, asked = _run(first, [ValueError(), other], monkeypatch)
    assert out.camera is other.camera
    assert len(asked) == len(STARTS)
    said = out.report.warnings[-1]
    assert "the first start's fit was refused (the camera centre is above it)" in said


def test_where_no_start_ends_at_a_rig_the_first_refusal_is_raised(monkeypatch):
    refusal = ValueError("the camera centre is above it")
    first = starts.NoRig(_fitted().rounds, "", None, refusal)
    with pytest.raises(ValueError, match="the camera centre is above it"):
        _run(first, [], monkeypatch)


def test_a_sphere_turned_about_its_centre_images_every_point_where_it_did():
    """The turn of the other starts is a symmetry of the sphere: a scene point, held still,
    is seen at the same pixel (within 1e-6 px) by the rig with its sphere turned 15 deg."""
    camera = rig("sphere")
    rvec = np.radians([15.0, -6.0, 3.0])
    turned = starts.turned_about_centre(camera, rvec)
    Q = cv2.Rodrigues(rvec)[0]
    C = np.array([0.0, 0.0, camera.mirror.vertex_z + camera.mirror.R])
    rng = np.random.default_rng(0)
    d = rng.normal(size=(400, 3)) * [1.0, 1.0, 0.3] + [0.0, 0.0, -0.8]
    X = 2000.0 * d / np.linalg.norm(d, axis=1, keepdims=True)  # (in the old mirror frame)
    before = camera.project(X)
    Z = turned.R.T @ camera.R @ Q  # (its gauge turns the new frame about the mirror's axis)
    after = turned.project(((X - C) @ Q + C) @ Z.T)  # Z (Q^T (X - C) + C): the same points
    both = np.isfinite(before).all(1) & np.isfinite(after).all(1)
    assert both.sum() > 100
    assert np.abs(after[both] - before[both]).max() < 1e-6
    assert not np.allclose(turned.R, camera.R)  # (the posture did change)
