"""omnicam calibrate --chessboard: progress per image, names in the table, the held-out check,
corners from other tools, starts for K honoured or refused, views that cannot determine the rig."""

import json
import re

import cv2
import numpy as np
import pytest

import omnicam
import omnicam.formats.calibration_file
from omnicam import synthetic
from omnicam.cli import main
from omnicam.gauge import posture_error
from omnicam.synthetic import boards

PATTERN, SQUARE = (7, 5), 60.0
SIZE = (700, 700)
RIG = synthetic.misaligned_rig(3.0, 30.0, (1.5, -2.0, 1.9), image_size=SIZE)
MIRROR = ["--mirror", "23.4", "28.1", "30"]
#: The library's parameter names that the command line must say as options (issue 29 item 7).
PYTHON_NAMES = re.compile(
    r"\b(lens_z|lens_r|pattern_size|rim_radius|refine_mirror_shape|image_points|square_size)\b"
)


def _render(folder, poses, prefix="board"):
    paths = []
    for i, p in enumerate(poses):
        path = folder / f"{prefix}{i}.png"
        cv2.imwrite(str(path), boards.render_board(RIG, PATTERN, SQUARE, *p, supersample=2))
        paths.append(str(path))
    return paths


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    folder = tmp_path_factory.mktemp("views")
    poses = boards.random_board_poses(
        RIG, 6, PATTERN, SQUARE, distance=(350.0, 700.0), max_tilt_deg=40.0, rng=11
    )
    return _render(folder, poses)


def _calibrate(paths, out, *extra):
    args = ["calibrate", "--chessboard", "7x5", "--square", "60", *paths, *MIRROR]
    return main([*args, "--dist-model", "none", "-o", str(out), *extra])


def test_progress_names_and_the_heldout_check_are_printed(views, tmp_path, capsys):
    assert _calibrate(views, tmp_path / "rig.yaml", "--heldout", "3") == 0
    out = capsys.readouterr().out
    assert "[1/6] board0.png: board (raw)" in out
    assert "board5.png" in out.split("found by")[1]  # the table names the images
    assert "held-out corner RMS (3-fold" in out and "cv2.omnidir on the same folds" in out
    assert "viewing directions std" in out
    # the file keeps what the run printed: RMS, held-out figures, ray uncertainty (issue 18)
    verdict = omnicam.formats.calibration_file.read_verdict(tmp_path / "rig.yaml")
    assert (verdict.method, verdict.K_source, verdict.forced) == ("chessboard", "chessboard", False)
    assert f"RMS {verdict.rms_px:.3f} px" in out
    held = f"median {verdict.heldout_median_px:.3f} px, max {verdict.heldout_max_px:.3f} px"
    assert held in out and verdict.heldout_folds == 3
    assert f"viewing directions std {verdict.ray_std_deg[0]:.3f} deg" in out
    assert f"axis std {verdict.axis_std_deg:.3f} deg" in out
    assert main(["info", str(tmp_path / "rig.yaml")]) == 0
    info = capsys.readouterr().out
    assert "K from         fitted to the chessboards" in info
    assert f"corner RMS median {held[7:]} (3-fold)" in info
    assert f"viewing directions std {verdict.ray_std_deg[0]:.3f} deg" in info


def test_corners_from_another_tool_are_used_and_missing_ones_searched(views, tmp_path, capsys):
    corners = {}
    for i, path in enumerate(views):
        found = omnicam.detect_pattern(cv2.imread(path), PATTERN)
        corners[f"board{i}.png"] = found.corners.reshape(-1, 2).tolist()
    corners["board2.png"] = None
    (tmp_path / "c.json").write_text(json.dumps(corners))
    assert (
        _calibrate(
            views, tmp_path / "rig.yaml", "--corners", str(tmp_path / "c.json"), "--heldout", "0"
        )
        == 0
    )
    table = capsys.readouterr().out.split("found by")[1]
    rows = {line.split()[0]: line.split()[-1] for line in table.strip().splitlines()[:6]}
    assert rows["board0.png"] == "given" and rows["board2.png"] != "given"


def test_corners_as_npz_in_the_order_of_the_images(views, tmp_path, capsys):
    arrays = [omnicam.detect_pattern(cv2.imread(p), PATTERN).corners.reshape(-1, 2) for p in views]
    np.savez(tmp_path / "c.npz", *arrays)
    assert (
        _calibrate(
            views, tmp_path / "rig.yaml", "--corners", str(tmp_path / "c.npz"), "--heldout", "0"
        )
        == 0
    )
    assert capsys.readouterr().out.count(" given") == 6


