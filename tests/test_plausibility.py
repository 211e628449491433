"""Plausibility of a calibration: what no real rig gives is warned about, a good rig is not."""

import math
import re

import numpy as np
import pytest

from omnicam import HyperbolicMirror, MisalignedHyperbolicCamera, synthetic
from omnicam.calibration.plausibility import (
    PlausibilityWarning,
    check_plausibility,
    expected_rim,
    focus_offset,
    swapped_mirror_warnings,
    tilt_deg,
)
from omnicam.calibration.rim import fit_rim
from omnicam.camera import scale_K

calibrate = MisalignedHyperbolicCamera.calibrate

SIZE = (400, 300)


@pytest.fixture(scope="module")
def scene():
    """A rig within the limits (tilt 3 deg, camera 2.3 mm from the lower focus), its render and
    far lines."""
    cam = synthetic.misaligned_rig(3.0, 30.0, (1.5, -1.0, 1.0), image_size=SIZE)
    return {
        "cam": cam,
        "image": synthetic.render_environment(cam, seed=1),
        "lines": synthetic.far_line_pixels(cam, 3, rng=2),
    }


def kinds(report):
    return sorted({w.kind for w in report.plausibility})


def true_rim(cam):
    return fit_rim(cam.rim_image_points(720), robust=False)


# -- expected rim ------------------------------------------------------------------------------
def test_expected_rim_of_aligned_rig_is_f_rim_radius_over_z_rim_plus_c():
    cam = synthetic.aligned_rig((500, 400))
    m = cam.mirror
    exp = expected_rim(cam.K, m)
    assert exp.radius == pytest.approx(cam.K[0, 0] * m.rim_radius / (m.z_rim + m.c), rel=1e-4)
    np.testing.assert_allclose(exp.center, cam.K[:2, 2], atol=1e-3)
    assert exp.radius_range[0] < exp.radius < exp.radius_range[1]


def test_expected_rim_range_covers_rigs_within_the_limits():
    """Random rigs with tilt <= 10 deg and offset <= 10 mm: their rim ellipses (projected by the
    camera model, not by expected_rim's own code) lie within the range."""
    rng = np.random.default_rng(7)
    base = synthetic.aligned_rig((500, 500))
    exp = expected_rim(base.K, base.mirror)
    for _ in range(20):
        cam = synthetic.random_misaligned_rig(rng, 10.0, 10.0)
        rim = true_rim(cam)
        assert exp.radius_range[0] * 0.99 <= rim.axes[1] <= rim.axes[0]
        assert rim.axes[0] <= exp.radius_range[1] * 1.01
        assert np.linalg.norm(rim.center - exp.center) <= exp.max_center_offset * 1.01 + 0.5


# -- a good rig --------------------------------------------------------------------------------
@pytest.mark.parametrize("with_lines", [False, True], ids=["rim_and_lens", "far_lines"])
def test_good_rig_gives_no_plausibility_warning(scene, with_lines):
    cam = scene["cam"]
    far = scene["lines"] if with_lines else None
    camera, report = calibrate(cam.K, cam.mirror, image=scene["image"], far_lines=far)
    assert report.plausibility == ()
    assert check_plausibility(camera, report.conic) == []
    assert tilt_deg(camera.R) == pytest.approx(3.0, abs=0.3)


def test_true_rigs_at_moderate_misalignment_pass_every_check():
    for cam in (
        synthetic.aligned_rig(),
        synthetic.misaligned_rig(),
        synthetic.misaligned_rig(8.0, 200.0, (4.0, -5.0, 3.0)),
    ):
        assert check_plausibility(cam, true_rim(cam)) == []


# -- implausible inputs ------------------------------------------------------------------------
def test_K_for_twice_the_resolution_warns_about_the_rim_size(scene):
    cam = scene["cam"]
    K2 = scale_K(cam.K, SIZE, (2 * SIZE[0], 2 * SIZE[1]))
    _, report = calibrate(K2, cam.mirror, image=scene["image"])
    assert {"rim_size", "offset"} <= set(kinds(report))
    size = next(w for w in report.plausibility if w.kind == "rim_size")
    assert "another resolution" in str(size)
    assert re.search(r"about 0\.(49|50)x", str(size))
    assert str(size) in report.warnings


