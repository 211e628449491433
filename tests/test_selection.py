"""Selection of the posture with far lines (paper section 3.2, eq. 31)."""

import dataclasses
import math

import numpy as np
import pytest
from conftest import RANDOM_RIGS as RIGS
from conftest import candidates_of

from omnicam import synthetic
from omnicam.calibration import EstimationError, selection
from omnicam.calibration.steps import candidate_cameras


def _cameras(cam, cands):
    """The rig under each physical candidate, as calibrate's selection step builds them."""
    return candidate_cameras(cands, cam.K, cam.D, cam.mirror)


def _select(cam, lines):
    cands = candidates_of(cam)
    sel = selection.select_candidate(cands, _cameras(cam, cands), lines, (0.0, 0.0, -cam.mirror.c))
    return list(sel.candidates), sel.chosen, sel.confidence, list(sel.warnings)


def test_far_lines_select_the_true_candidate_on_100_random_rigs():
    rng = np.random.default_rng(7)
    right, confidences = 0, []
    for cam in RIGS:
        cands, chosen, conf, warnings = _select(cam, synthetic.far_line_pixels(cam, rng=rng))
        right += np.linalg.norm(cands[chosen].tvec - cam.tvec) < 1e-6
        confidences.append(conf)
        assert not warnings
    assert right == len(RIGS)
    assert min(confidences) > 0.9


def test_scores_only_for_physical_candidates():
    cam = RIGS[3]
    cands, chosen, conf, _ = _select(cam, synthetic.far_line_pixels(cam, rng=1))
    for c in cands:
        assert np.isfinite(c.score) == c.physical
    phys = sorted(c.score for c in cands if c.physical)
    assert math.isclose(conf, 1.0 - phys[0] / phys[1])


def test_true_posture_makes_far_line_rays_nearly_coplanar():
    cam = RIGS[5]
    lines = synthetic.far_line_pixels(cam, n_lines=1, rng=2)
    s_true, n = selection.line_score(cam, lines[0])
    assert n == len(lines[0])
    cands = [c for c in candidates_of(cam) if c.physical]
    wrong = max(cands, key=lambda c: np.linalg.norm(c.tvec - cam.tvec))
    s_wrong, _ = selection.line_score(cam.replace(rvec=wrong.rvec, tvec=wrong.tvec), lines[0])
    assert s_true < 1e-3 * s_wrong


def test_without_lines_the_fallback_warns_that_the_choice_is_ambiguous():
    cam = RIGS[0]
    cands, chosen, conf, warnings = _select(cam, [])
    assert cands[chosen].physical and conf == 0.0
    assert len(warnings) == 1 and "ambiguous" in warnings[0]
    # the fallback: the camera nearest the lower focus
    dist = {
        i: np.linalg.norm(-c.R.T @ c.tvec - [0, 0, -cam.mirror.c])
        for i, c in enumerate(cands)
        if c.physical
    }
    assert chosen == min(dist, key=dist.get)


def test_far_line_with_two_points_raises():
    with pytest.raises(ValueError, match="at least 3 pixels"):
        selection.validate_far_lines([np.zeros((2, 2))])


def test_far_lines_accept_opencv_shapes_and_reject_bad_ones():
    lines = selection.validate_far_lines(
        [np.zeros((4, 1, 2), np.float32), [[0, 0], [1, 1], [2, 2]]]
    )
    assert [x.shape for x in lines] == [(4, 2), (3, 2)]
    assert selection.validate_far_lines(None) == []
    # a bare array is one line; an (L, N, 2) array is L lines
    assert [x.shape for x in selection.validate_far_lines(np.zeros((5, 2)))] == [(5, 2)]
    assert [x.shape for x in selection.validate_far_lines(np.zeros((5, 1, 2)))] == [(5, 2)]
    assert [x.shape for x in selection.validate_far_lines(np.zeros((2, 4, 2)))] == [(4, 2)] * 2
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        selection.validate_far_lines([np.zeros((4, 3))])
    with pytest.raises(ValueError, match="non-finite"):
        selection.validate_far_lines([np.array([[0.0, 0.0], [1.0, np.nan], [2.0, 2.0]])])


def test_far_line_outside_the_rim_raises():
    selection.check_lines_inside_rim([np.array([-5.0, -0.1, 1.9])], 2.0)
    with pytest.raises(ValueError, match="outside the mirror rim"):
        selection.check_lines_inside_rim(
            [np.array([-5.0, -0.1, 1.9]), np.array([-3.0, 2.5, -1.0])], 2.0
        )
    with pytest.raises(ValueError, match="outside the mirror rim"):
        selection.check_lines_inside_rim([np.array([-5.0, np.nan, -1.0])], 2.0)


def test_no_physical_candidate_raises():
    cam = RIGS[0]
    cands = [c.__class__(**{**c.__dict__, "physical": False}) for c in candidates_of(cam)]
    with pytest.raises(EstimationError, match="physically possible"):
        selection.select_candidate(cands, None, [], (0, 0, -cam.mirror.c))