@pytest.mark.parametrize(
    "content, words",
    [
        ({"board0.png": [[1.0, 2.0]] * 7}, "board0.png has 7 corners"),
        ({"other.png": None}, "'other.png' is not one of the IMAGES"),
        ({"board0.png": "x"}, "not (x, y) pairs"),
    ],
    ids=["count", "unknown image", "not pairs"],
)
def test_a_bad_corners_file_is_one_line_and_writes_nothing(views, tmp_path, capsys, content, words):
    (tmp_path / "c.json").write_text(json.dumps(content))
    assert _calibrate(views, tmp_path / "rig.yaml", "--corners", str(tmp_path / "c.json")) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0]
    assert not (tmp_path / "rig.yaml").exists()


def test_starts_for_K_are_honoured_or_refused(views, tmp_path, capsys):
    assert _calibrate(views, tmp_path / "a.yaml", "--fx", "300") == 2
    assert "--fx --fy --cx --cy go together" in capsys.readouterr().err
    assert _calibrate(views, tmp_path / "a.yaml", "--dist", "0", "0", "0", "0") == 2
    assert "--dist is a start for D" in capsys.readouterr().err
    assert _calibrate(views, tmp_path / "a.yaml", "--heldout", "1") == 2
    K = RIG.K
    start = ["--fx", f"{K[0, 0] * 1.05}", "--fy", f"{K[1, 1] * 1.05}", "--cx", "350", "--cy", "350"]
    assert _calibrate(views, tmp_path / "b.yaml", *start, "--heldout", "0") == 0
    cam = omnicam.MisalignedHyperbolicCamera.load(str(tmp_path / "b.yaml"))
    assert abs(cam.K[0, 0] / K[0, 0] - 1.0) < 0.02


def test_boards_all_on_one_side_exit_one_unless_forced(tmp_path, capsys):
    poses = boards.random_board_poses(
        RIG,
        4,
        PATTERN,
        SQUARE,
        distance=(350.0, 600.0),
        max_tilt_deg=30.0,
        rng=5,
        azimuth=(10.0, 80.0),
    )
    paths = _render(tmp_path, poses)
    assert _calibrate(paths, tmp_path / "rig.yaml", "--heldout", "0") == 1
    err = capsys.readouterr().err
    assert "all on one side" in err.strip().splitlines()[-1]
    assert not (tmp_path / "rig.yaml").exists()
    assert _calibrate(paths, tmp_path / "rig.yaml", "--heldout", "0", "--force") == 0
    assert (tmp_path / "rig.yaml").exists()
    # forced, and why
    verdict = omnicam.formats.calibration_file.read_verdict(tmp_path / "rig.yaml")
    assert verdict.forced and "all boards are on one side" in verdict.implausible[0]
    assert verdict.doubts()[0] == "forced past 1 implausibility warning"


@pytest.mark.parametrize(
    "option",
    [
        ["--square", "30"],
        ["--corners", "c.json"],
        ["--heldout", "5"],
        ["--dist-model", "k1"],
        ["--rim-radius", "30"],
        ["--refine-mirror-shape"],
    ],
    ids=lambda o: o[0],
)
def test_chessboard_options_without_chessboard_are_refused_not_ignored(tmp_path, capsys, option):
    args = ["calibrate", str(tmp_path / "a.png"), *MIRROR, "--fx", "300", "--fy", "300"]
    args += ["--cx", "350", "--cy", "350", "-o", str(tmp_path / "r.yaml"), *option]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{option[0]} is an option of --chessboard mode" in err[0]


def test_the_reflections_plane_is_honoured_and_its_radius_refused(views, tmp_path, capsys):
    """The boards' renders show the lens barrel's front circle (r, z) = (15, 25): with
    --lens-z its outline joins the fit, without it the run says why it does not; --lens-r is
    for one image (chessboard mode fits the radius)."""
    assert _calibrate(views, tmp_path / "a.yaml", "--heldout", "0") == 0
    assert "camera's reflection: not used: its plane is unknown" in capsys.readouterr().out
    assert _calibrate(views, tmp_path / "b.yaml", "--heldout", "0", "--lens-z", "25") == 0
    assert "camera's reflection: used: " in capsys.readouterr().out
    without, with_plane = (
        omnicam.formats.calibration_file.read_verdict(tmp_path / f"{n}.yaml") for n in "ab"
    )
    assert with_plane.axis_std_deg < 0.5 * without.axis_std_deg  # it pins the tilt
    cam = omnicam.MisalignedHyperbolicCamera.load(str(tmp_path / "b.yaml"))
    assert posture_error(cam, RIG)[0] < 3.0 * with_plane.axis_std_deg
    assert _calibrate(views, tmp_path / "c.yaml", "--lens-r", "15", "--lens-z", "25") == 2
    assert "--lens-r is for one image" in capsys.readouterr().err
    assert not (tmp_path / "c.yaml").exists()


