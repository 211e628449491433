"""What a chessboard calibration predicts on views it did not fit (k-fold held-out corners).

The views are split into ``k`` folds (view ``i`` in fold ``i % k``); the rig is calibrated on
the other folds, its intrinsics (and for omnicam the mirror and posture) kept, and each held-out
view's board pose alone is fitted to its corners; its corner RMS (px) is what the calibration
predicts there. A model that bends to fit its training views where nothing constrains it, or a
central model that misplaces boards at depths the training views do not cover, shows up here,
not in the training RMS. ``cv2.omnidir.calibrate`` (Mei's unified model, every intrinsic free)
gets the same test on the same folds, for comparison.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import cv2
import numpy as np
from scipy.optimize import least_squares

from .._progress import say
from ..raytrace import undistort_normalized
from .board_pose import board_pose_from_rays

__all__ = [
    "HeldOut",
    "cross_validate",
    "fold_of",
    "heldout_rms",
    "omnicam_predictor",
    "omnidir_predictor",
    "unified_predictor",
]

_UNSEEN_PX = 1e3  # residual of a corner the model cannot see (as the shared held-out test)


@dataclasses.dataclass(frozen=True)
class HeldOut:
    """k-fold held-out corner RMS of a chessboard calibration.

    Attributes
    ----------
    folds : int
    rms : dict
        ``{view: px}``: each view's corner RMS with only its board pose fitted, under the rig
        calibrated on the other folds.
    omnidir : dict
        The same for ``cv2.omnidir.calibrate`` on the same folds (empty if it failed).
    failed : dict
        ``{view: why}`` of the views whose fold's training views could not be calibrated.
    """

    folds: int
    rms: dict
    omnidir: dict
    failed: dict = dataclasses.field(default_factory=dict)

    @property
    def median(self) -> float:
        """Median of :attr:`rms` (NaN when every fold failed)."""
        return float(np.median(list(self.rms.values()))) if self.rms else math.nan

    @property
    def max(self) -> float:
        """Largest of :attr:`rms` (NaN when every fold failed)."""
        return float(np.max(list(self.rms.values()))) if self.rms else math.nan

    def summary(self) -> str:
        """One line: median and max, and cv2.omnidir's beside them."""
        line = (
            f"held-out corner RMS ({self.folds}-fold, each view's board pose alone): "
            f"median {self.median:.3f} px, max {self.max:.3f} px"
        )
        if self.omnidir:
            v = list(self.omnidir.values())
            line += f"; cv2.omnidir on the same folds {np.median(v):.3f} / {np.max(v):.3f} px"
        if self.failed:
            line += (
                f"; {len(self.failed)} view(s) not predicted: their fold's training views "
                f"could not be calibrated ({next(iter(self.failed.values()))})"
            )
        return line


def fold_of(n_views: int, k: int) -> list[list[int]]:
    """``k`` folds of ``range(n_views)``: view ``i`` in fold ``i % k``."""
    return [list(range(n_views))[f::k] for f in range(k)]


def heldout_rms(project: Callable, directions: Callable, corners, obj) -> float:
    """Corner RMS (px) of one view after fitting only its board pose.

    Parameters
    ----------
    project : callable
        ``project(obj, rvec, tvec) -> (N, 2)`` pixels (NaN where unseen).
    directions : callable
        ``directions(pixels) -> (origins (N, 3), directions (N, 3))`` of the pixels' rays.
    corners : (N, 2) array_like
    obj : (N, 3) ndarray
        The board's object points.
    """
    p = np.asarray(corners, np.float64).reshape(-1, 2)
    P, d = directions(p)
    ok = np.isfinite(d).all(axis=1) & np.isfinite(P).all(axis=1)
    if ok.sum() < 4:
        return math.inf
    rvec, tvec, _ = board_pose_from_rays(P[ok], d[ok], obj[ok], P[ok].mean(axis=0))

    def residuals(x):
        r = (project(obj, x[:3], x[3:]) - p).ravel()
        return np.where(np.isfinite(r), r, _UNSEEN_PX)

    sol = least_squares(residuals, np.concatenate([rvec, tvec]), method="lm", x_scale="jac")
    r = residuals(sol.x).reshape(-1, 2)
    return float(np.sqrt(np.mean(np.sum(r * r, axis=1))))


def omnicam_predictor(camera) -> tuple[Callable, Callable]:
    """``(project, directions)`` of a :class:`~omnicam.MisalignedHyperbolicCamera`."""

    def project(obj, rvec, tvec):
        return np.asarray(camera.project(obj, rvec, tvec), np.float64).reshape(-1, 2)

    def directions(px):
        P, d = camera.unproject(px)
        return np.asarray(P, np.float64).reshape(-1, 3), np.asarray(d, np.float64).reshape(-1, 3)

    return project, directions


