"""The named steps of calibrate() (calibration.steps), each called directly: its typed result on
data made by the camera model, and its failure modes (the ValueError or EstimationError that says
what is wrong)."""

import dataclasses
import math

import cv2
import numpy as np
import pytest
from conftest import RANDOM_RIGS, RIGS, white_holder_render

from omnicam import synthetic
from omnicam.calibration import EstimationError, reflection, steps
from omnicam.calibration.refine import RefineResult, Uncertainty
from omnicam.calibration.rim import RimFit
from omnicam.calibration.selection import Selection
from omnicam.raytrace import normalize

CAM = RANDOM_RIGS[1]  # 1.5 mm off the axis: the two physical postures are 1.5 deg apart
R_C, Z_C = 9.0, 12.0  # a circle of the camera's front, as tests/barrel.py's


def pinhole_rim(cam, n):
    """The rim circle imaged by the pinhole ``K`` alone (no distortion): undistorted pixels."""
    X = cam.mirror.rim_points(n) @ cam.R.T + cam.tvec
    return (X[:, :2] / X[:, 2:]) @ cam.K[:2, :2].T + cam.K[:2, 2]


def the_truth(cands, cam=CAM):
    """Index of the candidate at the true posture."""
    return min(range(len(cands.all)), key=lambda i: np.linalg.norm(cands.all[i].tvec - cam.tvec))


@pytest.fixture(scope="module")
def exact():
    """The steps up to the candidates on the exact rim of ``CAM``, and exact far lines."""
    rim = steps.rim_step(CAM.K, None, boundary_points=CAM.rim_image_points(360))
    cands = steps.candidates_step(rim, CAM.K, CAM.mirror)
    lines = synthetic.far_line_pixels(CAM, rng=1)
    no_cue = steps.reflection_step(None, None, rim.fit, CAM.K, None)
    return {"rim": rim, "cands": cands, "lines": lines, "no_cue": no_cue}


def outline_cue(exact, z=None, r=None):
    out, _ = reflection.outline_pixels(CAM, R_C, Z_C, 64)
    cue = steps.reflection_step(out, None, exact["rim"].fit, CAM.K, None, r, z)
    return out, cue


# -- as_pixels, normalize --------------------------------------------------------------------------
def test_as_pixels_takes_both_opencv_layouts_and_lists():
    raw = np.arange(10, dtype=np.float32).reshape(5, 1, 2)
    got = steps.as_pixels(raw, "pts")
    assert got.shape == (5, 2) and got.dtype == np.float64
    np.testing.assert_array_equal(got, raw.reshape(5, 2))
    np.testing.assert_array_equal(
        steps.as_pixels([[1, 2], [3, 4]], "pts"), [[1.0, 2.0], [3.0, 4.0]]
    )


@pytest.mark.parametrize(
    "bad, match",
    [
        (
            np.zeros((4, 3)),
            r"pts must be an \(N, 2\) or \(N, 1, 2\) array of pixels, got shape \(4, 3\)",
        ),
        (np.zeros((4, 2, 1)), r"got shape \(4, 2, 1\)"),
        (np.zeros(6), r"got shape \(6,\)"),
        (
            [["a", "b"]],
            r"pts must be an \(N, 2\) or \(N, 1, 2\) array of pixels \(real numbers\), "
            r"got \[\['a', 'b'\]\]$",
        ),
        (np.ones((4, 2), complex), r"pts must be .* got complex numbers \(dtype complex128"),
        ([[1, 2], [3]], "pts must be"),
    ],
    ids=["3 columns", "(N, 2, 1)", "flat", "strings", "complex", "ragged"],
)
def test_as_pixels_names_the_argument_of_a_bad_array(bad, match):
    with pytest.raises(ValueError, match=match):
        steps.as_pixels(bad, "pts")


def test_normalize_applies_the_inverse_of_K_with_its_skew():
    cam = RIGS["skew"]
    px = np.random.default_rng(0).uniform(0, 500, (50, 2))
    ref = np.linalg.solve(cam.K, np.concatenate([px, np.ones((50, 1))], 1).T).T
    np.testing.assert_allclose(normalize(px, cam.K, None), ref[:, :2] / ref[:, 2:], atol=1e-15)


