"""Other starts where the views determine the rays weakly: along the focal length and with
the mirror turned, and the rays' spread over the fits as good stated.

The generic start (:mod:`.any_start`) takes the focal length that makes the rim subtend
:data:`.central_start.RIM_HALF_ANGLE_DEG` (20 deg): no central model tells it; and it
starts the mirror aligned, its tilt left to the adjustment. Where the views determine the
rays weakly (behind a wide-angle lens, the rim at 35-50 deg), the adjustment's cost has
several minima, as good as each other for the data and degrees apart in the rays: along the
focal length, the lens's distortion and the mirror's shape; and along the mirror's axis, which
only its rim and its departure from a sphere hold (a sphere turned about its centre reflects
every ray as before), traded against the principal point. The uncertainty linearised at the
one minimum the start leads to says nothing of the others: on
``benchmarks/bench_mirrors_hostile.py`` behind the wide-angle lens, 5 of 18 fits stated
1.3-1.9 deg with their rays 4.2-12.5 deg off.

So where the linearised uncertainty of the rays exceeds :data:`RAYS_WEAK_DEG` (median over the
mirror's image), the same steps (the rounds of adjustment, the family's terms, the report) are
run again, on the first fit's views (none dropped, so that the costs compare), from

- the generic start with the rim at each of :data:`RIM_ANGLES_DEG` instead (:func:`_start_at`);
- then the fit of the lowest cost so far with its mirror turned about its centre of curvature
  by each of :data:`TURN_DEG` towards four sides (:func:`turned_about_centre`).

A first fit that ran off along its valley to a rig that cannot be (:class:`NoRig`, which the
report step refuses) is fitted from the other starts all the same, and refused only where none
of them ends at a rig either. The fit of the lowest robust cost is taken; the fits whose cost
is within :func:`.family.chi2_limit` of it (the globals' count of degrees of freedom: as good
for these views) are the others the data allow, and the rays' stated uncertainty is at least
their spread: the largest angle between their rays and the taken fit's, median and worst over
the mirror's image. The report says so in a note (:data:`.report.STARTS_STATED`). Each start
costs about one more fit (3, and 4 per turn), only on rigs whose rays the views determine to
worse than :data:`RAYS_WEAK_DEG` or whose first fit is no rig.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable

import cv2
import numpy as np

from .._progress import say
from ..calibration.plausibility import rim_radius_px
from ..camera import MisalignedCatadioptricCamera
from ..mirror import HyperbolicMirror
from .central_start import RIM_HALF_ANGLE_DEG
from .family import chi2_limit, family_step
from .fit_steps import Rounds, mean_cost, report_step, rounds_step
from .fold_rays import grid_angles_deg
from .report import STARTS_STATED, PatternReport
from .steps import Boards, PatternOptions, RimStep, StartStep, generic_start_step

__all__ = [
    "NoRig",
    "RAYS_WEAK_DEG",
    "RIM_ANGLES_DEG",
    "TURN_DEG",
    "Fitted",
    "first_fit",
    "fitter",
    "other_starts_step",
    "turned_about_centre",
]

#: The rim's half-angle from the camera (deg) at which the other starts put it: from a long lens
#: (10) to a wide-angle one (50); the default start's is 20.
RIM_ANGLES_DEG = (10.0, 35.0, 50.0)
#: A linearised ray uncertainty (median, deg) above this: the rays weakly determined, the
#: other starts run (near-pinhole renders state 0.13-0.38 deg, wide-angle ones 1.0-3.4).
RAYS_WEAK_DEG = 0.5
#: The turns (deg) of the mirror about its centre of curvature from which the fit of the lowest
#: cost is started again, each towards the four sides of :data:`_SIDES`.
TURN_DEG = (15.0,)
#: The axes of those turns: the mirror frame's x and y, both ways.
_SIDES = ((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, -1.0, 0.0))


@dataclasses.dataclass(frozen=True)
class Fitted:
    """One start's fit: its rounds, the family's sentence, the start, the camera and report."""

    rounds: Rounds
    family: str
    start: StartStep
    camera: MisalignedCatadioptricCamera
    report: PatternReport


@dataclasses.dataclass(frozen=True)
class NoRig:
    """A start's fit that ended at a rig that cannot be: its rounds, the family's sentence,
    the start, and the report step's refusal."""

    rounds: Rounds
    family: str
    start: StartStep
    error: ValueError


