"""The single-image route (paper section 3) for any known mirror of revolution.

The rim is a circle on the axis for every mirror of revolution, so Chen's method, the
candidates and the cues hold for an even asphere as for the hyperboloid; only the checks that
assume a rig built as designed need the mirror's nominal camera position
(:func:`omnicam.mirror.nominal_camera_z`).
"""

import math

import numpy as np
import pytest
from asphere_rigs import rig

import omnicam
from omnicam import MisalignedCatadioptricCamera
from omnicam.asphere import AsphericMirror
from omnicam.calibration.plausibility import (
    assess,
    check_plausibility,
    expected_rim,
    focus_offset,
    guess_K,
)
from omnicam.calibration.rim import fit_rim
from omnicam.mirror import HyperbolicMirror, nominal_camera_z
from omnicam.synthetic import far_line_pixels


def _rim_pixels(cam, n=400, sigma=0.3, seed=0):
    pts = cam.rim_image_points(n)
    return pts + np.random.default_rng(seed).normal(0.0, sigma, pts.shape)


def _errors(cam, truth):
    axis = math.degrees(math.acos(min(1.0, float(cam.R[:, 2] @ truth.R[:, 2]))))
    return axis, float(np.linalg.norm(cam.camera_center - truth.camera_center))


def test_nominal_camera_position_of_each_mirror_kind():
    hyp = HyperbolicMirror(23.4, 28.1, 30.0)
    assert nominal_camera_z(hyp) == -hyp.c
    assert nominal_camera_z(hyp.as_asphere()) == pytest.approx(-hyp.c, abs=1e-12)
    assert nominal_camera_z(rig("equiangular 7").mirror) == 0.0  # camera at the origin
    assert nominal_camera_z(AsphericMirror.sphere(30.0, 18.0, vertex_z=40.0)) == 0.0
    assert nominal_camera_z(AsphericMirror.sphere(30.0, 18.0)) is None  # frame says nothing


@pytest.mark.parametrize("name", ["sphere", "equiangular 7"])
def test_misaligned_asphere_rig_posture_from_rim_and_far_lines_within_stated_uncertainty(name):
    truth = rig(name)
    lines = far_line_pixels(truth, n_lines=3, rng=1)
    cam, report = omnicam.calibrate(
        truth.K,
        truth.mirror,
        boundary_points=_rim_pixels(truth),
        far_lines=lines,
        image_size=truth.image_size,
    )
    assert type(cam.mirror) is AsphericMirror and cam.mirror == truth.mirror
    axis, origin = _errors(cam, truth)
    assert axis <= 3.0 * report.axis_std_deg + 0.05
    assert origin <= 3.0 * report.origin_std_mm + 0.05
    assert not report.plausibility  # a plausible rig: nothing implausible found
    assert "asphere" in report.summary()


@pytest.mark.parametrize("name", ["sphere", "equiangular 7"])
def test_asphere_rig_from_the_rim_alone_falls_back_near_the_nominal_camera(name):
    truth = rig(name)
    cam, report = omnicam.calibrate(
        truth.K, truth.mirror, boundary_points=_rim_pixels(truth), image_size=truth.image_size
    )
    axis, origin = _errors(cam, truth)
    # the fallback picks one of the mirrored pair; this rig's is the right one
    assert axis <= 3.0 * report.axis_std_deg + 0.05
    assert origin <= 3.0 * report.origin_std_mm + 0.05
    assert any("ambiguous" in w and "nominal camera position" in w for w in report.warnings)


def test_expected_rim_and_guess_K_use_the_nominal_camera_position():
    truth = rig("equiangular 7", misaligned=False)  # camera at the origin, axes parallel
    exp = expected_rim(truth.K, truth.mirror)
    # the aligned rig's rim: 200 px about the principal point (asphere_rigs.RIM_IMAGE_RADIUS)
    assert exp.radius == pytest.approx(200.0, rel=1e-6)
    np.testing.assert_allclose(exp.center, truth.K[:2, 2], atol=1e-6)
    K = guess_K(fit_rim(truth.rim_image_points(200)), truth.mirror)
    np.testing.assert_allclose(K, truth.K, rtol=1e-6, atol=1e-6)


def test_a_mirror_without_a_nominal_camera_position_says_so_instead_of_guessing():
    truth = rig("sphere")
    m = truth.mirror
    # the same sphere, its frame's origin at the vertex: the frame says nothing of the camera
    moved = AsphericMirror.sphere(m.R, m.rim_radius)
    shift = np.array([0.0, 0.0, m.vertex_z])
    cam = MisalignedCatadioptricCamera(
        truth.K, moved, truth.rvec, truth.tvec + truth.R @ shift, image_size=truth.image_size
    )
    with pytest.raises(ValueError, match="does not say where the camera sits.*give K"):
        guess_K(fit_rim(cam.rim_image_points(200)), moved)
    with pytest.raises(ValueError, match="does not say where the camera sits"):
        expected_rim(cam.K, moved)
    assert math.isnan(focus_offset(cam.camera_center, moved))
    cal, report = omnicam.calibrate(
        cam.K, moved, boundary_points=_rim_pixels(cam), image_size=cam.image_size
    )
    assert any("does not say where the camera sits" in w for w in report.warnings)
    assert not [w for w in report.plausibility if w.kind in ("rim_size", "offset")]
    assert "least tilted" in " ".join(report.warnings)  # the fallback without it


def test_the_swapped_a_b_check_is_a_hyperboloids_only():
    truth = rig("sphere")
    cam, report = omnicam.calibrate(
        truth.K,
        truth.mirror,
        boundary_points=_rim_pixels(truth),
        image_size=truth.image_size,
        check_plausibility=False,
    )
    calls = []

    def recalibrate(m):
        calls.append(m)
        raise AssertionError("no swap of a and b for an asphere")

    # a posture made implausible (tilted 20 deg) would ask for the swap with a hyperboloid
    tilted = MisalignedCatadioptricCamera(
        cam.K, cam.mirror, np.array([0.35, 0.0, 0.0]), cam.tvec, image_size=cam.image_size
    )
    import dataclasses

    warnings = assess(dataclasses.replace(report, camera=tilted), recalibrate=recalibrate)
    assert not calls
    assert any(w.kind == "tilt" for w in warnings)
    assert all("a, b" not in str(w) for w in warnings)
    assert not check_plausibility(cam, report.conic)


@pytest.mark.parametrize("name", ["sphere", "equiangular 7"])
def test_asphere_rig_from_a_rendered_image_rim_and_camera_reflection(name):
    from omnicam.synthetic import render_environment

    truth = rig(name)
    image = render_environment(truth, supersample=2, seed=0)
    cam, report = omnicam.calibrate(truth.K, truth.mirror, image=image)
    axis, origin = _errors(cam, truth)
    assert axis <= 3.0 * report.axis_std_deg + 0.05
    assert origin <= 3.0 * report.origin_std_mm + 0.05
    assert np.isfinite(report.lens_rms) and report.lens_rms < 1.0  # the reflection was used
    assert cam.camera_reflection is not None
