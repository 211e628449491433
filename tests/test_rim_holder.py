"""The rim next to a stronger boundary: a white holder's outer edge, clutter around the mirror.

Renders by ``omnicam.synthetic.realistic`` (its own tracer, sharing nothing with the detector):
a mirror in a white holder plate whose outer edge is 1.37x the rim's diameter, in a bright room
(the mirror's content near the rim is almost as bright as the holder, so the holder's outer edge
is the stronger boundary), and a mirror on a textured background (leaves, gravel: the first fit
of the rim takes the texture's edges). With the size ``K`` and the mirror predict the rim is
found; where none of that size is, the error says what was found and what was expected.
"""

from __future__ import annotations

import re

import cv2
import numpy as np
import pytest
from conftest import one_error_line

from omnicam import MisalignedHyperbolicCamera, synthetic
from omnicam.calibration.ellipse import conic_distance
from omnicam.calibration.plausibility import expected_rim
from omnicam.calibration.rim import detect_rim, fit_rim
from omnicam.cli import main
from omnicam.synthetic import realistic as rl

calibrate = MisalignedHyperbolicCamera.calibrate

SIZE = 480
HOLDER = 1.37  # the holder's outer edge over the rim, diameters


def _camera(fill):
    return synthetic.misaligned_rig(3.0, 40.0, (1.0, -0.5, 0.5), image_size=(SIZE, SIZE), fill=fill)


def _truth(cam):
    """The true rim: its points (1440) and the ellipse through them."""
    pts = cam.rim_image_points(1440)
    return pts, fit_rim(pts, robust=False)


def _rms(fit, pts):
    return float(np.sqrt(np.mean(conic_distance(fit.conic, pts) ** 2)))


@pytest.fixture(scope="module")
def holder():
    """A white holder plate (outer edge 1.37x the rim) in a bright room with pale walls."""
    cam = _camera(0.62)
    r = cam.mirror.rim_radius
    yy, xx = np.mgrid[0:SIZE, 0:SIZE].astype(np.float32)
    beyond = 60.0 + 20.0 * np.sin(xx / 23.0) * np.cos(yy / 31.0)  # a dark housing around
    rng = np.random.default_rng(1)
    walls = tuple((240.0 + rng.uniform(-15, 15),) * 3 for _ in range(4))
    rig = rl.Rig(
        holder=rl.Holder(outer_axes=(HOLDER * r, HOLDER * r), kind="white"),
        room=rl.RoomScene(wall_colors=walls + ((90.0, 100.0, 110.0), (235.0, 235.0, 235.0))),
        background=np.repeat(beyond[..., None], 3, axis=2),
    )
    ren = rl.render_rig(cam, rig, supersample=2)
    img = rl.degrade(ren.image, rl.Photometric(blur_sigma=0.7, noise_sigma=2.0), seed=1)
    return img, cam


@pytest.fixture(scope="module")
def clutter():
    """A mirror on a textured background (grey level 150 +- 35 at a 6 px scale), JPEG."""
    cam = _camera(0.8)
    rng = np.random.default_rng(2)
    n = SIZE // 6
    noise = rng.normal(0.0, 1.0, (n, n, 3)).astype(np.float32)
    noise = cv2.resize(noise, (SIZE, SIZE), interpolation=cv2.INTER_CUBIC)
    rig = rl.Rig(room=rl.random_room(rng), background=np.clip(150.0 + 35.0 * noise, 0, 255))
    ren = rl.render_rig(cam, rig, supersample=2)
    photo = rl.Photometric(blur_sigma=0.8, noise_sigma=3.0, jpeg_quality=85)
    return rl.degrade(ren.image, photo, seed=2), cam


def test_white_holder_render_has_its_outer_edge_stronger_than_the_rim(holder):
    img, cam = holder
    _, truth = _truth(cam)
    g = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY).astype(float)
    cx, cy = np.rint(truth.center).astype(int)
    r = truth.axes.mean()
    for sign in (-1, 1):  # left and right of the centre
        mirror, plate = g[cy, cx + sign * int(r - 6)], g[cy, cx + sign * int(r + 10)]
        beyond = g[cy, cx + sign * int(HOLDER * r + 10)]
        assert plate - beyond > 3 * abs(plate - mirror)  # the outer edge is the strong one


def test_white_holder_with_the_expected_size_finds_the_rim(holder):
    """Unguided, or with a size the holder's edge also fits, the outer edge wins; with the
    range K and the mirror predict the search goes on to the boundary inside it, the rim."""
    img, cam = holder
    pts, truth = _truth(cam)
    fit = detect_rim(img, expected=expected_rim(cam.K, cam.mirror).radius_range)
    assert np.linalg.norm(fit.center - truth.center) < 0.3
    assert abs(fit.diameter / truth.diameter - 1.0) < 0.002
    assert _rms(fit, pts) < 0.2


