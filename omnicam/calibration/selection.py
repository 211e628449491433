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

The camera's own reflection (:mod:`.lens`) separates them without lines: under each physical
candidate the outline of the dark blob must be the set of pixels whose rays pass at one distance
``rho`` from the camera centre; its score is the RMS of ``(d - rho) / |grad d|`` in px with
``rho`` fitted in closed form. Alone it chooses by the least score; with far lines each kind of
score is divided by its largest value over the physical candidates and the sums are compared.
"""
from __future__ import annotations

import math

import numpy as np

from ..raytrace import as_points

__all__ = ["validate_far_lines", "check_lines_inside_rim", "line_score", "select_candidate"]

AMBIGUOUS_CONFIDENCE = 0.8  # below this a selection by far lines comes with a warning
# (exact far lines give > 0.99; with rim noise the wrong choices seen had 0.07-0.74)
LENS_AMBIGUOUS_CONFIDENCE = 0.5  # below this a selection by the lens alone comes with a warning


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
    if isinstance(far_lines, np.ndarray) and far_lines.dtype != object and (
            far_lines.ndim == 2 or (far_lines.ndim == 3 and far_lines.shape[1] == 1)):
        far_lines = [far_lines]  # one line given as a bare (N, 2) or (N, 1, 2) array
    if isinstance(far_lines, (str, bytes, dict)) or not hasattr(far_lines, "__iter__"):
        raise ValueError(f"far_lines must be a sequence of (N_i, 2) pixel arrays, "
                         f"got {type(far_lines).__name__}")
    out = []
    for i, line in enumerate(far_lines):
        arr, _ = as_points(line, f"far_lines[{i}]", 2)
        if not np.isfinite(arr).all():
            raise ValueError(f"far_lines[{i}] has non-finite pixels; drop them")
        if len(arr) < 3:
            raise ValueError(f"far_lines[{i}] has {len(arr)} point(s); sample at least 3 pixels "
                             f"along the image of each far straight line (more is better)")
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
            raise ValueError(f"far_lines[{i}] has {int(bad.sum())} pixel(s) outside the mirror "
                             f"rim (e.g. index {k}, {float(d[k]):.1f} px outside); give only "
                             f"pixels that see the mirror, inside the rim ellipse")


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


def _confidence(scores):
    """``1 - best / second best`` of an array of scores (1 with one, 0 when undecided)."""
    if len(scores) == 1:
        return 1.0
    order = np.argsort(scores, kind="stable")
    best, second = scores[order[0]], scores[order[1]]
    if not np.isfinite(best):
        return 0.0
    if second > 0:
        return float(1.0 - best / second) if np.isfinite(second) else 1.0
    return 0.0


def select_candidate(candidates, make_camera, far_lines, lower_focus, lens_scores=None):
    """Score the physical candidates and choose one (section 3.2).

    Parameters
    ----------
    candidates : list of Candidate
    make_camera : callable
        ``make_camera(candidate) -> camera`` with ``unproject``.
    far_lines : list of (N_i, 2) ndarray
        Validated far-line pixels (may be empty).
    lower_focus : (3,) array_like
        ``(0, 0, -c)``, for the fallback without lines.
    lens_scores : dict, optional
        ``{index: RMS outline residual (px)}`` of the camera's reflection for the physical
        candidates (:func:`.lens.outline_score`); used alone without far lines, and together
        with them otherwise.

    Returns
    -------
    candidates : list of Candidate
        With scores set (NaN for non-physical ones; without lines, NaN for all).
    chosen : int
        Index of the chosen candidate.
    confidence : float
        ``1 - best / second best`` among physical candidates (1 with one physical candidate,
        0 without far lines and lens; with both, of the summed normalised scores).
    warnings : list of str
    """
    warnings = []
    phys = [i for i, c in enumerate(candidates) if c.physical]
    if not phys:
        raise ValueError("none of the four postures of the rim ellipse is physically possible "
                         "(rim behind the camera or mirror seen from behind); check K, D, the "
                         "mirror's rim_radius and that the boundary points are on the rim")
    use_lens = lens_scores is not None and len(phys) > 1 and \
        np.isfinite([lens_scores.get(i, math.inf) for i in phys]).any()
    lens = np.array([lens_scores.get(i, math.inf) for i in phys]) if use_lens else None
    if not far_lines and use_lens:
        chosen = phys[int(np.argmin(lens))]
        confidence = _confidence(lens)
        if confidence < LENS_AMBIGUOUS_CONFIDENCE:
            warnings.append(f"no far_lines given and the camera's reflection barely separates "
                            f"the physical postures (confidence {confidence:.3f}): the choice "
                            f"may be wrong; give far_lines (pixels along the image of a far "
                            f"straight line)")
        return list(candidates), chosen, confidence, warnings
    if not far_lines:
        dist = []
        for i in phys:
            c = candidates[i]
            C = -c.R.T @ c.tvec
            dist.append(float(np.linalg.norm(C - np.asarray(lower_focus, np.float64))))
        chosen = phys[int(np.argmin(dist))]
        if len(phys) > 1:
            warnings.append("no far_lines given: the choice between the physical postures is "
                            "ambiguous (fallback: the camera nearest the lower focus, right about "
                            "half of the time); give far_lines (pixels along the image of a far "
                            "straight line) to select by eq. 31")
            confidence = 0.0
        else:
            confidence = 1.0
        return list(candidates), chosen, confidence, warnings

    scored = list(candidates)
    for i in phys:
        cam = make_camera(candidates[i])
        total = 0.0
        for j, line in enumerate(far_lines):
            s, n_used = line_score(cam, line)
            if n_used < len(line):
                warnings.append(f"candidate {i}: {len(line) - n_used} pixel(s) of far_lines[{j}] "
                                f"miss the mirror and were left out")
            total += s
        scored[i] = candidates[i].with_score(total)
    scores = np.array([scored[i].score for i in phys])
    if use_lens and np.isfinite(scores).any():
        def normalised(v):
            top = np.max(v[np.isfinite(v)])
            return np.where(np.isfinite(v), v / top if top > 0 else 0.0, 2.0)
        scores = normalised(scores) + normalised(lens)
    order = np.argsort(scores, kind="stable")
    chosen = phys[int(order[0])]
    confidence = _confidence(scores)
    return scored, chosen, confidence, warnings
