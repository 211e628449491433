"""Choosing one of Chen's postures with the image of a far straight line (paper section 3.2).

The rays ``P_i + k_i V_i`` (reflection point, unit reflected direction; eqs. 6-19) of pixels
along the image of one straight line meet that line, so they lie in one plane
``(P_i + k_i V_i, N) = S`` (eq. 30). For a far line the reflection points do not matter and the
directions alone are coplanar, ``(V_i, N) -> 0`` (eq. 31): ``N`` is the eigenvector of the least
eigenvalue of ``sum_i V_i V_i^T`` and that eigenvalue measures how far the rays are from a
plane. Under the wrong posture the rays of one line are not coplanar. The score of a candidate
is

    score = sum over lines of  lambda_min(sum_i V_i V_i^T) / N_i          (eq. 31)

and the physical candidate with the least score is chosen; ``confidence = 1 - best /
second best`` among the physical candidates.

Without a line the rim alone cannot tell the two physical candidates apart (they are the two
circular sections of the same cone). The fallback then picks the candidate whose camera centre
is nearest to the mirror's lower focus ``(0, 0, -c)`` (where a rig's camera is meant to be), and
says that the choice is ambiguous: on random misalignments this is right only about half of the
time.

The camera's own reflection (:mod:`.reflection`) separates them without lines: under each
physical candidate the outline must be the pixels whose reflected rays pass through one circle
coaxial with the optical axis; the candidates' best fits differ by a displacement of the
predicted outline, measured in units of the outline's own noise (:func:`reflection_costs`).

Every cue gives a cost per candidate in chi-square units above its best candidate; the costs add
up, the least total is chosen, and ``confidence = tanh(gap / 4)`` (for far lines alone exactly the
paper-style ``1 - best / second best``). :class:`Selection` lists every cue's scores.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..raytrace import as_points
from .errors import EstimationError

__all__ = [
    "Selection",
    "validate_far_lines",
    "check_lines_inside_rim",
    "line_score",
    "line_costs",
    "reflection_costs",
    "prediction_limited",
    "ReflectionEvidence",
    "select_candidate",
]

AMBIGUOUS_CONFIDENCE = 0.8  # below this a choice by far lines comes with a warning
# (exact far lines give > 0.99; with rim noise the wrong choices seen had 0.07-0.74)
REFLECTION_SIGMA = 3.0  # a choice that rests on the reflection needs 3 sigma (confidence 0.978)


def validate_far_lines(far_lines):
    """Far lines as a list of ``(N_i, 2)`` float64 pixel arrays (used as given).

    Raises
    ------
    ValueError
        Not a sequence of ``(N_i, 2)`` / ``(N_i, 1, 2)`` arrays, non-finite pixels, or a line
        with fewer than 3 points.
    """
    if far_lines is None:
        return []
    if (
        isinstance(far_lines, np.ndarray)
        and far_lines.dtype != object
        and (far_lines.ndim == 2 or (far_lines.ndim == 3 and far_lines.shape[1] == 1))
    ):
        far_lines = [far_lines]  # one line given as a bare (N, 2) or (N, 1, 2) array
    if isinstance(far_lines, (str, bytes, dict)) or not hasattr(far_lines, "__iter__"):
        raise ValueError(
            f"far_lines must be a sequence of (N_i, 2) pixel arrays, got {type(far_lines).__name__}"
        )
    out = []
    for i, line in enumerate(far_lines):
        arr, _ = as_points(line, f"far_lines[{i}]", 2)
        if not np.isfinite(arr).all():
            raise ValueError(f"far_lines[{i}] has non-finite pixels; drop them")
        if len(arr) < 3:
            raise ValueError(
                f"far_lines[{i}] has {len(arr)} point(s); sample at least 3 pixels "
                f"along the image of each far straight line (more is better)"
            )
        out.append(np.ascontiguousarray(arr))
    return out


def check_lines_inside_rim(distances, tolerance):
    """Raise ``ValueError`` if a far-line pixel lies clearly outside the rim ellipse.

    Parameters
    ----------
    distances : list of (N_i,) ndarray
        Signed distances of each line's pixels to the fitted rim ellipse, px (positive
        outside; :meth:`RimFit.distance` of the undistorted pixels).
    tolerance : float
        Pixels up to this far outside are accepted (the fitted rim is noisy); their rays may
        miss the mirror and are then left out of the score with a warning.
    """
    for i, d in enumerate(distances):
        bad = ~(np.asarray(d) <= tolerance)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"far_lines[{i}] has {int(bad.sum())} pixel(s) outside the mirror "
                f"rim (e.g. index {k}, {float(d[k]):.1f} px outside); give only "
                f"pixels that see the mirror, inside the rim ellipse"
            )


def line_score(camera, line_pixels):
    """``lambda_min(sum_i V_i V_i^T) / N`` of one far line under ``camera`` (eq. 31).

    Returns ``(score, n_used)``; rays that miss the mirror are left out (``n_used < N``), and
    the score is ``inf`` when fewer than 3 rays remain.
    """
    _, V = camera.unproject(line_pixels)
    V = V[np.isfinite(V).all(axis=1)]
    if len(V) < 3:
        return math.inf, len(V)
    # N minimises sum (V_i, N)^2: the eigenvector of the least eigenvalue  (eq. 31)
    lam = np.linalg.eigvalsh(V.T @ V)
    return float(max(lam[0], 0.0)) / len(V), len(V)


@dataclasses.dataclass(frozen=True, eq=False)
class Selection:
    """The choice between the physical postures (section 3.2 and the camera's reflection).

    Attributes
    ----------
    candidates : tuple of Candidate
        With the far-line score of eq. 31 set on the physical ones when lines were given.
    chosen : int
        Index of the chosen candidate.
    confidence : float
        ``tanh((cost_second - cost_best) / 4)`` of the combined costs, in [0, 1]: 1 with one
        physical candidate, 0 without any cue; with far lines alone it equals the paper's
        ``1 - best / second best``.
    ambiguous : bool
        More than one physical candidate and ``confidence < AMBIGUOUS_CONFIDENCE`` (with the
        reflection among the cues: below ``tanh(REFLECTION_SIGMA^2 / 4)``, a 3-sigma gap).
    scores_per_cue : dict
        ``{cue: {candidate index: score}}``: ``"far lines"`` (eq. 31), ``"reflection rms px"``
        (outline residual with the circle fitted), ``"self-reflection px"`` (distance of the
        predicted self-reflection pixel from the detected outline's centre; information only).
    costs_per_cue : dict
        ``{cue: {candidate index: cost}}`` in chi-square units above the best candidate of that
        cue; their sum is the combined cost.
    sigma : dict
        ``{cue: separation of the two best candidates in standard deviations}``.
    warnings : tuple of str
    chosen_by : str
        ``"cues"`` (the scores above) or ``"user"`` (:func:`user_choice`).
    """

    candidates: tuple
    chosen: int
    confidence: float
    ambiguous: bool
    scores_per_cue: dict
    costs_per_cue: dict
    sigma: dict
    warnings: tuple
    chosen_by: str = "cues"


def line_costs(scores):
    """Far-line costs ``4 artanh(1 - best / score)`` (0 for the best; ``{index: score}``)."""
    finite = [v for v in scores.values() if np.isfinite(v)]
    if not finite:
        return {i: 0.0 for i in scores}
    best = min(finite)
    out = {}
    for i, s in scores.items():
        if not np.isfinite(s):
            out[i] = math.inf
        elif s <= best:
            out[i] = 0.0
        else:
            c = 1.0 - best / s if s > 0 else 0.0
            out[i] = math.inf if c >= 1.0 else 4.0 * math.atanh(c)
    return out


def reflection_costs(rms, n_points, sigma_measured):
    """Reflection costs from each candidate's RMS outline residual (px, circle fitted).

    The predictions of two candidates differ by a displacement field along the outline; with
    ``N`` points of noise ``sigma`` its chi-square is ``N_eff (rms_k^2 - rms_best^2) / sigma^2``
    with ``N_eff`` the outline's effective number of independent points (``n_points``: at
    most ``N / 2``, fewer when the residuals are correlated along it) and ``sigma`` the larger
    of the measurement's own scatter (the detection's RMS to its ellipse), the best
    candidate's RMS (model error counts as noise) and 0.05 px.
    """
    finite = [v for v in rms.values() if np.isfinite(v)]
    if not finite:
        return {i: 0.0 for i in rms}
    best = min(finite)
    s = max(float(sigma_measured) if np.isfinite(sigma_measured) else 0.0, best, 0.05)
    n_eff = float(n_points)
    return {
        i: (n_eff * max(v * v - best * best, 0.0) / (s * s) if np.isfinite(v) else math.inf)
        for i, v in rms.items()
    }


def prediction_limited(costs, pred):
    """Costs of a cue whose predictions are uncertain: ``c / (1 + c v / d^2)``.

    A cost ``c`` (chi-square units) measures the gap ``d`` between two candidates'
    predictions (here the pixel where each says the camera sees itself) against the
    measurement's noise, ``c = d^2 / s^2``. When each prediction is itself uncertain (its
    posture is, ``pred[i] = (pixel, variance px^2)``), the gap is known to ``s^2 + v`` with
    ``v`` the two variances' sum, so ``c' = d^2 / (d^2 / c + v)``.
    """
    finite = {i: c for i, c in costs.items() if np.isfinite(c)}
    if not pred or not finite:
        return dict(costs)
    best = min(finite, key=finite.get)
    if best not in pred:
        return dict(costs)
    u0, v0 = pred[best]
    out = {}
    for i, c in costs.items():
        if i == best or i not in pred or not np.isfinite(c) or c <= 0:
            out[i] = c
            continue
        u, v = pred[i]
        d2 = float(np.sum((np.asarray(u) - np.asarray(u0)) ** 2))
        out[i] = c / (1.0 + c * (v + v0) / d2) if d2 > 0 else 0.0
    return out


@dataclasses.dataclass(frozen=True, eq=False)
class ReflectionEvidence:
    """The camera's reflection fitted under each physical candidate, for :func:`select_candidate`
    (:func:`.reflection.fit_circle` under each posture; :func:`.steps.selection_step`).

    Attributes
    ----------
    rms : dict
        ``{candidate index: RMS outline residual, px}`` with the circle fitted.
    n : float
        The outline's effective number of independent points (:func:`reflection_costs`).
    sigma : float
        The measurement's own scatter, px (NaN if unknown).
    self_px : dict
        ``{candidate index: px}``: distance of its predicted self-reflection pixel from the
        detected outline's centre (information only).
    limit : float
        The reflection chooses only if the best RMS is within this, px.
    pred : dict
        ``{candidate index: (self-reflection pixel, its variance px^2)}`` from each posture's
        uncertainty (:func:`prediction_limited`; empty: the predictions taken as exact).
    """

    rms: dict
    n: float
    sigma: float
    self_px: dict = dataclasses.field(default_factory=dict)
    limit: float = math.inf
    pred: dict = dataclasses.field(default_factory=dict)


def _score_reflection(reflection, phys, scores, costs, warnings):
    """The reflection's scores and costs per physical candidate (:func:`select_candidate`),
    written into ``scores``, ``costs`` and ``warnings``: costs only if some posture explains
    the outline within ``reflection.limit``, else a warning that it fits none."""
    rms = {i: float(reflection.rms.get(i, math.inf)) for i in phys}
    if not any(np.isfinite(v) for v in rms.values()):
        return
    scores["reflection rms px"] = rms
    if reflection.self_px:
        scores["self-reflection px"] = dict(reflection.self_px)
    limit = float(reflection.limit)
    if min(rms.values()) <= limit:
        costs["reflection"] = prediction_limited(
            reflection_costs(rms, reflection.n, reflection.sigma), reflection.pred or {}
        )
        return
    # no posture explains it: it cannot tell them apart either
    where = reflection.self_px or {}
    off = (
        f"; the camera sees itself {min(where.values()):.0f} px or more from where the "
        f"postures predict"
        if where
        else ""
    )
    warnings.append(
        f"the camera's reflection fits none of the rim's postures (best RMS "
        f"{min(rms.values()):.2f} px, allowed {limit:.2f}{off}) and was not used to choose: "
        f"check K (the principal point), D and the mirror's a, b and rim_radius"
    )


def _score_far_lines(candidates, phys, cameras, far_lines, warnings):
    """The far-line score of eq. 31 of each physical candidate (summed over the lines):
    ``(candidates with the scores set, {index: score})``; rays that miss the mirror are left
    out with a warning."""
    scored = list(candidates)
    line_s = {}
    for i in phys:
        cam = cameras[i]
        total = 0.0
        for j, line in enumerate(far_lines):
            s, n_used = line_score(cam, line)
            if n_used < len(line):
                warnings.append(
                    f"candidate {i}: {len(line) - n_used} pixel(s) of "
                    f"far_lines[{j}] miss the mirror and were left out"
                )
            total += s
        scored[i] = candidates[i].with_score(total)
        line_s[i] = total
    return scored, line_s


def _least_tilted(candidates, phys):
    """The fallback without any cue nor a nominal camera position: the physical candidate
    whose mirror axis ``R e_z`` is nearest the optical axis (a tie to the lower index)."""
    cos = [float(candidates[i].R[2, 2]) for i in phys]
    near = max(cos) - 1e-12
    return next(i for i, c in zip(phys, cos) if c >= near)


def _nearest_lower_focus(candidates, phys, lower_focus):
    """The fallback without any cue: the physical candidate whose camera centre is nearest the
    lower focus."""
    dist = [
        float(
            np.linalg.norm(
                -candidates[i].R.T @ candidates[i].tvec - np.asarray(lower_focus, np.float64)
            )
        )
        for i in phys
    ]
    # the two physical postures are mirror images, often at equal distances: a tie (within
    # 1e-9 relative) goes to the lower index, so rounding in the rim's last digits cannot
    # flip the fallback between runs or versions
    near = min(dist) * (1.0 + 1e-9) + 1e-12
    return next(i for i, d in zip(phys, dist) if d <= near)


def _cue_warnings(costs, phys, chosen, confidence, ambiguous):
    """Warnings of a choice by cues: barely separated, or a cue preferring another posture."""
    out = []
    if ambiguous:
        cues = " and ".join(costs)
        verb = "separate" if len(costs) > 1 or cues == "far lines" else "separates"
        out.append(
            f"the {cues} barely {verb} the physical postures (confidence "
            f"{confidence:.3f}): the choice may be wrong; give more or longer far "
            f"lines, far from the image centre"
        )
    disagree = [
        cue
        for cue, c in costs.items()
        if min(phys, key=lambda i: (c[i], i)) != chosen and c[chosen] > 4.0
    ]
    for cue in disagree:
        out.append(
            f"the {cue} prefer another posture than the combined choice (by "
            f"{math.sqrt(costs[cue][chosen]):.1f} sigma): check that cue"
        )
    return out


def user_choice(sel, index):
    """``sel`` with candidate ``index`` chosen by the user (by eye, e.g. from the candidates'
    panoramas), recorded as such.

    The cues' scores stay for the record; a warning says what they chose. The confidence
    is the cues' when they chose the same candidate, else 0 (nothing but the user's eye
    supports it); the choice is no longer ambiguous (the user settled it).

    Raises
    ------
    ValueError
        ``index`` is not a candidate, or not a physically possible one.
    """
    n = len(sel.candidates)
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or not 0 <= index < n:
        raise ValueError(f"choose must be a candidate's index, 0 to {n - 1}, got {index!r}")
    index = int(index)
    cand = sel.candidates[index]
    phys = [i for i, c in enumerate(sel.candidates) if c.physical]
    if not cand.physical:
        raise ValueError(
            f"choose: candidate {index} is not physically possible ({'; '.join(cand.reasons)}); "
            f"the physical ones: {', '.join(map(str, phys))}"
        )
    agree = index == sel.chosen
    note = (
        f"candidate {index} chosen by the user; the cues chose "
        + ("it too" if agree else f"{sel.chosen}")
        + (f" (confidence {sel.confidence:.3f}{', ambiguous' if sel.ambiguous else ''})")
    )
    return dataclasses.replace(
        sel,
        chosen=index,
        confidence=sel.confidence if agree else 0.0,
        ambiguous=False,
        warnings=(*sel.warnings, note),
        chosen_by="user",
    )


def select_candidate(
    candidates, cameras, far_lines, lower_focus, reflection=None, focus_name="lower focus"
):
    """Score the physical candidates by every cue given and choose one (section 3.2).

    Parameters
    ----------
    candidates : sequence of Candidate
    cameras : sequence of MisalignedCatadioptricCamera or None
        ``cameras[i]``, the rig under candidate ``i`` (used for far lines; None at the
        candidates that are not physical). Unused without far lines, where it may be None.
    far_lines : list of (N_i, 2) ndarray
        Validated far-line pixels (may be empty).
    lower_focus : (3,) array_like or None
        The nominal camera position (``(0, 0, -c)`` for a hyperboloid,
        :func:`omnicam.mirror.nominal_camera_z`), for the fallback without any cue: the
        candidate whose camera is nearest it; None (a mirror without one): the candidate whose
        mirror axis is least tilted from the optical axis.
    focus_name : str
        What ``lower_focus`` is, as the fallback's warning names it.
    reflection : ReflectionEvidence, optional
        The camera's reflection fitted under each physical candidate; it chooses only if the
        best RMS is within its ``limit``.

    Returns
    -------
    Selection

    Raises
    ------
    EstimationError
        No physically possible candidate.
    """
    warnings = []
    phys = [i for i, c in enumerate(candidates) if c.physical]
    if not phys:
        raise EstimationError(
            "none of the four postures of the rim ellipse is physically possible "
            "(rim behind the camera or mirror seen from behind); check K, D, the "
            "mirror's rim_radius and that the boundary points are on the rim"
        )
    scored = list(candidates)
    scores, costs, sigma = {}, {}, {}
    if far_lines and len(phys) > 1:
        scored, line_s = _score_far_lines(candidates, phys, cameras, far_lines, warnings)
        scores["far lines"] = line_s
        costs["far lines"] = line_costs(line_s)
    if reflection is not None and len(phys) > 1:
        _score_reflection(reflection, phys, scores, costs, warnings)
    if len(phys) == 1:
        return Selection(tuple(scored), phys[0], 1.0, False, scores, costs, sigma, tuple(warnings))
    if not costs:
        if lower_focus is None:
            chosen = _least_tilted(candidates, phys)
            fallback = "the mirror axis least tilted"
        else:
            chosen = _nearest_lower_focus(candidates, phys, lower_focus)
            fallback = f"the camera nearest the {focus_name}"
        warnings.append(
            "no far_lines given and no camera reflection used: the choice between "
            f"the physical postures is ambiguous (fallback: {fallback}, "
            "right about half of the time); give far_lines (pixels "
            "along the image of a far straight line) or an image showing the "
            "camera's reflection"
        )
        return Selection(tuple(scored), chosen, 0.0, True, scores, costs, sigma, tuple(warnings))
    total = {i: sum(c[i] for c in costs.values()) for i in phys}
    order = sorted(phys, key=lambda i: (total[i], i))
    chosen = order[0]
    gap = total[order[1]] - total[chosen]
    confidence = 1.0 if not np.isfinite(gap) else float(math.tanh(gap / 4.0))
    for cue, c in costs.items():
        ranked = sorted(c[i] for i in phys)
        sigma[cue] = math.sqrt(ranked[1] - ranked[0]) if np.isfinite(ranked[1]) else math.inf
    needed = AMBIGUOUS_CONFIDENCE
    if "reflection" in costs:
        needed = max(needed, math.tanh(REFLECTION_SIGMA**2 / 4.0))
    ambiguous = confidence < needed
    warnings += _cue_warnings(costs, phys, chosen, confidence, ambiguous)
    return Selection(
        tuple(scored), chosen, confidence, ambiguous, scores, costs, sigma, tuple(warnings)
    )