def test_K_rescaled_to_another_aspect_ratio_warns_about_K_and_the_tilt(scene):
    cam = scene["cam"]
    K = scale_K(cam.K, SIZE, (SIZE[0], SIZE[1] * 3 // 4))  # 4:3 -> 16:9 by (w, h) separately
    camera, report = calibrate(K, cam.mirror, image=scene["image"])
    assert {"intrinsics", "tilt"} <= set(kinds(report))
    aspect = next(w for w in report.plausibility if w.kind == "intrinsics")
    assert "fx / fy = 1.333" in str(aspect) and "aspect ratio" in str(aspect)
    assert tilt_deg(camera.R) > 10.0


def test_a_and_b_swapped_with_far_lines_fit_clearly_better_swapped(scene):
    cam = scene["cam"]
    m = cam.mirror
    swapped = HyperbolicMirror(m.b, m.a, m.rim_radius)
    _, report = calibrate(cam.K, swapped, image=scene["image"], far_lines=scene["lines"])
    w = next(w for w in report.plausibility if w.kind == "swapped_ab")
    assert "fits clearly better with a and b swapped" in str(w)
    assert f"a = {m.a:g}, b = {m.b:g}" in str(w) and "far-line score" in str(w)


def test_a_and_b_swapped_rim_only_says_the_swap_would_be_plausible(scene):
    cam = scene["cam"]
    m = cam.mirror
    _, report = calibrate(cam.K, HyperbolicMirror(m.b, m.a, m.rim_radius), image=scene["image"])
    assert {"offset", "swapped_ab"} <= set(kinds(report))
    w = next(w for w in report.plausibility if w.kind == "swapped_ab")
    assert "would be plausible with a and b swapped" in str(w)


def test_principal_point_far_from_the_rim_centre(scene):
    cam = scene["cam"]
    K = cam.K.copy()
    K[0, 2] += 170.0  # cx of another crop: 1.35 rim radii off
    _, report = calibrate(K, cam.mirror, image=scene["image"])
    assert "principal_point" in kinds(report)
    w = next(w for w in report.plausibility if w.kind == "principal_point")
    assert "check cx, cy of K" in str(w)


def test_principal_point_outside_the_image():
    cam = synthetic.aligned_rig((400, 300))
    moved = cam.replace(K=np.array([[cam.K[0, 0], 0, 700.0], [0, cam.K[1, 1], 150.0], [0, 0, 1]]))
    ws = check_plausibility(moved, true_rim(moved), (400, 300))
    assert [w.kind for w in ws] == ["intrinsics"]
    assert "outside the 400x300 image" in str(ws[0])


def test_focal_length_absurd_for_the_image_size():
    cam = synthetic.aligned_rig((400, 300))
    ws = check_plausibility(cam, true_rim(cam), (40000, 30000))
    assert any(w.kind == "intrinsics" and "absurd" in str(w) for w in ws)


def test_image_without_a_mirror_is_never_a_quiet_calibration():
    """A photograph of a coffee cup (scikit-image's sample) with a plausible K for its size:
    either no rim is found (ValueError) or the result carries warnings that say what to check."""
    skdata = pytest.importorskip("skimage.data")
    cup = np.ascontiguousarray(skdata.coffee()[:, :, ::-1])
    h, w = cup.shape[:2]
    m = synthetic.default_mirror()
    f = 0.5 * 0.85 * min(w, h) * (m.z_rim + m.c) / m.rim_radius
    K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]])
    try:
        camera, report = calibrate(K, m, image=cup)
    except ValueError as err:
        assert "ellipse" in str(err) or "rim" in str(err)
        return
    assert report.plausibility, f"quiet calibration: tilt {tilt_deg(camera.R):.1f} deg"
    assert any("that the ellipse found is the mirror's rim" in str(w) for w in report.plausibility)


@pytest.mark.parametrize("seed", [0, 1])
def test_random_texture_raises_or_warns(seed):
    import cv2

    rng = np.random.default_rng(seed)
    img = cv2.GaussianBlur(rng.integers(0, 256, (300, 400), dtype=np.uint8), (0, 0), 2.0)
    cam = synthetic.aligned_rig((400, 300))
    try:
        _, report = calibrate(cam.K, cam.mirror, image=img)
    except ValueError as err:
        assert "no ellipse" in str(err)
        return
    assert report.plausibility


def test_rim_hint_outside_the_image_raises_value_error_naming_hint(scene):
    cam = scene["cam"]
    with pytest.raises(ValueError, match="hint"):
        calibrate(cam.K, cam.mirror, image=scene["image"], rim_hint=(900.0, 100.0, 120.0))


def test_rim_hint_is_passed_to_detect_rim(scene):
    cam = scene["cam"]
    rim = true_rim(cam)
    _, report = calibrate(
        cam.K,
        cam.mirror,
        image=scene["image"],
        rim_hint=(*(rim.center + 5.0), rim.axes.mean() * 1.1),
    )
    assert abs(fit_rim(report.boundary_points).axes.mean() - rim.axes.mean()) < 0.5
    with pytest.raises(ValueError, match="near the hint"):  # nothing there at that size
        calibrate(cam.K, cam.mirror, image=scene["image"], rim_hint=(60.0, 60.0, 50.0))