def test_white_holder_without_the_expected_size_takes_the_outer_edge(holder):
    """What ``expected`` buys: without it the brighter-inside boundary is the holder's edge."""
    img, cam = holder
    _, truth = _truth(cam)
    fit = detect_rim(img)
    assert abs(fit.diameter / truth.diameter - HOLDER) < 0.02


def test_calibrate_on_the_white_holder_uses_the_rim(holder):
    img, cam = holder
    pts, _ = _truth(cam)
    _, report = calibrate(cam.K, cam.mirror, image=img)
    assert _rms(fit_rim(report.boundary_points), pts) < 0.2
    assert not report.plausibility


def test_a_rough_first_fit_in_clutter_goes_on_to_the_rim(clutter):
    """The textured surround makes the first fit rough (several px RMS); the circles of the
    expected size about it hold the rim."""
    img, cam = clutter
    pts, truth = _truth(cam)
    fit = detect_rim(img, expected=expected_rim(cam.K, cam.mirror).radius_range)
    assert np.linalg.norm(fit.center - truth.center) < 0.5
    assert abs(fit.diameter / truth.diameter - 1.0) < 0.002
    assert _rms(fit, pts) < 0.3


def _wrong_K(cam, factor):
    K = cam.K.copy()
    K[0, 0] *= factor
    K[1, 1] *= factor
    return K


def test_no_rim_of_the_expected_size_names_what_was_found_and_expected(clutter):
    """K 1.3x too long: the rim is smaller than the range, the boundaries of that size are
    the texture's, and none passes: the error gives the best one and the range."""
    img, cam = clutter
    _, truth = _truth(cam)
    lo, hi = expected_rim(_wrong_K(cam, 1.3), cam.mirror).radius_range
    assert truth.axes.max() < lo  # no rim of that size in the image
    with pytest.raises(ValueError, match="no ellipse found") as err:
        detect_rim(img, expected=(lo, hi))
    text = str(err.value)
    found = re.search(
        r"diameter of ([\d.]+) px \(semi-axes ([\d.]+) and ([\d.]+) px\), centre \(([\d.]+), "
        r"([\d.]+)\) px and ([\d.]+) px RMS along (\d+) %",
        text,
    )
    assert found, text
    d, a, b, x, y, rms, share = (float(v) for v in found.groups())
    assert abs(d - (a + b)) < 0.15 and a >= b
    assert 0 <= x < SIZE and 0 <= y < SIZE and 0 <= share <= 100
    assert rms > 1.5  # rejected for its roughness: a rim fits within 1.5 px
    assert f"semi-axes {lo:.1f}-{hi:.1f} px" in text
    assert f"a diameter of {2 * lo:.0f}-{2 * hi:.0f} px" in text


def test_calibrate_names_fx_and_the_mirror_behind_the_expected_size(clutter):
    img, cam = clutter
    K = _wrong_K(cam, 1.3)
    with pytest.raises(ValueError, match="no ellipse found") as err:
        calibrate(K, cam.mirror, image=img)
    text = str(err.value)
    assert f"fx = {K[0, 0]:.1f}" in text and "rim radius 30" in text and "a = 23.4" in text
    assert "px RMS" in text and "semi-axes" in text and "rim hint" in text


def test_command_line_says_it_in_one_line(clutter, tmp_path, capsys):
    img, cam = clutter
    K = _wrong_K(cam, 1.3)
    path = tmp_path / "roof.png"
    cv2.imwrite(str(path), img)
    code = main(
        [
            "calibrate",
            str(path),
            "--mirror",
            "23.4",
            "28.1",
            "30",
            "--fx",
            f"{K[0, 0]:.6f}",
            "--fy",
            f"{K[1, 1]:.6f}",
            "--cx",
            f"{K[0, 2]:.6f}",
            "--cy",
            f"{K[1, 2]:.6f}",
            "-o",
            str(tmp_path / "calib.yaml"),
        ]
    )
    assert code != 0
    line = one_error_line(capsys.readouterr().err)
    assert "diameter of" in line and "px RMS" in line and f"fx = {K[0, 0]:.1f}" in line
    assert "--rim-hint" in line
    assert not (tmp_path / "calib.yaml").exists()


def test_expected_size_far_below_the_rim_still_takes_the_rim():
    """A K for another resolution (expected 4x too small): no boundary next to the rim is
    searched; the rim is taken as before (the plausibility check reports the size)."""
    cam = _camera(0.62)
    img = rl.degrade(rl.render_rig(cam, rl.Rig(), supersample=2).image, rl.Photometric())
    pts, _ = _truth(cam)
    lo, hi = expected_rim(_wrong_K(cam, 0.25), cam.mirror).radius_range
    assert _rms(detect_rim(img, expected=(lo, hi)), pts) < 0.1