def test_single_physical_candidate_has_full_confidence():
    cam = synthetic.misaligned_rig()
    cands = candidates_of(cam)
    first = next(i for i, c in enumerate(cands) if c.physical)
    cands = [
        c if i == first else c.__class__(**{**c.__dict__, "physical": False})
        for i, c in enumerate(cands)
    ]
    sel = selection.select_candidate(cands, None, [], (0, 0, -cam.mirror.c))
    assert sel.chosen == first and sel.confidence == 1.0 and not sel.warnings
    assert not sel.ambiguous


def test_reflection_costs_are_the_outline_separation_in_sigma():
    # two candidates 0.1 px and 0.3 px RMS, 100 effective points of 0.1 px scatter:
    # 100 (0.09 - 0.01) / 0.01 = 800 chi-square units, about 28 sigma
    c = selection.reflection_costs({0: 0.1, 1: 0.3}, 100, 0.1)
    assert c[0] == 0.0 and c[1] == pytest.approx(800.0)
    # the best candidate's own misfit counts as noise: 1.0 vs 1.2 px over 200 points
    c = selection.reflection_costs({0: 1.0, 1: 1.2}, 100, 0.1)
    assert c[1] == pytest.approx(100 * 0.44)


def test_reflection_chooses_without_far_lines_and_adds_to_the_far_lines():
    cam = RIGS[5]
    cands = candidates_of(cam)
    phys = [i for i, c in enumerate(cands) if c.physical]
    true = min(phys, key=lambda i: np.linalg.norm(cands[i].tvec - cam.tvec))
    other = next(i for i in phys if i != true)
    seen = selection.ReflectionEvidence(rms={true: 0.1, other: 0.3}, n=100, sigma=0.1)
    sel = selection.select_candidate(cands, None, [], (0, 0, -cam.mirror.c), seen)
    assert sel.chosen == true and sel.confidence > 0.99 and not sel.ambiguous
    assert sel.sigma["reflection"] == pytest.approx(math.sqrt(800.0))
    assert sel.scores_per_cue["reflection rms px"] == {true: 0.1, other: 0.3}
    # barely separated (1.5 sigma): chosen, flagged ambiguous, with a warning
    barely = {true: 0.1, other: 0.1 * math.sqrt(1 + 2.25 / 100)}
    seen = selection.ReflectionEvidence(rms=barely, n=100, sigma=0.1)
    sel = selection.select_candidate(cands, None, [], (0, 0, -cam.mirror.c), seen)
    assert sel.chosen == true and sel.ambiguous and sel.warnings
    assert sel.sigma["reflection"] == pytest.approx(1.5)

    # with far lines both cues' costs add up; each cue's scores are listed
    lines = synthetic.far_line_pixels(cam, rng=2)
    sel = selection.select_candidate(
        cands, _cameras(cam, cands), lines, (0, 0, -cam.mirror.c), seen
    )
    assert sel.chosen == true and sel.confidence > 0.9 and not sel.ambiguous
    assert set(sel.costs_per_cue) == {"far lines", "reflection"}
    assert all(np.isfinite(sel.candidates[i].score) for i in phys)  # eq. 31 scores kept


def test_far_lines_alone_give_the_papers_confidence():
    cam = RIGS[7]
    cands, chosen, conf, _ = _select(cam, synthetic.far_line_pixels(cam, n_lines=1, rng=3))
    phys = sorted(c.score for c in cands if c.physical)
    assert conf == pytest.approx(1.0 - phys[0] / phys[1], abs=1e-9)


def test_the_fallback_breaks_a_tie_by_the_lower_index():
    # mirror-image postures at the same distance from the lower focus (to the last digits):
    # without far lines or a reflection the first one is chosen, whatever the rounding
    cam = RIGS[5]
    cands = list(candidates_of(cam))
    phys = [i for i, c in enumerate(cands) if c.physical]
    for eps in (0.0, 1e-13, -1e-13):
        twin = dataclasses.replace(cands[phys[0]], tvec=cands[phys[0]].tvec * (1 + eps))
        moved = [twin if i == phys[1] else c for i, c in enumerate(cands)]
        sel = selection.select_candidate(moved, None, [], (0, 0, -cam.mirror.c), None)
        assert sel.chosen == phys[0] and sel.ambiguous


def test_uncertain_predictions_limit_the_reflections_cost():
    # a gap of 5 px between the two predicted self-reflection pixels measured at 10 sigma
    # (cost 100): exact predictions keep it; predictions each uncertain by 0.35 px (variances
    # summing to 0.25 px^2) halve it, c / (1 + c v / d^2); a gap the postures' uncertainty
    # covers costs (almost) nothing
    costs = {0: 0.0, 2: 100.0}
    exact = {0: ((100.0, 100.0), 0.0), 2: ((105.0, 100.0), 0.0)}
    assert selection.prediction_limited(costs, exact) == costs
    unsure = {0: ((100.0, 100.0), 0.125), 2: ((105.0, 100.0), 0.125)}
    assert selection.prediction_limited(costs, unsure)[2] == pytest.approx(50.0)
    covered = {0: ((100.0, 100.0), 12.5), 2: ((105.0, 100.0), 12.5)}
    assert selection.prediction_limited(costs, covered)[2] < 1.0
    assert selection.prediction_limited(costs, {}) == costs