# -- limits --------------------------------------------------------------------------------------
def test_tilt_and_offset_limits_are_settable():
    cam = synthetic.misaligned_rig(12.0, 60.0, (-3.0, -2.0, 2.0))
    assert tilt_deg(cam.R) == pytest.approx(12.0)
    off = focus_offset(cam.camera_center, cam.mirror)
    assert 10.0 < off < 12.0
    ws = check_plausibility(cam, true_rim(cam))
    assert {"tilt", "offset"} <= {w.kind for w in ws}
    tilt = next(w for w in ws if w.kind == "tilt")
    assert tilt.value == pytest.approx(12.0) and tilt.limit == 10.0 and "12.0 deg" in str(tilt)
    assert check_plausibility(cam, true_rim(cam), max_tilt_deg=15, max_offset_mm=12) == []
    only = check_plausibility(cam, true_rim(cam), max_tilt_deg=15)
    assert [w.kind for w in only] == ["offset"]


def test_residuals_above_the_limit_warn_by_name():
    cam = synthetic.misaligned_rig()
    ws = check_plausibility(
        cam, true_rim(cam), residuals={"far lines": 4.2, "outline": 0.3, "x": math.nan}
    )
    assert [w.kind for w in ws] == ["residual"] and "far lines" in str(ws[0])
    assert (
        check_plausibility(cam, true_rim(cam), residuals={"far lines": 4.2}, max_residual_px=5)
        == []
    )


def test_check_plausibility_takes_the_conic_as_well_as_a_rim_fit():
    cam = synthetic.misaligned_rig(12.0)
    a = check_plausibility(cam, true_rim(cam))
    b = check_plausibility(cam, true_rim(cam).conic)
    assert [str(w) for w in a] == [str(w) for w in b] and a


@pytest.mark.parametrize(
    "kwargs",
    [
        {"max_tilt_deg": 0},
        {"max_offset_mm": -1},
        {"max_tilt_deg": math.nan},
        {"max_residual_px": "a"},
        {"max_aspect_deviation": math.inf},
    ],
)
def test_bad_limits_raise_value_error_naming_them(kwargs):
    cam = synthetic.aligned_rig()
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        check_plausibility(cam, true_rim(cam), **kwargs)


def test_swapped_mirror_warnings_compare_costs_and_postures():
    good = synthetic.misaligned_rig()
    bad = synthetic.misaligned_rig(20.0)
    m = good.mirror
    g = {"camera": good, "costs": {"far-line score (eq. 31)": 1e-4}}
    s = {"camera": good, "costs": {"far-line score (eq. 31)": 1e-8}}
    assert swapped_mirror_warnings(m, g, s)[0].kind == "swapped_ab"
    assert swapped_mirror_warnings(m, s, g) == []
    assert swapped_mirror_warnings(m, g, None) == []
    posture = swapped_mirror_warnings(
        m, {"camera": bad, "costs": {}}, {"camera": good, "costs": {}}
    )
    assert "would be plausible" in str(posture[0])


def test_plausibility_warning_is_a_user_warning_with_its_message():
    w = PlausibilityWarning("tilt", "too tilted", 12.0, 10.0)
    assert isinstance(w, UserWarning) and str(w) == "too tilted"
    assert (w.kind, w.value, w.limit) == ("tilt", 12.0, 10.0)


def test_implausible_choice_with_a_plausible_other_candidate_says_so(scene):
    """The chosen posture implausible, another physical candidate of Chen's method within the
    limits: the warning points at the choice, not at a swap of a and b."""
    import dataclasses

    from omnicam.calibration.plausibility import assess

    cam = scene["cam"]
    _, report = calibrate(cam.K, cam.mirror, image=scene["image"])
    physical = [i for i, c in enumerate(report.candidates) if c.physical]
    assert len(physical) == 2
    bad = synthetic.misaligned_rig(20.0, 0.0, (0.0, 0.0, 0.0), image_size=SIZE)
    calls = []
    faked = dataclasses.replace(report, camera=bad, chosen=physical[0])
    ws = assess(faked, SIZE, lambda m: calls.append(m))
    assert "choice" in [w.kind for w in ws] and "swapped_ab" not in [w.kind for w in ws]
    assert f"candidate {physical[1]}" in str(next(w for w in ws if w.kind == "choice"))
    assert calls == []  # no second calibration with a and b swapped


def test_a_mirror_in_metres_is_named_with_the_millimetres_to_give():
    from omnicam.calibration.chen import rim_conic

    def conic(c):
        return rim_conic(c.K, c.R, c.tvec, c.mirror)

    cam = synthetic.misaligned_rig()
    m = cam.mirror
    metres = cam.replace(  # the same rig, every length in metres: the same image
        mirror=HyperbolicMirror(m.a / 1000, m.b / 1000, m.rim_radius / 1000), tvec=cam.tvec / 1000
    )
    units = [w for w in check_plausibility(metres, conic(metres)) if w.kind == "units"]
    assert len(units) == 1 and "in metres?" in str(units[0])
    assert f"{m.rim_radius:g}" in str(units[0])  # the rim radius to give, in mm
    assert not [w for w in check_plausibility(cam, conic(cam)) if w.kind == "units"]