def test_normalize_undoes_opencvs_distortion():
    cam = RIGS["distorted"]
    xn = np.random.default_rng(1).uniform(-0.5, 0.5, (50, 2))
    px, _ = cv2.projectPoints(
        np.concatenate([xn, np.ones((50, 1))], 1).reshape(-1, 1, 3),
        np.zeros(3),
        np.zeros(3),
        cam.K,
        cam.D,
    )
    np.testing.assert_allclose(normalize(px.reshape(-1, 2), cam.K, cam.D), xn, atol=1e-12)


# -- 1. rim_step -----------------------------------------------------------------------------------
def test_rim_step_fits_boundary_points():
    rim = steps.rim_step(CAM.K, None, boundary_points=CAM.rim_image_points(360))
    assert isinstance(rim, steps.RimStep) and isinstance(rim.fit, RimFit)
    assert rim.detected is None and rim.warnings == ()
    assert rim.fit.rms < 1e-9
    np.testing.assert_allclose(rim.points, CAM.rim_image_points(360), rtol=0, atol=1e-9)
    np.testing.assert_array_equal(rim.seen, CAM.rim_image_points(360))


def test_rim_step_with_D_fits_the_undistorted_rim_and_keeps_the_seen_points():
    cam = RIGS["distorted"]
    seen = cam.rim_image_points(360)
    rim = steps.rim_step(cam.K, cam.D, boundary_points=seen.reshape(-1, 1, 2).astype(np.float32))
    assert rim.fit.rms < 1e-4  # float32 input: 1e-5 px of rounding
    np.testing.assert_allclose(rim.points, pinhole_rim(cam, 360), atol=1e-3)
    assert np.abs(rim.points - seen).max() > 1.0  # the distortion really moved them
    np.testing.assert_allclose(rim.seen, seen, atol=1e-4)


def test_rim_step_drops_outliers_from_the_seen_points():
    pts = CAM.rim_image_points(360)
    pts[::40] += 15.0  # 9 points far off the rim
    rim = steps.rim_step(CAM.K, None, boundary_points=pts)
    assert len(rim.seen) == 351 and rim.fit.rms < 1e-6
    np.testing.assert_array_equal(rim.seen, np.delete(pts, np.s_[::40], axis=0))


def test_rim_step_warns_of_a_poor_fit_and_of_an_unused_image():
    noisy = CAM.rim_image_points(200) + np.random.default_rng(0).normal(size=(200, 2)) * 2.0
    rim = steps.rim_step(CAM.K, None, boundary_points=noisy)
    assert rim.fit.rms > 1.0
    assert rim.warnings == (
        f"the rim fit is poor (RMS {rim.fit.rms:.2f} px): check the boundary points (the posture "
        f"error grows by about 1 deg per px of rim noise)",
    )
    image = np.zeros((500, 500), np.uint8)
    rim = steps.rim_step(CAM.K, None, image=image, boundary_points=CAM.rim_image_points(90))
    assert rim.warnings == (
        "both image and boundary_points given: the rim was fitted to the boundary points, the "
        "image only gave the size",
    )


def test_rim_step_in_an_image_takes_the_rim_the_mirror_predicts_not_the_holders_edge():
    img, cam = white_holder_render()
    truth = cam.rim_image_points(720)
    rim = steps.rim_step(cam.K, None, image=img, mirror=cam.mirror)
    assert rim.detected is rim.fit and len(rim.seen) > 500
    assert np.abs(rim.fit.distance(truth)).max() < 0.1  # px
    hinted = steps.rim_step(cam.K, None, image=img, hint=(200, 200, 130))
    assert np.abs(hinted.fit.distance(truth)).max() < 0.1
    # without the mirror's prediction or a hint the bright holder's outer edge wins
    blind = steps.rim_step(cam.K, None, image=img)
    assert np.abs(blind.fit.distance(truth)).max() > 20.0


@pytest.mark.parametrize(
    "points, match",
    [
        (np.zeros((5, 2)), r"boundary_points has 5 point\(s\); give at least 6 points"),
        (np.full((8, 2), np.nan), "boundary_points has non-finite values; drop them"),
        (np.zeros((8, 3)), r"boundary_points must be an \(N, 2\) or \(N, 1, 2\) array"),
    ],
    ids=["5 points", "NaN", "3 columns"],
)
def test_rim_step_refuses_boundary_points_that_cannot_give_a_rim(points, match):
    with pytest.raises(ValueError, match=match):
        steps.rim_step(CAM.K, None, boundary_points=points)


