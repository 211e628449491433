"""A second start of the generic (aspheric) fit, where the first ends in a worse valley than the
central model it was started from.

The generic start (:mod:`.any_start`) is the aligned rig whose principal point is the corners'
Taylor centre: the image of the mirror's axis, which a misaligned rig moves off the principal
point (32 px for 3 deg and 3.1 mm on ``benchmarks/bench_mirrors_hostile.py``'s paraboloid behind
the near-pinhole lens). The adjustment's first stage holds the principal point at the start, and
from there the fit can settle where the mirror's shape bends to make up for it: on that render
at 0.338 px RMS (f 359 px, k -2.13, rays 1.44 deg off for 0.245 stated) against the Taylor
model's 0.320, and at 0.199 px (f 678 px, k -1.00, rays 0.087 deg off) from the image centre.
The non-central rig holds the central one it was started from, so corners that fit it worse
than the central model say the fit is in the wrong valley: the same adjustment is run again
from the principal point at the image centre (the other prior a start has: lenses are centred
to a few per cent of the image), and the fit of the lower mean robust cost taken
(:func:`second_start_step`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .fit_steps import AdjustmentStep, Rounds, mean_cost, rounds_step
from .steps import PatternOptions, RimStep, StartStep

__all__ = ["second_start_step"]


def corner_rms(fit: AdjustmentStep) -> float:
    """The corners' RMS reprojection error of an adjustment (px), as the report gives it."""
    r = fit.adj.corner_residuals(fit.sol.x)
    return float(np.sqrt(np.mean(r**2) * 2))


def centred_start(start: StartStep, image_size) -> StartStep:
    """``start`` with its camera's principal point at the image centre."""
    K = np.array(start.camera.K, np.float64)
    K[0, 2], K[1, 2] = (image_size[0] - 1) / 2.0, (image_size[1] - 1) / 2.0
    return dataclasses.replace(start, camera=start.camera.replace(K=K))


def second_start_step(
    rounds: Rounds,
    start: StartStep,
    rim: RimStep,
    model,
    options: PatternOptions,
    greys=(),
    progress=None,
) -> Rounds:
    """The generic start's fit ``rounds`` checked against the central Taylor model it came
    from (module docstring): when its corners' RMS exceeds the Taylor model's, the rounds of
    adjustment again from the principal point at the image centre (:func:`centred_start`),
    and the fit of the lower mean robust cost kept; the report's note says which. A start
    whose ``K`` was given, or a fit no worse than the central model, is returned as it is."""
    taylor = start.taylor
    if taylor is None or options.mirror is not None or options.K is not None:
        return rounds
    rms = corner_rms(rounds.fit)
    if not rms > taylor.rms:
        return rounds
    try:
        alt = rounds_step(
            greys,
            rounds.boards,
            centred_start(start, options.image_size),
            rim,
            model,
            options,
            progress,
        )
    except ValueError:
        alt = None
    alt_rms = math.nan if alt is None else corner_rms(alt.fit)
    best = rounds
    if alt is not None and mean_cost(alt.fit.sol) < mean_cost(rounds.fit.sol):
        best = alt
    taken = best is alt
    note = (
        f"the adjustment from the Taylor model's centre ended at {rms:.3f} px RMS, above the "
        f"central Taylor model's {taylor.rms:.3f} px (a non-central rig fits at least as well "
        f"as the central one it started from): started again from the principal point at the "
        f"image centre, {alt_rms:.3f} px RMS, "
        + (
            "taken"
            if taken
            else "not better: kept; the rays may be off by more than stated: give K (the "
            "camera calibrated alone) or the mirror as a start"
        )
    )
    fit = dataclasses.replace(best.fit, warnings=(*best.fit.warnings, note))
    return dataclasses.replace(best, fit=fit)