def test_an_implausible_chessboard_calibration_is_refused_as_one_from_one_image(
    views, tmp_path, capsys
):
    """One set of limits (issue 29 item 1): the rig's mirror axis leans 3 deg, so with
    --max-tilt 1 the plausibility checks of one image refuse it: exit 1 and no file, unless
    --force, whose file records the finding."""
    calib = tmp_path / "rig.yaml"
    assert _calibrate(views, calib, "--heldout", "0", "--max-tilt", "1") == 1
    cap = capsys.readouterr()
    assert "verdict: REFUSED: 1 implausible finding" in cap.out
    assert "implausible: the mirror axis is tilted" in cap.err and "(limit 1 deg" in cap.err
    assert "not written" in cap.err.strip().splitlines()[-1] and not calib.exists()
    assert _calibrate(views, calib, "--heldout", "0", "--max-tilt", "1", "--force") == 0
    verdict = omnicam.read_verdict(calib)
    assert verdict.forced and "tilted" in verdict.implausible[0]
    assert omnicam.load_camera(calib).verdict == verdict
    capsys.readouterr()
    assert _calibrate(views, tmp_path / "ok.yaml", "--heldout", "0") == 0  # default limits
    assert "verdict: " in capsys.readouterr().out
    assert not omnicam.read_verdict(tmp_path / "ok.yaml").implausible


def test_the_report_leads_with_the_rays_the_heldout_check_and_the_verdict(views, tmp_path, capsys):
    """What users use first (issue 29 item 2), right after the line per image."""
    assert _calibrate(views, tmp_path / "rig.yaml", "--heldout", "3") == 0
    out = capsys.readouterr().out.splitlines()
    first = [ln for ln in out if not ln.startswith("[")][:3]
    assert first[0].startswith("viewing directions known to ")
    assert first[1].startswith("held-out corner RMS (3-fold") and "cv2.omnidir" in first[1]
    assert first[2].startswith("verdict: ")


def test_an_unscaled_calibration_of_a_good_rig_raises_no_alarm_about_fx(tmp_path, capsys):
    """Without --mirror the scale and fx against the mirror's size are unknown by nature: a
    neutral line says so, no warning (issue 29 item 2). A rig close to the design, 10 views."""
    good = synthetic.misaligned_rig(1.0, 30.0, (0.5, -0.5, 0.5), image_size=SIZE)
    poses = boards.random_board_poses(
        good, 10, PATTERN, SQUARE, distance=(350.0, 700.0), max_tilt_deg=40.0, rng=11
    )
    paths = []
    for i, p in enumerate(poses):
        paths.append(str(tmp_path / f"good{i}.png"))
        cv2.imwrite(paths[-1], boards.render_board(good, PATTERN, SQUARE, *p, supersample=2))
    args = ["calibrate", "--chessboard", "7x5", "--square", "60", *paths, "--heldout", "0"]
    assert main([*args, "--dist-model", "none", "-o", str(tmp_path / "rig.yaml")]) == 0
    cap = capsys.readouterr()
    assert "focal length" not in cap.err and "fx" not in cap.err and "scale" not in cap.err
    assert "by nature, boards alone do not fix fx and the mirror's size separately" in cap.out
    assert "nor the scale, without --rim-radius" in cap.out
    assert not PYTHON_NAMES.search(cap.out + cap.err)  # options, not parameters (item 7)
    verdict = omnicam.read_verdict(tmp_path / "rig.yaml")
    assert any("scale is assumed" in n for n in verdict.notes)
    assert not any("focal length" in w or "scale" in w for w in verdict.warnings)