def test_rim_step_raises_estimation_error_when_valid_input_has_no_ellipse():
    line = np.stack([np.arange(20.0), 2 * np.arange(20.0)], axis=1)
    with pytest.raises(EstimationError, match="no ellipse found among the boundary points"):
        steps.rim_step(CAM.K, None, boundary_points=line)
    with pytest.raises(EstimationError, match="the image is uniform"):
        steps.rim_step(CAM.K, None, image=np.full((200, 200), 128, np.uint8))


@pytest.mark.parametrize(
    "image, hint, match",
    [
        (np.zeros((50, 50, 2)), None, r"image must be grey \(H, W\) or BGR/BGRA"),
        (np.zeros((50, 50)), (1, 2), r"hint must be \(cx, cy, r\)"),
        (np.zeros((50, 50)), (25, 25, -3), "hint radius must be positive"),
        (np.zeros((50, 50)), (80, 25, 10), r"hint centre \(80, 25\) is outside the 50x50 image"),
    ],
    ids=["2 channels", "short hint", "negative radius", "hint outside"],
)
def test_rim_step_refuses_a_bad_image_or_hint_before_searching(image, hint, match):
    with pytest.raises(ValueError, match=match):
        steps.rim_step(CAM.K, None, image=image, hint=hint)


# -- 2. reflection_step ----------------------------------------------------------------------------
def test_reflection_step_takes_outline_pixels(exact):
    out, cue = outline_cue(exact, z=Z_C)
    assert isinstance(cue, steps.ReflectionCue) and cue.used
    np.testing.assert_array_equal(cue.points, out)
    np.testing.assert_allclose(cue.normalized, normalize(out, CAM.K, None), atol=0)
    assert cue.fit is None and math.isnan(cue.sigma)
    assert (cue.r, cue.z) == (None, Z_C)
    assert cue.note == "used: 64 outline points"


@pytest.mark.parametrize(
    "lens, image, note",
    [
        (None, None, "not used (lens=None)"),
        (False, None, "not used (lens=None)"),
        ("auto", None, "not used: no image (give lens=outline pixels to use it)"),
        ("auto", np.full((300, 300), 128, np.uint8), "not used: no camera reflection found"),
    ],
    ids=["None", "False", "auto without image", "auto, nothing to find"],
)
def test_reflection_step_says_why_the_cue_is_not_used(exact, lens, image, note):
    cue = steps.reflection_step(lens, image, exact["rim"].fit, CAM.K, None)
    assert not cue.used and cue.points is None and cue.normalized is None
    assert cue.note.startswith(note)


@pytest.mark.parametrize(
    "lens, r, z, match",
    [
        ("manual", None, None, "lens must be 'auto', None, False or an \\(M, 2\\) array"),
        (np.zeros((5, 2)), None, None, r"lens has 5 point\(s\) or non-finite values"),
        (np.full((9, 2), np.nan), None, None, r"lens has 9 point\(s\) or non-finite values"),
        (np.zeros((9, 3)), None, None, r"lens must be an \(N, 2\) or \(N, 1, 2\) array"),
        (None, -1.0, None, r"lens_r must be a finite number \(lens_r > 0\) or None, got -1.0"),
        (None, 0.0, None, "lens_r must be a finite number"),
        (None, None, math.nan, "lens_z must be a finite number"),
        (None, None, math.inf, "lens_z must be a finite number"),
    ],
    ids=["unknown word", "5 points", "NaN", "3 columns", "r < 0", "r = 0", "z NaN", "z inf"],
)
def test_reflection_step_refuses_a_bad_lens_or_circle(exact, lens, r, z, match):
    with pytest.raises(ValueError, match=match):
        steps.reflection_step(lens, None, exact["rim"].fit, CAM.K, None, r, z)


def test_reflection_step_accepts_a_circle_behind_the_camera_centre(exact):
    _, cue = outline_cue(exact, z=-5.0)  # lens_z may be negative: only lens_r must be > 0
    assert cue.used and cue.z == -5.0


