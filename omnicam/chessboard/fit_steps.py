"""The fitting steps of :func:`.calibrate.calibrate_pattern`, each returning a typed result.

corners (:func:`corner_step` -> :class:`CornerStep`) -> the adjustment
(:func:`adjustment_step` -> :class:`AdjustmentStep`), in rounds of detection and adjustment
(:func:`rounds_step` -> :class:`Rounds`) -> a held shape checked (:func:`shape_check_step`)
-> the camera and its report (:func:`report_step`, the warnings by
:func:`.report_warnings.report_warnings`).
"""

from __future__ import annotations

import dataclasses
import math
import warnings as _warnings
from typing import Any

import numpy as np

from ..camera import MisalignedCatadioptricCamera
from .adjustment import (
    D_NAMES,
    AdjustmentModel,
    BundleAdjustment,
    ray_uncertainty,
    robust_residuals,
    std_from_jacobian,
)
from .board_pose import board_pose_from_rays, object_points, rodrigues, start_viewpoint
from .report import PatternReport
from .report_warnings import FitFacts, implausible, report_warnings
from .steps import Boards, GreyImage, PatternOptions, RimStep, StartStep, redetect

__all__ = [
    "SHAPE_REJECT_CHI2",
    "AdjustmentStep",
    "CornerStep",
    "ResidualGroups",
    "Rounds",
    "adjustment_step",
    "carried_on",
    "corner_step",
    "mean_cost",
    "report_step",
    "rounds_step",
    "shape_check_step",
    "shape_free",
]

MIN_VIEWS = 3
_EDGE_ON_SIN = math.sin(math.radians(5.0))  # a board plane within 5 deg of the viewpoint
_N_RIM = 360  # rim points kept for the adjustment
#: Rounds of detection and adjustment: a board the views of the fitted camera find that the
#: start's did not is added and the rig fitted again, until no new board is found.
_DETECT_ROUNDS = 3
#: MINPACK's tolerances of the adjustment's first stage (the second's are 1e-10).
_STAGE1_TOL = 1e-6
#: Evaluations of the short refinement with the shape free that checks a held shape.
_SHAPE_CHECK_NFEV = 10
#: The held shape is rejected when freeing ``a, b`` lowers the cost by more than this times
#: the residual variance: chi-square with 2 degrees of freedom exceeds ``-2 ln p`` with
#: probability ``p = 0.001``.
SHAPE_REJECT_CHI2 = -2.0 * math.log(1e-3)


# -- 5. the corners -----------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class CornerStep:
    """The corners of every image (None where there is no board), each usable board's start
    pose ``{index: (rvec_b, tvec_b)}``, the images left out ``{index: reason}`` and the
    board's object points."""

    pts: list
    poses: dict
    dropped: dict
    obj: np.ndarray


def _check_points(points, n, index, pattern_size):
    arr = np.asarray(points, np.float64)
    if arr.ndim == 3 and arr.shape[1:] == (1, 2):
        arr = arr.reshape(-1, 2)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(
            f"image_points[{index}] must be an (N, 1, 2) or (N, 2) array, got shape {arr.shape}"
        )
    if len(arr) != n:
        raise ValueError(
            f"image_points[{index}] has {len(arr)} corners but pattern_size "
            f"{tuple(pattern_size)} has {n}: fix pattern_size (inner corners "
            f"(columns, rows), not squares)"
        )
    if not np.isfinite(arr).all():
        raise ValueError(f"image_points[{index}] has non-finite values")
    return arr


def _drop(dropped, i, why):
    dropped[i] = why
    _warnings.warn(f"view {i} dropped: {why}", RuntimeWarning, stacklevel=3)