@pytest.mark.parametrize(
    "extra",
    [
        ["--chessboard", "9x8"],  # no board: the library says the mirror's (a, b, rim_radius)
        ["--chessboard", "9x8", *MIRROR],  # no board: the library says pattern_size
        ["--refine-mirror-shape", "--force"],  # the notes name refine_mirror_shape, rim_radius
    ],
    ids=["no-start", "no-board", "notes"],
)
def test_the_command_line_names_options_not_python_parameters(views, tmp_path, capsys, extra):
    """Library messages reaching the command line say --chessboard, --rim-radius, --lens-z,
    --refine-mirror-shape (cli/_common.py OPTION_OF), not the parameters' names."""
    args = ["calibrate", "--chessboard", "7x5", "--square", "60", *views, "--heldout", "0"]
    main([*args, "--dist-model", "none", "-o", str(tmp_path / "rig.yaml"), *extra])
    cap = capsys.readouterr()
    assert not PYTHON_NAMES.search(cap.out + cap.err), PYTHON_NAMES.search(cap.out + cap.err)
    said = cap.out + cap.err
    if "9x8" in extra:
        assert ("--chessboard" if "--mirror" in extra else "--mirror A B RIM") in cap.err
    else:
        assert "--lens-z" in said and "--rim-radius" in said


def test_progress_lines_on_stderr_for_the_long_steps_and_quiet_silences_them(
    views, tmp_path, capsys
):
    """Issue 29 item 3: the adjustment's evaluations and cost, each held-out fold; -q: none."""
    assert _calibrate(views, tmp_path / "rig.yaml", "--heldout", "2") == 0
    err = capsys.readouterr().err.splitlines()
    adjust = [ln for ln in err if ln.startswith("omnicam: adjustment of ")]
    assert adjust and all("evaluations in" in ln and "cost" in ln for ln in adjust[-1:])
    assert "omnicam: held-out check: fold 1/2, the rig calibrated on 3 views" in err
    assert "omnicam: held-out check: fold 2/2, the rig calibrated on 3 views" in err
    assert _calibrate(views, tmp_path / "q.yaml", "--heldout", "2", "-q") == 0
    cap = capsys.readouterr()
    assert "adjustment of" not in cap.err and "held-out check: fold" not in cap.err
    assert "[1/6]" not in cap.out


def test_the_library_is_silent_by_default_and_reports_through_progress(views):
    heard = []
    images = [cv2.imread(p) for p in views]
    cam, report = omnicam.calibrate_pattern(
        images,
        PATTERN,
        SQUARE,
        RIG.mirror,
        dist_model="none",
        heldout=2,
        progress=lambda i, text: heard.append((i, text)),
    )
    steps = [t for i, t in heard if i is None]
    assert any(t.startswith("adjustment of ") for t in steps)
    assert sum(t.startswith("held-out check: fold") for t in steps) == 2
    assert [i for i, _ in heard if i is not None] == list(range(6))
    # str(report) leads with what users use; the camera carries the report's verdict
    lead = str(report).splitlines()[1:4]
    assert lead[0].strip().startswith("viewing directions known to ")
    assert lead[1].strip().startswith("held-out corner RMS (2-fold")
    assert lead[2].strip().startswith("verdict: ") and cam.verdict == report.verdict()


def test_a_chessboard_calibration_records_the_cameras_reflection_for_default_panoramas(
    views, tmp_path
):
    """The renders show the lens barrel's reflection: without --lens-z it takes no part in the
    fit, but the file records its circle, so a default panorama starts above the lens
    (issue 29 item 6), as after a calibration from one image."""
    out = tmp_path / "rig.yaml"
    assert _calibrate(views, out, "--heldout", "0") == 0
    cam = omnicam.load_camera(out)
    assert cam.camera_reflection is not None
    band = omnicam.default_elevation_range(cam)
    assert band.lower_edge in (omnicam.views.LOWER_EDGE_REFLECTION, omnicam.views.LOWER_EDGE_FLOOR)
    # the lens's reflection lies below the band: its outline's rays point lower
    r, z = cam.camera_reflection
    phi = np.linspace(0, 2 * np.pi, 36, endpoint=False)
    ring = np.stack([r * np.cos(phi), r * np.sin(phi), np.full_like(phi, z)], axis=1)
    X = (ring - cam.tvec) @ cam.R  # camera frame -> mirror frame
    pixels = cam.project(X)
    _, d = cam.unproject(pixels[np.isfinite(pixels).all(axis=1)])
    elevation = np.degrees(np.arcsin(d[:, 2]))
    assert np.nanmax(elevation) <= band.lo + 1e-6