# -- 3. candidates_step ----------------------------------------------------------------------------
def test_candidates_step_gives_chens_four_postures_two_physical(exact):
    cands = exact["cands"]
    assert isinstance(cands, steps.Candidates)
    assert len(cands.all) == 4 and len(cands.physical) == 2
    assert cands.physical == tuple(i for i, c in enumerate(cands.all) if c.physical)
    i = the_truth(cands)
    assert i in cands.physical
    assert np.linalg.norm(cands.all[i].tvec - CAM.tvec) < 1e-9
    np.testing.assert_allclose(cands.all[i].rvec, CAM.rvec, atol=1e-9)


# -- 4. selection_step -----------------------------------------------------------------------------
def test_selection_step_chooses_the_truth_by_far_lines(exact):
    args = (exact["cands"], exact["no_cue"], exact["lines"], CAM.mirror, CAM.K, None)
    sel, circles = steps.selection_step(*args, exact["rim"])
    assert isinstance(sel, Selection) and circles == {}
    assert sel.chosen == the_truth(exact["cands"]) and not sel.ambiguous
    assert sel.confidence > 0.99 and sel.warnings == ()
    assert set(sel.costs_per_cue) == {"far lines"}


def test_selection_step_chooses_the_truth_by_the_reflection_and_fits_its_circles(exact):
    _, cue = outline_cue(exact, z=Z_C)
    sel, circles = steps.selection_step(
        exact["cands"], cue, [], CAM.mirror, CAM.K, None, exact["rim"]
    )
    true = the_truth(exact["cands"])
    assert sel.chosen == true and not sel.ambiguous
    assert set(circles) == set(exact["cands"].physical)
    assert circles[true].rms < 1e-9 and circles[true].r == pytest.approx(R_C, abs=1e-9)
    other = next(i for i in circles if i != true)
    assert circles[other].rms > 0.5  # px: the other posture cannot explain the outline
    assert sel.scores_per_cue["reflection rms px"] == {i: c.rms for i, c in circles.items()}


def test_selection_step_without_cues_warns_that_the_choice_is_ambiguous(exact):
    args = (exact["cands"], exact["no_cue"], [], CAM.mirror, CAM.K, None)
    sel, circles = steps.selection_step(*args)
    assert circles == {} and sel.confidence == 0.0 and sel.ambiguous
    assert len(sel.warnings) == 1 and "ambiguous" in sel.warnings[0]


# -- 5. refinement_step ----------------------------------------------------------------------------
def refinement(exact, lines_xn=(), cue=None, circle=None, refine=True, rim=None):
    cand = exact["cands"].all[the_truth(exact["cands"])]
    cue = exact["no_cue"] if cue is None else cue
    rim = exact["rim"] if rim is None else rim
    return steps.refinement_step(CAM.K, CAM.mirror, cand, rim, list(lines_xn), cue, circle, refine)


def test_refinement_step_on_the_rim_alone_keeps_the_exact_posture(exact):
    ref = refinement(exact)
    assert isinstance(ref, steps.Refinement) and isinstance(ref.result, RefineResult)
    assert np.abs(ref.tvec - CAM.tvec).max() < 1e-9
    np.testing.assert_allclose(ref.rvec, CAM.rvec, atol=1e-12)
    assert ref.accepted_cues == ref.rejected_cues == ref.skipped_cues == ()
    assert ref.circle is None and isinstance(ref.uncertainty, Uncertainty)
    assert ref.uncertainty.axis_std_deg < 1e-6  # exact data: no floor here


def test_refinement_step_without_refining_keeps_the_candidate(exact):
    xn = [normalize(line, CAM.K, None) for line in exact["lines"]]
    ref = refinement(exact, xn, refine=False)
    cand = exact["cands"].all[the_truth(exact["cands"])]
    assert ref.result is None and ref.accepted_cues == ref.rejected_cues == ()
    np.testing.assert_array_equal(ref.rvec, cand.rvec)
    np.testing.assert_array_equal(ref.tvec, cand.tvec)
    assert np.isfinite(ref.uncertainty.axis_std_deg)


def test_refinement_step_lets_far_lines_that_agree_with_the_rim_join(exact):
    noisy_pts = CAM.rim_image_points(360) + np.random.default_rng(3).normal(size=(360, 2)) * 0.1
    noisy = steps.rim_step(CAM.K, None, boundary_points=noisy_pts)
    xn = [normalize(line, CAM.K, None) for line in exact["lines"]]
    ref = refinement(exact, xn, rim=noisy)
    assert ref.accepted_cues == ("far lines",) and ref.rejected_cues == ()
    assert ref.result.line_rms < 3.0 and len(ref.result.lines) == 3


