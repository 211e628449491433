"""The rays' uncertainty checked by the held-out check's folds: a delete-d jackknife.

The report's ray uncertainty (:func:`.adjustment.ray_uncertainty`) is linearised at the
estimate. Where the adjustment's cost has a long, flat or curved valley, the Jacobian there can
say the rays are well determined while a fit as good lies far along the valley:
``benchmarks/bench_mirrors_hostile.py``'s prolate ellipsoid behind the wide-angle lens states
1.36 deg (median) with its rays 10.73 deg off, and the adjustment started at the truth ends
1.3 deg from it with a cost only 1.4 times the residual variance higher (the information
bound at the truth is 1.9 deg, the Jacobian there says 4 times less about the mirror's axis
than at the estimate). No local quantity shows it; the calibrations of the held-out check's
folds (:mod:`.heldout`, each from its own start on ``(k - 1) / k`` of the views) do: they land
at different places along the valley.

With ``k`` folds of ``d = n / k`` views each left out, the delete-d jackknife's variance of a
ray is ``(n - d) / (d k) sum_s theta_s^2 = (k - 1) / k sum_s theta_s^2`` (``theta_s`` the angle
between fold ``s``'s ray and the full fit's; Shao & Wu 1989, the full fit taken as the
centre, which only adds). When the linearised uncertainty holds, ``sum_s theta_s^2`` over it
squared is about chi-square with ``k - 1`` degrees of freedom: the linearised uncertainty is
rejected when the jackknife's median exceeds :func:`rejection_ratio` times it (``p =
0.001``), and the report then states the jackknife's, with a warning (:func:`fold_check`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.stats import chi2

from .report import FOLDS_STATED

__all__ = [
    "FoldRays",
    "P_REJECT",
    "fold_check",
    "grid_angles_deg",
    "jackknife_ray_std",
    "rejection_ratio",
]

#: The probability with which a linearised uncertainty that holds is rejected.
P_REJECT = 1e-3
_GRID = 24  # pixels a side of the grid the rays are compared on (as ray_uncertainty's)


@dataclasses.dataclass(frozen=True)
class FoldRays:
    """The jackknife's ray standard deviation ``(median, worst)`` (deg), the folds it came
    from and whether it rejected the linearised uncertainty (then the report's)."""

    ray_std_deg: tuple[float, float]
    folds: int
    rejected: bool


def _grid(image_size) -> np.ndarray:
    w, h = (int(v) for v in image_size)
    u, v = np.meshgrid(np.linspace(0, w - 1, _GRID), np.linspace(0, h - 1, _GRID))
    return np.stack([u.ravel(), v.ravel()], axis=1)


def grid_angles_deg(camera, others, image_size) -> np.ndarray:
    """The angles (deg) between the rays of each camera of ``others`` and ``camera``'s, over
    the pixels of an image grid that ``camera`` sees: ``(len(others), N)``, NaN where that
    camera sees nothing."""
    px = _grid(image_size)
    d0 = camera.unproject(px)[1]
    seen = np.isfinite(d0).all(axis=1)
    px, d0 = px[seen], d0[seen]
    out = np.full((len(others), len(px)), np.nan)
    for s, cam in enumerate(others):
        d = cam.unproject(px)[1]
        ok = np.isfinite(d).all(axis=1)
        out[s, ok] = np.degrees(np.arccos(np.clip(np.sum(d[ok] * d0[ok], axis=1), -1.0, 1.0)))
    return out


def jackknife_ray_std(camera, fold_cameras, image_size) -> tuple[float, float]:
    """The delete-d jackknife's standard deviation (deg) of the rays of ``camera`` from the
    calibrations ``fold_cameras`` of its ``k`` folds (module docstring), over the pixels of an
    image grid that see the mirror: ``(median, worst)``; NaN with fewer than 2 folds. A pixel a
    fold's camera does not see is left out of that pixel's sum (its fold's angle unknown)."""
    k = len(fold_cameras)
    if k < 2:
        return math.nan, math.nan
    theta = np.radians(grid_angles_deg(camera, fold_cameras, image_size))
    ok = np.isfinite(theta)
    sq, n = (np.where(ok, theta, 0.0) ** 2).sum(axis=0), ok.sum(axis=0)
    use = n >= 2
    if not use.any():
        return math.nan, math.nan
    deg = np.degrees(np.sqrt((k - 1) / k * sq[use] * k / n[use]))
    return float(np.median(deg)), float(np.max(deg))


def rejection_ratio(k: int) -> float:
    """The jackknife's ray uncertainty over the linearised one above which the linearised is
    rejected: ``sqrt(chi2_{k-1}(1 - P_REJECT) / (k - 1))`` (module docstring)."""
    return math.sqrt(chi2.ppf(1.0 - P_REJECT, k - 1) / (k - 1))


def fold_check(report, camera, fold_cameras, image_size):
    """``report`` with the folds' check of its rays' uncertainty (module docstring): its
    ``ray_std_deg`` the jackknife's and a note (:data:`.report.FOLDS_STATED`) where the folds
    reject the linearised one; ``(report, FoldRays or None)``."""
    k = len(fold_cameras)
    jk = jackknife_ray_std(camera, fold_cameras, image_size)
    lin_med, lin_max = report.ray_std_deg
    if not all(math.isfinite(v) for v in (*jk, lin_med)):
        return report, None
    rejected = jk[0] > rejection_ratio(k) * lin_med
    found = FoldRays(jk, k, bool(rejected))
    if not rejected:
        return report, found
    msg = (
        f"{FOLDS_STATED} {k} folds' (a delete-d jackknife of their calibrations: {jk[0]:.3f} "
        f"deg, median over the mirror's image; worst {jk[1]:.3f} deg), above the adjustment's "
        f"linearised {lin_med:.3f} deg beyond chance (p = {P_REJECT:g}): a fit as good lies "
        f"elsewhere along a flat valley, or the model misfits these views; more views, nearer "
        f"the mirror's rim and around it, narrow it"
    )
    ray = (max(jk[0], lin_med), max(jk[1], lin_max))
    return dataclasses.replace(report, ray_std_deg=ray, warnings=(*report.warnings, msg)), found