def corner_step(image_points, pattern_size, square, cam0) -> CornerStep:
    """5. The corners of every view, checked, and each board's start pose from its rays
    under ``cam0`` (:class:`CornerStep`); a board seen edge-on is left out."""
    cols, rows = pattern_size
    dropped: dict[int, str] = {}
    pts: list[np.ndarray | None] = []
    for i, p in enumerate(image_points):
        if p is None:
            pts.append(None)
            dropped[i] = "no board found"
            continue
        pts.append(_check_points(p, cols * rows, i, (cols, rows)))
    found = [i for i, p in enumerate(pts) if p is not None]
    if not found:
        raise ValueError(
            f"no {cols}x{rows} chessboard was found in any of the {len(pts)} "
            f"image(s): check pattern_size (inner corners (columns, rows), not "
            f"squares) and that the whole board is seen in the mirror"
        )
    for i in sorted(dropped):
        _warnings.warn(f"view {i} dropped: {dropped[i]}", RuntimeWarning, stacklevel=2)
    obj = object_points((cols, rows), square)
    viewpoint = start_viewpoint(cam0)
    poses, edge_on = {}, []
    for i in found:
        P, d = cam0.unproject(pts[i])
        if not np.isfinite(d).all():
            _drop(dropped, i, "corners outside the mirror rim")
            continue
        rvec_b, tvec_b, _ = board_pose_from_rays(P, d, obj, viewpoint)
        n = rodrigues(rvec_b)[:, 2]
        centre = obj.mean(axis=0) @ rodrigues(rvec_b).T + tvec_b - viewpoint
        if abs(n @ centre) < _EDGE_ON_SIN * np.linalg.norm(centre):
            _drop(dropped, i, "board seen edge-on (its plane passes through the camera)")
            edge_on.append(i)
            continue
        poses[i] = (rvec_b, tvec_b)
    if edge_on and len(edge_on) == len(found):
        raise ValueError(
            "all boards are seen edge-on (their planes pass through the camera): "
            "turn the board towards the mirror"
        )
    if len(poses) < MIN_VIEWS:
        raise ValueError(
            f"only {len(poses)} usable view(s) of the board (need at least "
            f"{MIN_VIEWS}; dropped: {dropped}): take more views of the whole "
            f"board around the mirror"
        )
    return CornerStep(pts, poses, dropped, obj)


# -- 6. the adjustment --------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class ResidualGroups:
    """Where each group of the adjustment's residuals lies (:meth:`.BundleAdjustment.residuals`
    gives the corners', the rim's, then the outline's)."""

    corners: slice
    rim: slice
    outline: slice

    @classmethod
    def of(cls, adj: BundleAdjustment) -> ResidualGroups:
        """The groups of ``adj``'s residuals, from its own sizes."""
        n_corners = adj.obs.size
        n_boards = n_corners + len(adj.rim_px)
        return cls(slice(0, n_corners), slice(n_corners, n_boards), slice(n_boards, None))

    @property
    def sizes(self) -> tuple[int, int]:
        """The lengths of the corners' and the rim's groups (the outline takes the rest)."""
        return (self.corners.stop, self.rim.stop - self.rim.start)


@dataclasses.dataclass(frozen=True)
class AdjustmentStep:
    """The adjustment (:class:`.adjustment.BundleAdjustment`) and its solution, the views
    used, their RMS ``{index: px}``, the rim points used, the views it dropped
    ``{index: reason}`` (views whose RMS stands out) and its warnings."""

    adj: BundleAdjustment
    sol: Any
    used: list
    view_rms: dict
    rim_px: np.ndarray
    dropped: dict
    warnings: tuple[str, ...]


def _view_rms(adj, x, ids):
    """``{view index: corner RMS, px}`` of the views ``ids`` of ``adj`` at ``x``."""
    r = adj.corner_residuals(x).reshape(len(ids), -1)
    return {i: float(np.sqrt(np.mean(r[k] ** 2) * 2)) for k, i in enumerate(ids)}


def _adjust(cam0, mirror, corners, rim_px, model, f_scale, view_ids, x_boards, x_global=None):
    """The adjustment of the views ``view_ids`` from ``x_boards`` (and ``x_global``, or the
    start's): ``(adj, solution)``."""
    pts = corners.pts
    adj = BundleAdjustment(cam0, mirror, corners.obj, [pts[i] for i in view_ids], rim_px, model)
    x0 = np.concatenate([adj.x0_global if x_global is None else x_global, np.concatenate(x_boards)])
    if x_global is None:
        # stage 1: principal point, skew and distortion held at the start, so the fit does
        # not first wander along the valley where a shift of the principal point (or
        # tangential distortion) trades against a tilt of the mirror; only a start for
        # stage 2, which converges to 1e-10 on its own: its last evaluations would lower the
        # cost by fractions of a millionth. By MINPACK's steps even with the shape free: where
        # stage 2 starts decides which of the valley's minima it reaches (KaidanOmni's has
        # them at f = 504, 672 and 4400 px), and MINPACK's 20 evaluations start it towards
        # the lowest, where the accelerated solver's stopped at 19 or converged do not
        adj.fixed = {"cx", "cy", "skew", *D_NAMES}
        x0 = adj.solve(x0, f_scale=f_scale, max_nfev=20, tol=_STAGE1_TOL, accelerate=False).x
        adj.fixed = set()
    # with the mirror's shape free the fit follows a long, flat valley (a, b trade against
    # f and the camera's axial position; only the rig's non-centrality tells them apart),
    # which takes many more iterations
    return adj, adj.solve(x0, f_scale=f_scale, max_nfev=400 if model.fit_shape else 100)