def test_refinement_step_refines_with_a_known_z_reflection(exact):
    _, cue = outline_cue(exact, z=Z_C)
    _, circles = steps.selection_step(
        exact["cands"], cue, [], CAM.mirror, CAM.K, None, exact["rim"]
    )
    ref = refinement(exact, cue=cue, circle=circles[the_truth(exact["cands"])])
    assert ref.accepted_cues == ("reflection",) and ref.rejected_cues == ()
    assert ref.circle.r == pytest.approx(R_C, abs=1e-9) and ref.circle.z == Z_C
    assert np.abs(ref.tvec - CAM.tvec).max() < 1e-9


def test_refinement_step_skips_a_reflection_whose_r_and_z_are_both_unknown(exact):
    _, cue = outline_cue(exact)
    _, circles = steps.selection_step(
        exact["cands"], cue, [], CAM.mirror, CAM.K, None, exact["rim"]
    )
    ref = refinement(exact, cue=cue, circle=circles[the_truth(exact["cands"])])
    assert ref.accepted_cues == () and ref.rejected_cues == ()
    ((name, why),) = ref.skipped_cues
    assert name == "reflection" and "r and z are both unknown" in why and "lens_z" in why
    assert ref.circle.r == pytest.approx(R_C, rel=1e-3)  # still fitted under the posture


def test_refinement_step_leaves_out_a_reflection_that_disagrees_with_the_rim(exact):
    _, cue = outline_cue(exact, z=20.0)  # the circle really is at z = 12
    _, circles = steps.selection_step(
        exact["cands"], cue, [], CAM.mirror, CAM.K, None, exact["rim"]
    )
    ref = refinement(exact, cue=cue, circle=circles[the_truth(exact["cands"])])
    assert ref.accepted_cues == ()
    ((name, why),) = ref.rejected_cues
    assert name == "reflection" and why.startswith("joining it raised the rim's RMS from 0.000")
    assert np.abs(ref.tvec - CAM.tvec).max() < 1e-9  # the rim alone decides


# -- 6. warnings_step ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def settled(exact):
    """Every step on exact data with far lines: nothing to warn about."""
    args = (exact["cands"], exact["no_cue"], exact["lines"], CAM.mirror, CAM.K, None)
    sel, _ = steps.selection_step(*args, exact["rim"])
    xn = [normalize(line, CAM.K, None) for line in exact["lines"]]
    ref = steps.refinement_step(
        CAM.K, CAM.mirror, exact["cands"].all[sel.chosen], exact["rim"], xn, exact["no_cue"], None
    )
    return sel, ref


def warnings_of(exact, sel, ref):
    return steps.warnings_step(exact["rim"], exact["no_cue"], sel, ref, exact["cands"])


def test_warnings_step_has_nothing_to_say_about_an_exact_calibration(exact, settled):
    assert warnings_of(exact, *settled) == ()


def test_warnings_step_says_how_uncertain_the_axis_is(exact, settled):
    sel, ref = settled
    weak = Uncertainty(0.1, 0.2, 0.07, 0.05, 0.9)
    (w,) = warnings_of(exact, sel, dataclasses.replace(ref, uncertainty=weak))
    assert w.startswith(
        "the mirror axis is uncertain by about 0.10 deg (RMS; errors of 0.20 deg are plausible), "
        "mostly a tilt of 0.07 deg with a compensating shift of 0.05"
    )
    poor = Uncertainty(0.8, 1.5)
    w, *_ = warnings_of(exact, sel, dataclasses.replace(ref, uncertainty=poor))
    assert w.startswith("the posture is poorly determined: about 0.80 deg (RMS) on the mirror axis")
    assert "1.50 on the origin, mostly unknown" in w
    # at the threshold: quiet
    quiet = Uncertainty(steps.AXIS_WARN_DEG, 0.1)
    assert warnings_of(exact, sel, dataclasses.replace(ref, uncertainty=quiet)) == ()


