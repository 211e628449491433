"""After a bump: a rig's ``K``, ``D`` and mirror kept, its posture re-estimated
from one new frame (``MisalignedHyperbolicCamera.recalibrate``, ``omnicam calibrate --from``)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from omnicam import MisalignedHyperbolicCamera, synthetic
from omnicam.calibration import calibrate
from omnicam.camera import scale_K
from omnicam.cli import main
from omnicam.gauge import posture_error

SIZE = (500, 500)
D = [-0.05, 0.01, 0.0, 0.0]
#: "within the stated uncertainty": the stated axis and origin uncertainties are RMS values of a
#: 2-D (axis) and 3-D (origin) error, so 3x them bounds an honest estimate's error but for a
#: chance of about 1e-4 (axis) to 3e-3 (origin)
WITHIN = 3.0


def one_error_line(err):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err
    assert len(lines) == 1 and lines[0].startswith("omnicam: error: "), err
    return lines[0]


@pytest.fixture(scope="module")
def rig_and_frames(tmp_path_factory):
    """A rig with distortion calibrated earlier (saved to ``rig.yaml``) and two frames of the
    mirror: one of the rig as it was, one after a bump (tilt 3 -> 4.5 deg, towards another
    azimuth, and the mirror shifted by about 1.5 mm)."""
    folder = tmp_path_factory.mktemp("recalibrate")
    rig = synthetic.misaligned_rig(3.0, 30.0, (1.5, -1.0, 1.0), image_size=SIZE, D=D)
    bumped = synthetic.misaligned_rig(4.5, 100.0, (0.5, 0.0, 0.0), image_size=SIZE, D=D)
    assert np.array_equal(bumped.K, rig.K) and bumped.mirror == rig.mirror
    rig.save(folder / "rig.yaml")
    frames = {}
    for name, truth, seed in (("unmoved", rig, 1), ("bumped", bumped, 2)):
        image = synthetic.render_environment(truth, supersample=2, noise=1.0, seed=seed)
        cv2.imwrite(str(folder / f"{name}.png"), image)
        frames[name] = (truth, image, str(folder / f"{name}.png"))
    return rig, str(folder / "rig.yaml"), frames


@pytest.mark.parametrize("frame", ["unmoved", "bumped"])
def test_from_gives_the_frames_posture_back_within_its_stated_uncertainty(
    rig_and_frames, frame, tmp_path, capsys
):
    rig, rig_file, frames = rig_and_frames
    truth, image, path = frames[frame]
    out = tmp_path / "new.yaml"
    assert main(["calibrate", path, "--from", rig_file, "-o", str(out)]) == 0, (
        capsys.readouterr().err
    )
    printed = capsys.readouterr().out
    assert f"K, D and the mirror from {rig_file}" in printed
    new = MisalignedHyperbolicCamera.load(out)
    # K, D, the mirror and the image size are the rig's, to the bit
    assert np.array_equal(new.K, rig.K) and np.array_equal(new.D, rig.D)
    assert new.mirror == rig.mirror and new.image_size == rig.image_size
    # the API gives the same camera, and the report the stated uncertainty
    cam, report = rig.recalibrate(image)
    assert cam == new
    assert not report.ambiguous  # decided (the camera's reflection), and right:
    axis, origin = posture_error(new, truth)
    assert axis <= WITHIN * report.axis_std_deg, (axis, report.axis_std_deg)
    assert origin <= WITHIN * report.origin_std_mm, (origin, report.origin_std_mm)
    moved, _ = posture_error(new, rig)
    if frame == "bumped":  # the bump is seen, far beyond the uncertainty
        assert moved > 10 * report.axis_std_deg
    printed_axis = float(printed.split("mirror axis ")[-1].split(" deg")[0])
    assert printed_axis == pytest.approx(moved, abs=1e-3)


def test_a_frame_at_another_resolution_rescales_K_and_says_so(rig_and_frames, tmp_path, capsys):
    rig, rig_file, frames = rig_and_frames
    half = (SIZE[0] // 2, SIZE[1] // 2)
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), cv2.resize(frames["unmoved"][1], half, interpolation=cv2.INTER_AREA))
    out = tmp_path / "new.yaml"
    code = main(["calibrate", str(small), "--from", rig_file, "-o", str(out), "--force"])
    err = capsys.readouterr().err
    assert code == 0, err
    assert f"--from {rig_file}: K is for 500x500, image is 250x250: K rescaled" in err
    new = MisalignedHyperbolicCamera.load(out)
    np.testing.assert_allclose(new.K, scale_K(rig.K, SIZE, half), rtol=1e-12)
    assert new.image_size == half and np.array_equal(new.D, rig.D)


@pytest.mark.parametrize(
    "extra, flag",
    [
        (["--mirror", "23.4", "28.1", "30"], "--mirror"),
        (["--intrinsics", "K.yaml"], "--intrinsics"),
        (["--fx", "400"], "--fx"),
        (["--cy", "240"], "--cy"),
        (["--dist", "0.1", "0", "0", "0"], "--dist"),
        (["--chessboard", "6x7", "--square", "30"], "--chessboard"),
    ],
)
def test_from_is_refused_beside_what_it_replaces(rig_and_frames, extra, flag, tmp_path, capsys):
    _, rig_file, frames = rig_and_frames
    out = tmp_path / "new.yaml"
    code = main(["calibrate", frames["bumped"][2], "--from", rig_file, *extra, "-o", str(out)])
    assert code == 2
    line = one_error_line(capsys.readouterr().err)
    assert "--from" in line and flag in line
    assert not out.exists() and not (tmp_path / "new_overlay.png").exists()


def test_from_a_missing_or_broken_file_is_one_line(rig_and_frames, tmp_path, capsys):
    _, _, frames = rig_and_frames
    broken = tmp_path / "broken.yaml"
    broken.write_text("%YAML:1.0\nformat_version: 1\nmodel: misaligned_hyperbolic\n")
    for path, words in ((tmp_path / "none.yaml", "does not exist"), (broken, "mirror")):
        code = main(
            ["calibrate", frames["bumped"][2], "--from", str(path), "-o", str(tmp_path / "x.yaml")]
        )
        assert code == 1
        line = one_error_line(capsys.readouterr().err)
        assert str(path) in line and words in line


def test_recalibrate_keeps_K_D_and_the_mirror_and_refuses_other_ones(rig_and_frames):
    rig, _, frames = rig_and_frames
    image = frames["bumped"][1]
    with pytest.raises(ValueError, match="keeps this camera's K, D, mirror"):
        rig.recalibrate(image, D=None)
    with pytest.raises(ValueError, match=r"250x250.*500x500.*scaled\(\(250, 250\)\)"):
        rig.recalibrate(cv2.resize(image, (250, 250)))


def test_help_says_which_of_a_and_b_is_along_the_axis(capsys):
    assert main(["calibrate", "--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    for words in (
        "(X^2+Y^2)/A^2 - Z^2/B^2 = -1",
        "B is the semi-axis ALONG the axis",
        "A is the semi-axis ACROSS it",
        "--mirror b a RIM",
        "--from RIG.yaml",
    ):
        assert words in out


# -- the stated uncertainty against the errors, by tilt ----------------------------------------
def _rim_only(rig, pts):
    return calibrate(
        rig.K,
        rig.mirror,
        boundary_points=pts,
        image_size=rig.image_size,
        lens=False,
        check_plausibility=False,
    )


def _errors_over_stated(tilt_deg, draws=20, sigma=0.3, seed=7):
    """RMS over ``draws`` noisy rims (white noise ``sigma`` px) of the axis error over the stated
    axis uncertainty, on a rig tilted by ``tilt_deg``, the choice between the physical
    postures aside (the error is to the nearer of the exact rim's two physical postures)."""
    rig = synthetic.misaligned_rig(tilt_deg, 50.0, (0.2, -0.1, 0.0), image_size=(640, 480))
    rim = rig.rim_image_points(1200)
    _, exact = _rim_only(rig, rim)
    postures = [
        rig.replace(rvec=exact.candidates[i].rvec, tvec=exact.candidates[i].tvec)
        for i in exact.physical
    ]
    assert min(posture_error(p, rig)[0] for p in postures) < 1e-6
    rng = np.random.default_rng(seed)
    ratios = []
    for _ in range(draws):
        cam, report = _rim_only(rig, rim + rng.normal(scale=sigma, size=rim.shape))
        error = min(posture_error(cam, p)[0] for p in postures)
        ratios.append(error / report.axis_std_deg)
    return float(np.sqrt(np.mean(np.square(ratios))))


def test_a_tilted_rigs_stated_uncertainty_is_the_rms_of_its_errors():
    """Honest: the RMS of error / stated is 1 (sampling spread of 20 draws about 0.15)."""
    assert 0.7 < _errors_over_stated(4.0) < 1.4


def test_a_nearly_aligned_rigs_stated_uncertainty_is_the_rms_of_its_errors():
    """Issue 17 item 8: near alignment the rim's image depends on the tilt (with its
    compensating shift) only to second order, and the first-order uncertainty at an estimate
    the noise pushed away from the aligned posture was about half the errors here (RMS 1.9);
    the region of the cost itself states it (``refine.profile_uncertainty``)."""
    assert 0.7 < _errors_over_stated(0.3) < 1.4