def adjustment_step(
    cam0, mirror, corners: CornerStep, rim_seen, model, options: PatternOptions
) -> AdjustmentStep:
    """6. The bundle adjustment in two stages, views whose RMS exceeds ``max(outlier_factor
    * median, outlier_min_px)`` reported (and dropped by ``drop_outlier_views``, the rig then
    fitted again): an :class:`AdjustmentStep`."""
    poses, f_scale = corners.poses, options.f_scale
    warns, dropped = [], {}
    used = sorted(poses)
    rim_px = rim_seen
    if len(rim_px) > _N_RIM:
        rim_px = rim_px[np.linspace(0, len(rim_px) - 1, _N_RIM).round().astype(int)]
    fit = (cam0, mirror, corners, rim_px, model, f_scale)
    adj, sol = _adjust(*fit, used, [np.concatenate(poses[i]) for i in used])
    vr = _view_rms(adj, sol.x, used)
    med = float(np.median(list(vr.values())))
    limit = max(options.outlier_factor * med, options.outlier_min_px)
    standing_out = [i for i in used if vr[i] > limit]
    drop = options.drop_outlier_views
    if standing_out:
        what = "dropped" if drop else "kept"
        msg = (
            f"view(s) {standing_out} reproject with RMS "
            f"{', '.join(f'{vr[i]:.2f}' for i in standing_out)} px against a median of "
            f"{med:.3f} px ({what}; check their corners)"
        )
        warns.append(msg)
        _warnings.warn(msg, RuntimeWarning, stacklevel=2)
        if drop and len(used) - len(standing_out) >= MIN_VIEWS:
            B = adj.boards(sol.x)
            keep = [k for k, i in enumerate(used) if i not in standing_out]
            for i in standing_out:
                dropped[i] = f"RMS {vr[i]:.2f} px stands out (median {med:.3f} px)"
            used = [used[k] for k in keep]
            adj, sol = _adjust(*fit, used, [B[k] for k in keep], sol.x[: adj.n_global])
            vr = _view_rms(adj, sol.x, used)
        elif drop:
            warns.append("too few views would remain: the outliers were kept")
    return AdjustmentStep(adj, sol, used, vr, rim_px, dropped, tuple(warns))


# -- 7. rounds of detection and adjustment ------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Rounds:
    """The boards as the last round knew them, its corners and its adjustment."""

    boards: Boards
    corners: CornerStep
    fit: AdjustmentStep


def rounds_step(
    greys: tuple[GreyImage, ...],
    boards: Boards,
    start: StartStep,
    rim: RimStep,
    model: AdjustmentModel,
    options: PatternOptions,
    progress=None,
) -> Rounds:
    """7. The adjustment from the start; while boards are missing, the views of the fitted
    camera, which aim better than the start's, look for them again, and the rig is fitted
    again only when one is found (at most :data:`_DETECT_ROUNDS` adjustments: a board found
    after the last would be reported but not fitted)."""
    camera, shape = start.camera, start.mirror
    for round_ in range(_DETECT_ROUNDS):
        corners = corner_step(boards.points, options.pattern_size, options.square, camera)
        fit = adjustment_step(camera, shape, corners, rim.seen, model, options)
        missing = boards.missing()
        if not greys or not missing or round_ == _DETECT_ROUNDS - 1:
            break
        camera = fit.adj.to_gauge(fit.sol.x, options.image_size)[0]
        shape = camera.mirror
        new = redetect(greys, missing, options.pattern_size, camera, progress)
        if not new:
            break
        boards = boards.with_found(new, "views (fitted camera)")
    return Rounds(boards, corners, fit)


# -- 8. a shape held from the central fit, checked ----------------------------------------------
def mean_cost(sol) -> float:
    """The robust cost per residual of a solution (fits of different views compared)."""
    return 2.0 * float(sol.cost) / max(len(sol.fun), 1)


def carried_on(fit: AdjustmentStep, adj2, x, f_scale) -> AdjustmentStep:
    """``fit`` replaced by the adjustment ``adj2`` solved to convergence from ``x`` (a short
    refinement's end, in a likelihood-ratio test that took it), its views' RMS anew."""
    sol2 = adj2.solve(x, f_scale=f_scale, max_nfev=400)
    return dataclasses.replace(fit, adj=adj2, sol=sol2, view_rms=_view_rms(adj2, sol2.x, fit.used))