def first_fit(
    rounds: Rounds, family: str, start: StartStep, lens_note, options: PatternOptions
) -> Fitted | NoRig:
    """The generic start's fit with its camera and report, or :class:`NoRig` where the report
    step refuses it (the adjustment ran off along its valley: the other starts may not)."""
    try:
        return Fitted(rounds, family, start, *report_step(rounds, start, lens_note, options))
    except ValueError as e:
        return NoRig(rounds, family, start, e)


def _global_dof(fit) -> int:
    """The free global parameters of an adjustment (the boards' poses not counted)."""
    return sum(1 for n in fit.adj.names if n not in fit.adj.fixed)


def _chi2(fit, best) -> float:
    """How much worse ``fit``'s robust cost is than ``best``'s, in ``best``'s residual
    variances (``2 (cost - cost_best) / sigma^2``)."""
    sol = best.sol
    dof = max(len(sol.fun) - len(sol.x), 1)
    sigma2 = 2.0 * float(sol.cost) / dof
    return 2.0 * (float(fit.sol.cost) - float(sol.cost)) / sigma2


def _spread_deg(camera, others, image_size) -> tuple[float, float]:
    """The largest angle (deg) between ``camera``'s rays and each of ``others``', over the
    image grid's pixels that ``camera`` sees: ``(median, worst)``; 0 without others."""
    a = grid_angles_deg(camera, others, image_size)
    if not a.shape[1]:
        return 0.0, 0.0
    worst = np.max(np.where(np.isfinite(a), a, 0.0), axis=0, initial=0.0)
    return float(np.median(worst)), float(np.max(worst))


def other_starts_step(
    first: Fitted | NoRig,
    fit_from: Callable[[StartStep], Fitted],
    rim: RimStep,
    options: PatternOptions,
) -> Fitted:
    """``first`` (the generic start's fit) where its rays are determined to
    :data:`RAYS_WEAK_DEG` or better; else the fit of the lowest robust cost over it and the
    other starts (module docstring; ``fit_from(start)`` runs the steps from a start, one that
    fails is left out), its rays' uncertainty at least the spread of the fits as good, with a
    note. A ``first`` that is :class:`NoRig` is not among them; where no other start ends at a
    rig either, its refusal is raised."""
    if isinstance(first, Fitted) and not first.report.ray_std_deg[0] > RAYS_WEAK_DEG:
        return first
    n_turns = len(TURN_DEG) * len(_SIDES)
    say(
        f"{'the rays weakly determined' if isinstance(first, Fitted) else 'no rig'}: the rig "
        f"fitted from {len(RIM_ANGLES_DEG) + n_turns} other starts"
    )
    used = list(first.rounds.fit.used)
    fits = [first] if isinstance(first, Fitted) else []
    origin = {id(first): f"the rim at {RIM_HALF_ANGLE_DEG:g} deg"}

    def attempt(what: str, make: Callable[..., StartStep], *args) -> None:
        try:
            fit = fit_from(make(*args))
        except ValueError:  # (a start, or its fit, that is no rig)
            return
        if list(fit.rounds.fit.used) == used:  # (the same residuals: the costs compare)
            fits.append(fit)
            origin[id(fit)] = what

    for angle in RIM_ANGLES_DEG:
        attempt(f"the rim at {angle:g} deg", _start_at, first, rim, options, angle)
    if not fits:  # (no rig to turn)
        assert isinstance(first, NoRig)
        raise first.error
    lowest = _lowest(fits)
    for deg in TURN_DEG:
        for side in _SIDES:
            attempt(f"the mirror turned {deg:g} deg", _turned_start, lowest, deg, side)
    best = _lowest(fits)
    limit = chi2_limit(_global_dof(best.rounds.fit))
    kept = [f for f in fits if f is not best and _chi2(f.rounds.fit, best.rounds.fit) <= limit]
    spread = _spread_deg(best.camera, [f.camera for f in kept], options.image_size)
    lin = best.report.ray_std_deg
    ray = (max(lin[0], spread[0]), max(lin[1], spread[1]))
    why = (
        f"the linearised uncertainty ({first.report.ray_std_deg[0]:.3f} deg) says the views "
        "determine the rays weakly"
        if isinstance(first, Fitted)
        else f"the first start's fit was refused ({first.error})"
    )
    note = (
        f"{STARTS_STATED} ({ray[0]:.3f} deg, median over the mirror's image; worst "
        f"{ray[1]:.3f} deg): {why}, so the rig was fitted from "
        f"{len(fits) - isinstance(first, Fitted)} other start(s) (the rim at "
        f"{', '.join(f'{a:g}' for a in RIM_ANGLES_DEG)} deg from the camera; the mirror turned "
        f"{' and '.join(f'{d:g}' for d in TURN_DEG)} deg four ways about its centre of "
        f"curvature) and the fit of the lowest cost taken (from {origin[id(best)]}); "
        f"{len(kept)} other fit(s) end within chi-square {limit:.1f} of it, their rays up to "
        f"{spread[0]:.3f} deg (median; worst {spread[1]:.3f} deg) from its"
    )
    report = dataclasses.replace(
        best.report, ray_std_deg=ray, warnings=(*best.report.warnings, note)
    )
    return dataclasses.replace(best, report=report)


