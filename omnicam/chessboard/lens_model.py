"""The lens model of a chessboard calibration: which of OpenCV's distortion coefficients the
views determine, and ``dist_model="auto"``, the model chosen by held-out views (beyond the
paper).

The camera sees the mirror through its lens, modelled by OpenCV's distortion ``D = (k1, k2, p1,
p2, k3, k4, k5, k6)`` (:data:`.adjustment.DIST_MODELS` names the subsets estimated). A model
with more coefficients always fits its own views better; whether it describes the lens better
is what views it did not fit say. ``"auto"`` fits each of :data:`AUTO_CANDIDATES` (simplest
first) with its k-fold held-out check (:mod:`.heldout`) and keeps the simplest whose median
held-out corner RMS is within :data:`AUTO_TOLERANCE` of the best (:func:`choose`): a model
is only taken for a lens when it predicts unseen views better by more than the folds'
scatter. Each coefficient's standard deviation then says what these views determine
(:func:`coefficient_lines`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .adjustment import D_NAMES, DIST_MODELS

__all__ = [
    "AUTO_CANDIDATES",
    "AUTO_FOLDS",
    "AUTO_TOLERANCE",
    "LensChoice",
    "choose",
    "coefficient_lines",
]

#: The models ``dist_model="auto"`` compares, simplest first: the default's radial ``k1, k2``,
#: OpenCV's 5 coefficients, and its rational model (a wide-angle lens).
AUTO_CANDIDATES = ("k1k2", "k1k2p1p2k3", "rational")
#: ``"auto"`` keeps the simplest model whose median held-out RMS is at most ``1 +`` this
#: times the best's. Models that fit the lens alike differed by 2 % at most on the renders of
#: ``tests/test_lens_model.py`` and the wide-angle k1k2 case of
#: ``benchmarks/bench_chessboard_hostile.py`` (the richer one worse); behind the rational
#: lens ``k1k2p1p2k3``, whose rays were 0.6-1.0 deg off, came within 4.5-8 % of the rational
#: model over three draws of noise: a held-out view's own board pose absorbs most of a wrong
#: lens model's error, so the margin is thin either way.
AUTO_TOLERANCE = 0.03
#: Folds of ``"auto"``'s held-out check when ``heldout`` is not given (0).
AUTO_FOLDS = 3


@dataclasses.dataclass(frozen=True)
class LensChoice:
    """What ``dist_model="auto"`` compared and took.

    Attributes
    ----------
    model : str
        The model taken (a key of :data:`.adjustment.DIST_MODELS`).
    heldout : dict
        ``{model: median held-out corner RMS, px}`` of every candidate (inf: its folds could
        not be calibrated).
    folds : int
    """

    model: str
    heldout: dict
    folds: int

    def summary(self) -> str:
        """One line: the model taken, the rule and every candidate's held-out figure."""
        best = min(self.heldout.values())
        figures = ", ".join(f"{m} {v:.3f} px" for m, v in self.heldout.items())
        return (
            f"lens model {self.model}, chosen by held-out views ({self.folds}-fold median "
            f"corner RMS: {figures}; the simplest within {100 * AUTO_TOLERANCE:.0f} % of the "
            f"best, {best:.3f} px)"
        )


def choose(heldout: dict) -> str:
    """The simplest model (the first of ``heldout``'s keys, in order of :data:`AUTO_CANDIDATES`)
    whose median held-out RMS is at most ``1 + AUTO_TOLERANCE`` times the best's.

    Raises ``ValueError`` when no candidate predicts anything (every figure infinite or NaN).
    """
    finite = {m: v for m, v in heldout.items() if math.isfinite(v)}
    if not finite:
        raise ValueError(
            f"no lens model could be compared on held-out views ({', '.join(heldout)}): "
            f"give dist_model"
        )
    best = min(finite.values())
    return next(m for m, v in finite.items() if v <= (1.0 + AUTO_TOLERANCE) * best)


def coefficient_lines(D, std: dict, dist_model: str) -> list[str]:
    """One line per coefficient of ``D`` estimated by ``dist_model``: its value, its standard
    deviation (the report's ``std``) and, where that exceeds the value, that these views do
    not determine it (the rays may still be right: the coefficients trade against each other
    and against ``K``, the report's ``ray_std_deg`` says what the rays keep)."""
    D = np.ravel(np.asarray(D if D is not None else [], np.float64))
    lines = []
    for i in DIST_MODELS[dist_model]:
        name = D_NAMES[i]
        value = float(D[i]) if i < D.size else 0.0
        s = float(std.get(name, math.nan))
        text = f"{name} {value:+.6g} (std {s:.2g})"
        if not s <= abs(value):
            text += ": not determined by these views"
        lines.append(text)
    return lines