def shape_free(adj, x, camera, board_poses):
    """The adjustment ``adj`` at ``x`` again, with the mirror's ``a, b`` free: ``(adj2, x2)``
    at the same solution (``camera`` and its ``board_poses`` in the gauge), whose covariance
    holds what an unknown shape leaves unknown."""
    model = AdjustmentModel(
        adj.free_d,
        adj.n_d,
        adj.fit_skew,
        True,
        adj.lens_px,
        None if adj.fit_lens_z else adj.lens_z,
    )
    adj2 = BundleAdjustment(camera, camera.mirror, adj.obj, adj.views, adj.rim_px, model)
    boards = [np.concatenate([np.ravel(r), np.ravel(t)]) for r, t in board_poses]
    return adj2, np.concatenate([adj2.x0_global, *boards])


def _held_shape_chi2(fit: AdjustmentStep, image_size, f_scale):
    """How much a short refinement with ``a, b`` free lowers the corners' and the rim's
    robust cost (the outline's left out: its misfit is the coaxial circle's model error more
    than noise), in units of the residual variance: ``(chi2, adj2, short solution, camera)``."""
    adj, sol = fit.adj, fit.sol
    camera, gauged = adj.to_gauge(sol.x, image_size)
    adj2, x2 = shape_free(adj, sol.x, camera, gauged)
    boards_rows = slice(0, ResidualGroups.of(adj2).rim.stop)

    def boards_cost(x):
        z = robust_residuals(adj2.residuals(x), f_scale)[0][boards_rows]
        return float(z @ z)

    cost = boards_cost(x2)
    sigma2 = cost / max(boards_rows.stop - len(sol.x), 1)
    # MINPACK's steps: the test's threshold was set by their gain (its first step is nearly
    # Gauss-Newton's, the accelerated solver's first ones are damped)
    short = adj2.solve(x2, f_scale=f_scale, max_nfev=_SHAPE_CHECK_NFEV, accelerate=False)
    return (cost - boards_cost(short.x)) / sigma2, adj2, short, camera


def shape_check_step(rounds: Rounds, start: StartStep, rim: RimStep, model, options) -> Rounds:
    """8. A shape held from the central fit checked: a likelihood-ratio test
    (:func:`_held_shape_chi2`). When freeing ``a, b`` lowers the cost by more than
    :data:`SHAPE_REJECT_CHI2` times the residual variance, the corners reject the central
    fit's shape (on a wide-angle rig the rays are then off by several times their stated
    uncertainty, which a shape held at a biased value does not contain), and ``a, b`` are
    estimated, with a warning: the fit with them free carried on from the held solution, and
    the adjustment with them free from the start camera, whichever ends at the lower mean
    robust cost (the held solution lies in the valley the wrong shape made, and can lead to a
    minimum of its own, as on some wide-angle renders of
    ``benchmarks/bench_chessboard_hostile.py``). Returns ``rounds`` when the held shape
    stands."""
    fit, f_scale = rounds.fit, options.f_scale
    chi2, adj2, short, camera = _held_shape_chi2(fit, options.image_size, f_scale)
    if not chi2 > SHAPE_REJECT_CHI2:
        return rounds
    ratio = camera.mirror.a / camera.mirror.b
    msg = (
        f"the central fit's mirror shape (a / b = {ratio:.3f}) is rejected by the corners: "
        f"freeing a, b lowers the cost by {chi2:.0f} times the residual variance (above "
        f"{SHAPE_REJECT_CHI2:.1f}, chi-square with 2 degrees of freedom at p = 0.001), so a, b "
        f"were estimated"
    )
    _warnings.warn(msg, RuntimeWarning, stacklevel=2)
    held = carried_on(fit, adj2, short.x, f_scale)
    sol2 = held.sol
    held = dataclasses.replace(held, warnings=(*fit.warnings, msg))
    with _warnings.catch_warnings(record=True) as caught:  # said only if it is taken
        _warnings.simplefilter("always")
        try:
            alt_corners = corner_step(
                rounds.boards.points, options.pattern_size, options.square, start.camera
            )
            free = dataclasses.replace(model, fit_shape=True)
            alt = adjustment_step(start.camera, start.mirror, alt_corners, rim.seen, free, options)
        except ValueError:
            return dataclasses.replace(rounds, fit=held)
    if not mean_cost(alt.sol) < mean_cost(sol2):
        return dataclasses.replace(rounds, fit=held)
    for w in caught:
        _warnings.warn(w.message, w.category, stacklevel=2)
    alt = dataclasses.replace(alt, warnings=(*alt.warnings, msg))
    return dataclasses.replace(rounds, corners=alt_corners, fit=alt)