def _lowest(fits: list[Fitted]) -> Fitted:
    """The fit of the lowest robust cost (the first of equals)."""
    return min(fits, key=lambda f: mean_cost(f.rounds.fit.sol))


def fitter(
    first: Fitted | NoRig, rim: RimStep, model, options: PatternOptions, lens_note, progress=None
) -> Callable[[StartStep], Fitted]:
    """``fit_from(start)`` for :func:`other_starts_step`: the steps after the start (the
    rounds of adjustment, the family's terms, the report) on exactly ``first``'s views, none
    dropped (so that the costs compare), silent (a fit not taken says nothing), the start's
    warnings ``first``'s (the story the report tells of its start)."""
    used = set(first.rounds.fit.used)
    boards = first.rounds.boards
    on_used = Boards(
        tuple(p if i in used else None for i, p in enumerate(boards.points)), boards.found_by
    )
    same = dataclasses.replace(options, drop_outlier_views=False)

    def fit_from(other: StartStep) -> Fitted:
        other = dataclasses.replace(other, warnings=first.start.warnings)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            alt = rounds_step((), on_used, other, rim, model, same, progress)
            alt, family = family_step(alt, options)
            return Fitted(alt, family, other, *report_step(alt, other, lens_note, same))

    return fit_from


def _start_at(
    first: Fitted | NoRig, rim: RimStep, options: PatternOptions, angle: float
) -> StartStep:
    """The generic start with the rim at ``angle`` deg from the camera (its focal length
    ``rho_rim / tan(angle)``, the principal point the Taylor model's centre)."""
    start = first.start
    K = np.array(start.camera.K, np.float64)
    K[0, 0] = K[1, 1] = rim_radius_px(rim.fit) / math.tan(math.radians(angle))
    given = dataclasses.replace(options, K=K)
    return generic_start_step(first.rounds.boards, rim, given, start.central, start.taylor)


def _turned_start(fit: Fitted, deg: float, side) -> StartStep:
    """``fit``'s camera as a start, its mirror turned by ``deg`` about ``side``
    (:func:`turned_about_centre`)."""
    camera = turned_about_centre(fit.camera, math.radians(deg) * np.asarray(side, np.float64))
    return dataclasses.replace(fit.start, camera=camera, mirror=camera.mirror)


def turned_about_centre(camera: MisalignedCatadioptricCamera, rvec) -> MisalignedCatadioptricCamera:
    """The camera with its mirror turned by the rotation vector ``rvec`` (mirror frame) about
    the mirror's centre of curvature ``C = (0, 0, vertex_z + R)``, the scene held still.

    A point ``Y`` of the turned mirror's frame lies at ``X = Q (Y - C) + C`` in the old one
    (``Q`` the rotation of ``rvec``), so ``x_cam = R X + t`` becomes ``R Q Y + t + R (C - Q C)``.
    A sphere turned so is itself: every pixel sees the same scene point (its rim moves). The
    camera's gauge (docs/conventions.md) then turns the new frame about the mirror's axis, which
    the boards' poses, fitted anew from a start, take up."""
    mirror = camera.mirror
    surface = mirror.as_asphere() if isinstance(mirror, HyperbolicMirror) else mirror
    C = np.array([0.0, 0.0, surface.vertex_z + surface.R])
    Q = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))[0]
    R, t = camera.R, np.ravel(camera.tvec)
    return MisalignedCatadioptricCamera(
        camera.K,
        mirror,
        cv2.Rodrigues(R @ Q)[0].ravel(),
        t + R @ (C - Q @ C),
        D=camera.D,
        image_size=camera.image_size,
    )