def _unified_directions(px, K, xi, D):
    """Unit rays of pixels under Mei's unified model (``cv2.omnidir``'s): ``K`` and the
    radial-tangential ``D = (k1, k2, p1, p2)`` undone
    (:func:`omnicam.raytrace.undistort_normalized`), then the point on the unit sphere that
    projects there from ``(0, 0, -xi)``; NaN where no point does (with ``xi > 1``, past the
    model's horizon ``r^2 > 1 / (xi^2 - 1)``)."""
    xy = undistort_normalized(np.ascontiguousarray(px, np.float64), K, np.ravel(D)[:4])
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    with np.errstate(invalid="ignore"):  # NaN past the horizon, as the docstring says
        lam = (xi + np.sqrt(1 + (1 - xi * xi) * r2)) / (r2 + 1)
    X = np.stack([lam * x, lam * y, lam - xi], axis=1)
    return X / np.linalg.norm(X, axis=1, keepdims=True)


def omnidir_predictor(views: Sequence, obj, image_size) -> tuple[Callable, Callable]:
    """``(project, directions)`` of ``cv2.omnidir.calibrate`` (flags 0: ``K`` with skew, ``xi``
    and ``D`` all free) fitted to ``views`` (``(N, 2)`` corners each)."""
    op = [obj.reshape(1, -1, 3).astype(np.float64) for _ in views]
    ip = [np.asarray(v, np.float64).reshape(1, -1, 2) for v in views]
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-8)
    # cv2's stubs make K, xi and D arrays; None (OpenCV's noArray) lets calibrate start them
    _, K, xi, D, _, _, _ = cv2.omnidir.calibrate(  # type: ignore[call-overload]
        op, ip, tuple(int(v) for v in image_size), None, None, None, 0, crit
    )
    return unified_predictor(K, float(np.ravel(xi)[0]), D)


def unified_predictor(K, xi, D) -> tuple[Callable, Callable]:
    """``(project, directions)`` of Mei's unified model ``K, xi, D`` (``cv2.omnidir``'s)."""
    K = np.asarray(K, np.float64)
    D = np.asarray(D, np.float64).reshape(1, 4)

    def project(o, rvec, tvec):
        q, _ = cv2.omnidir.projectPoints(
            o.reshape(-1, 1, 3),
            np.asarray(rvec, np.float64).reshape(3, 1),
            np.asarray(tvec, np.float64).reshape(3, 1),
            K,
            float(xi),
            D,
        )
        return q.reshape(-1, 2)

    def directions(px):
        d = _unified_directions(np.asarray(px, np.float64).reshape(-1, 2), K, float(xi), D)
        return np.zeros_like(d), d

    return project, directions


def cross_validate(fit: Callable, views: dict, obj, image_size, k: int = 5) -> HeldOut:
    """k-fold held-out corner RMS of ``fit`` and of ``cv2.omnidir.calibrate``.

    Parameters
    ----------
    fit : callable
        ``fit(indices) -> camera``: the calibration on the views ``indices`` (keys of
        ``views``) alone.
    views : dict
        ``{view index: (N, 2) corners}`` of the views used.
    obj : (N, 3) ndarray
        The board's object points.
    image_size : (int, int)
    k : int
        Folds (at most the number of views; each training set keeps at least 3 views).

    Returns
    -------
    HeldOut
    """
    ids = sorted(views)
    k = min(int(k), len(ids))
    if k < 2 or len(ids) - math.ceil(len(ids) / k) < 3:
        raise ValueError(
            f"a {k}-fold held-out check needs at least 2 folds and 3 training views per fold; "
            f"there are {len(ids)} views"
        )
    rms: dict[int, float] = {}
    omni: dict[int, float] | None = {}
    failed: dict[int, str] = {}
    for n, fold in enumerate(fold_of(len(ids), k)):
        held = [ids[j] for j in fold]
        train = [i for i in ids if i not in held]
        say(f"held-out check: fold {n + 1}/{k}, the rig calibrated on {len(train)} views")
        try:
            project, directions = omnicam_predictor(fit(train))
        except ValueError as e:  # this fold's views alone cannot determine the rig
            for i in held:
                failed[i] = str(e)
        else:
            for i in held:
                rms[i] = heldout_rms(project, directions, views[i], obj)
        try:
            project, directions = omnidir_predictor([views[i] for i in train], obj, image_size)
        except cv2.error:
            omni = None
        if omni is not None:
            for i in held:
                omni[i] = heldout_rms(project, directions, views[i], obj)
    return HeldOut(
        folds=k,
        rms=dict(sorted(rms.items())),
        omnidir=dict(sorted((omni or {}).items())),
        failed=dict(sorted(failed.items())),
    )