def test_warnings_step_says_when_the_uncertainty_covers_the_other_posture(exact, settled):
    sel, ref = settled
    a, b = (exact["cands"].all[i] for i in exact["cands"].physical)
    gap = math.degrees(math.atan2(np.linalg.norm(np.cross(a.axis, b.axis)), a.axis @ b.axis))
    assert 1.0 < gap < 1.5  # degrees between the two physical postures' axes
    unc = Uncertainty(0.5, 0.5)  # 3 x 0.5 deg covers the gap
    warnings = warnings_of(exact, sel, dataclasses.replace(ref, uncertainty=unc))
    assert len(warnings) == 2 and warnings[0].startswith("the mirror axis is uncertain")
    assert warnings[1].startswith(
        f"the posture's uncertainty (0.500 deg on the axis) is comparable with the separation of "
        f"the two physical postures ({gap:.3f} deg): the choice may be wrong"
    )


def test_warnings_step_says_when_a_shape_error_could_have_moved_a_nearly_aligned_axis(
    exact, settled
):
    sel, ref = settled
    # the aligned posture 1 deg away changes the rim by 0.2 px, chi-square +40: a low-order
    # shape error of that size may have moved the axis there, beyond 2 x 0.03 deg
    near = Uncertainty(0.03, 0.03, aligned_chi2=40.0, aligned_px=0.2, twin_deg=2.0)
    (w,) = warnings_of(exact, sel, dataclasses.replace(ref, uncertainty=near))
    assert w.startswith("the rig is nearly aligned (the camera close to the mirror's axis)")
    assert "with the rim's image as fitted the axis is known to 0.03 deg (RMS)" in w
    assert "could put it up to 1.00 deg off: the aligned posture midway between" in w
    assert "by only 0.20 px RMS (chi-square +40 with the residuals' correlation)" in w
    # honest about what the bound is (issue 29 item 1)
    assert "a bound over the shapes of the rim's image the data cannot rule out, not an " in w
    assert "lens_z" in w
    # quiet when the cost rises by more than ALIGNED_CHI2 there, or the aligned posture lies
    # within twice the stated uncertainty, or is unknown (no twin)
    for quiet in (
        dataclasses.replace(near, aligned_chi2=steps.ALIGNED_CHI2 + 1),
        dataclasses.replace(near, twin_deg=0.12),
        Uncertainty(0.03, 0.03),
    ):
        assert warnings_of(exact, sel, dataclasses.replace(ref, uncertainty=quiet)) == ()
    assert steps.ALIGNED_CHI2 == 64.0  # 8 standard deviations


def test_warnings_step_passes_on_the_rims_the_selections_and_the_rejected_cues(exact, settled):
    sel, ref = settled
    rim = dataclasses.replace(exact["rim"], warnings=("the rim fit is poor",))
    sel = dataclasses.replace(sel, warnings=("the choice is ambiguous",))
    ref = dataclasses.replace(ref, rejected_cues=(("far lines", "its own RMS is 4 px"),))
    warnings = steps.warnings_step(rim, exact["no_cue"], sel, ref, exact["cands"])
    assert warnings == (
        "the rim fit is poor",
        "the choice is ambiguous",
        "the far lines disagree(s) with the rim and was left out of the refinement: its own RMS "
        "is 4 px; check it (the posture rests on the rim alone)",
    )


def test_the_image_made_grey_once_gives_the_edge_detectors_what_the_image_gives_them():
    """calibrate and calibrate_pattern convert an image once (inputs.edge_image): the rim's and
    the reflection's detections on it are those on the image, bit for bit; an image of more
    bits, or one whose grey lies within 0..1, is kept as it is."""
    from omnicam.calibration.inputs import edge_image
    from omnicam.calibration.rim import detect_rim

    img, _ = white_holder_render()
    grey = edge_image(img)
    assert img.dtype == np.uint8 and grey.shape == img.shape[:2] and grey.dtype == np.float32
    rim, rim_grey = (
        detect_rim(img, expected=(110.0, 150.0)),
        detect_rim(grey, expected=(110.0, 150.0)),
    )
    assert np.array_equal(rim.points, rim_grey.points) and np.array_equal(rim.conic, rim_grey.conic)
    seen = reflection.detect_reflection(img, rim, allow_coreless=True)
    seen_grey = reflection.detect_reflection(grey, rim, allow_coreless=True)
    assert np.array_equal(seen.points, seen_grey.points)
    deep = img.astype(np.uint16) * 257
    dark = (img > 128).astype(np.uint8)
    assert edge_image(deep) is deep and edge_image(dark) is dark and edge_image(None) is None