# -- 9. the camera and its report ---------------------------------------------------------------
def _row_sigma(r, n_params, groups: ResidualGroups):
    """Each row's noise, estimated from the residuals ``r`` of its group (the corners, the rim,
    the outline): the RMS of the group, its degrees of freedom shared out in proportion to its
    rows. The adjustment weighs every row alike, so one sigma pooled over groups of different
    noise (the rim's points fit better than the corners) would understate the rays'
    uncertainty."""
    m = len(r)
    dof = max(m - n_params, 1) / max(m, 1)
    sigma = np.empty(m)
    for rows in (groups.corners, groups.rim, groups.outline):
        lo, hi, _ = rows.indices(m)
        if hi > lo:
            sigma[lo:hi] = math.sqrt(float(r[lo:hi] @ r[lo:hi]) / (dof * (hi - lo)))
    return sigma


def report_step(
    rounds: Rounds, start: StartStep, lens_note, options: PatternOptions
) -> tuple[MisalignedCatadioptricCamera, PatternReport]:
    """9. The camera in the gauge and the :class:`PatternReport` with the a posteriori
    standard deviations, the plausibility checks and the warnings
    (:func:`.report_warnings.report_warnings`). With the mirror unknown and its shape held
    (``refine_mirror_shape=False``), the standard deviations are those of the fit with
    ``a, b`` free at the same solution (:func:`shape_free`): the shape taken from the central
    fit is not known, and what it leaves unknown must be in them."""
    fit, corners, image_size = rounds.fit, rounds.corners, options.image_size
    adj, sol, used, obj = fit.adj, fit.sol, fit.used, corners.obj
    try:
        camera, gauged = adj.to_gauge(sol.x, image_size)
    except ValueError as e:  # (an aspheric fit can run off along its valley: MiniOmni's)
        raise ValueError(
            f"the adjustment ended at a rig that cannot be ({e}); the start was too far: give "
            f"the mirror (a data sheet) or K as a start"
        ) from None
    r_all = adj.residuals(sol.x)
    groups = ResidualGroups.of(adj)
    held_shape = options.mirror is None and not adj.fit_shape
    adj_u, x_u = shape_free(adj, sol.x, camera, gauged) if held_shape else (adj, sol.x)
    sigma = _row_sigma(r_all, len(sol.x), groups)
    std, cov = std_from_jacobian(adj_u, x_u, adj_u.jacobian(x_u), sigma, unweighted=True)
    ray_deg = ray_uncertainty(adj_u, x_u, cov, image_size)
    corner_r, rim_r, lens_r = r_all[groups.corners], r_all[groups.rim], r_all[groups.outline]
    board_poses = {i: gauged[k] for k, i in enumerate(used)}
    rms = float(np.sqrt(np.mean(corner_r**2) * 2))
    facts = FitFacts(
        camera=camera,
        std=std,
        ray_deg=ray_deg,
        rms=rms,
        n_views=len(used),
        board_centres=np.array(
            [obj.mean(axis=0) @ rodrigues(p[0]).T + p[1] for p in board_poses.values()]
        ),
        converged=bool(sol.success),
        solver_message=str(sol.message),
        held_shape=held_shape,
        estimated_shape=adj.fit_shape,
        central=start.central,
        image_size=image_size,
        plausibility=implausible(camera, image_size),
    )
    warns = list(fit.warnings) + report_warnings(facts)
    report = PatternReport(
        rms=rms,
        ray_std_deg=ray_deg,
        view_rms=fit.view_rms,
        corners_used={i: len(obj) for i in used},
        board_poses=board_poses,
        image_points=[
            None if p is None else p.reshape(-1, 1, 2).astype(np.float32) for p in corners.pts
        ],
        reprojected={i: camera.project(obj, *board_poses[i]).reshape(-1, 1, 2) for i in used},
        rim_points=fit.rim_px,
        rim_rms=float(np.sqrt(np.mean(rim_r**2))),
        std=std,
        warnings=tuple(warns),
        lens_rms=float(np.sqrt(np.mean(lens_r**2))) if len(lens_r) else math.nan,
        lens_note=lens_note,
        dropped=dict(sorted({**corners.dropped, **fit.dropped}.items())),
        nfev=int(sol.nfev),
        camera=camera,
        start=start.camera,
        plausibility=facts.plausibility,
        dist_model=options.dist_model,
    )
    return camera, report
