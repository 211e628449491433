"""``omnicam calibrate``: rim hints, boundary points, plausibility limits and --force."""

from __future__ import annotations

import json
import re

import cv2
import numpy as np
import pytest
from conftest import white_holder_render

from omnicam import MisalignedHyperbolicCamera, synthetic
from omnicam.calibration.rim import fit_rim
from omnicam.camera import scale_K
from omnicam.cli import main

SIZE = (320, 240)
MIRROR = ["--mirror", "23.4", "28.1", "30"]


def write_K(path, K, image_size=None):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("K", np.asarray(K, np.float64))
    if image_size is not None:
        fs.startWriteStruct("image_size", cv2.FileNode_SEQ)
        for v in image_size:
            fs.write("", int(v))
        fs.endWriteStruct()
    fs.release()
    return str(path)


def error_line(err):
    """The one error line of a failed command (warnings may come before it)."""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err
    errors = [ln for ln in lines if ln.startswith("omnicam: error: ")]
    assert len(errors) == 1 and lines[-1] == errors[0], err
    assert all(ln.startswith("omnicam: ") for ln in lines), err
    return errors[0]


def axis_error_deg(cam, truth):
    return float(np.degrees(np.arccos(np.clip(cam.R[:, 2] @ truth.R[:, 2], -1.0, 1.0))))


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cli-calibrate")
    truth = synthetic.misaligned_rig(3.0, 30.0, (1.5, -1.0, 1.0), image_size=SIZE)
    image = folder / "mirror.png"
    cv2.imwrite(str(image), synthetic.render_environment(truth, seed=1))
    tilted = synthetic.misaligned_rig(12.0, 100.0, (1.0, 0.5, 0.0), image_size=SIZE, fill=0.7)
    tilted_image = folder / "tilted.png"
    cv2.imwrite(str(tilted_image), synthetic.render_environment(tilted, seed=2))
    return {
        "truth": truth,
        "image": str(image),
        "k": write_K(folder / "k.yaml", truth.K),
        "tilted": tilted,
        "tilted_image": str(tilted_image),
        "tilted_k": write_K(folder / "tk.yaml", tilted.K),
    }


def run(image, k, out, *extra):
    return main(["calibrate", image, *MIRROR, "--intrinsics", k, "-o", str(out), *extra])


def test_good_rig_exits_zero_and_writes_the_calibration(scene, tmp_path, capsys):
    calib = tmp_path / "calib.yaml"
    code = run(scene["image"], scene["k"], calib)
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "implausible" not in captured.err
    assert axis_error_deg(MisalignedHyperbolicCamera.load(calib), scene["truth"]) < 0.2


def test_implausible_result_exits_one_and_writes_no_calibration(scene, tmp_path, capsys):
    """K for twice the resolution (the file gives no image_size, so nothing rescales it)."""
    k2 = write_K(tmp_path / "k2.yaml", scale_K(scene["truth"].K, SIZE, (640, 480)))
    calib = tmp_path / "calib.yaml"
    code = run(scene["image"], k2, calib)
    captured = capsys.readouterr()
    assert code == 1
    err = error_line(captured.err)
    assert "implausible" in err and "--force" in err and "not written" in err
    assert "omnicam: warning: implausible: the rim found has semi-axes" in captured.err
    assert "another resolution" in captured.err
    assert not calib.exists()
    # the overlay shows what went wrong, under a name that does not block the next attempt
    assert "calib_overlay_refused.png" in err
    assert (tmp_path / "calib_overlay_refused.png").is_file()
    assert not (tmp_path / "calib_overlay.png").exists()
    assert "omnicam mirror posture calibration" in captured.out  # the report is printed too
    assert "mirror: assumed the hyperboloid a " in captured.out  # one image cannot tell its shape


def test_force_writes_an_implausible_calibration_with_the_warnings(scene, tmp_path, capsys):
    k2 = write_K(tmp_path / "k2.yaml", scale_K(scene["truth"].K, SIZE, (640, 480)))
    calib = tmp_path / "calib.yaml"
    code = run(scene["image"], k2, calib, "--force")
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "omnicam: warning: implausible:" in captured.err
    assert calib.is_file()


def test_a_and_b_swapped_exit_one(scene, tmp_path, capsys):
    calib = tmp_path / "calib.yaml"
    code = main(
        [
            "calibrate",
            scene["image"],
            "--mirror",
            "28.1",
            "23.4",
            "30",
            "--intrinsics",
            scene["k"],
            "-o",
            str(calib),
        ]
    )
    captured = capsys.readouterr()
    assert code == 1 and not calib.exists()
    assert "a and b swapped (a = 23.4, b = 28.1)" in captured.err
    error_line(captured.err)


def test_max_tilt_and_max_offset_set_the_limits(scene, tmp_path, capsys):
    """A rig tilted 12 deg: refused by default, accepted with --max-tilt 15."""
    calib = tmp_path / "calib.yaml"
    code = run(scene["tilted_image"], scene["tilted_k"], calib)
    captured = capsys.readouterr()
    assert code == 1 and not calib.exists()
    assert re.search(r"tilted 1[12]\.\d deg from the optical axis \(limit 10 deg", captured.err)
    code = run(scene["tilted_image"], scene["tilted_k"], calib, "--max-tilt", "15", "--overwrite")
    captured = capsys.readouterr()
    assert code == 0, captured.err
    cam = MisalignedHyperbolicCamera.load(calib)
    assert axis_error_deg(cam, scene["tilted"]) < 0.3
    code = run(
        scene["tilted_image"],
        scene["tilted_k"],
        calib,
        "--max-tilt",
        "15",
        "--max-offset",
        "0.5",
        "--overwrite",
    )
    captured = capsys.readouterr()
    assert code == 1 and "(limit 0.5, mirror units)" in captured.err


def test_rim_hint_finds_the_rim_inside_a_white_holder(tmp_path, capsys):
    img, truth = white_holder_render(320, 104, 134)
    cv2.imwrite(str(tmp_path / "holder.png"), img)
    k = write_K(tmp_path / "k.yaml", truth.K)
    rim = fit_rim(truth.rim_image_points(720), robust=False)
    hint = f"{rim.center[0] + 4:.1f},{rim.center[1] - 3:.1f},{rim.axes.mean() * 0.97:.1f}"
    calib = tmp_path / "calib.yaml"
    code = run(str(tmp_path / "holder.png"), k, calib, "--rim-hint", hint)
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert axis_error_deg(MisalignedHyperbolicCamera.load(calib), truth) < 0.3
    # the hint names the circle: at the holder's outer edge the result is refused
    code = run(
        str(tmp_path / "holder.png"),
        k,
        tmp_path / "edge.yaml",
        "--rim-hint",
        f"{rim.center[0]:.1f},{rim.center[1]:.1f},134",
    )
    captured = capsys.readouterr()
    assert code == 1 and "the rim found has semi-axes 13" in captured.err
    assert not (tmp_path / "edge.yaml").exists()


@pytest.mark.parametrize(
    "hint, status, words",
    [
        ("900,100,50", 1, "--rim-hint: hint centre (900, 100) is outside the 320x240 image"),
        ("100,100,0", 2, "positive R"),
        ("100,100", 2, "expected CX,CY,R"),
        ("a,b,c", 2, "expected CX,CY,R"),
        ("nan,1,2", 2, "finite"),
    ],
)
def test_bad_rim_hint_is_one_line_and_writes_nothing(scene, tmp_path, capsys, hint, status, words):
    code = run(scene["image"], scene["k"], tmp_path / "calib.yaml", "--rim-hint", hint)
    assert code == status
    assert words in error_line(capsys.readouterr().err)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("fmt", ["json", "yaml", "xml"])
def test_boundary_points_from_json_or_filestorage(scene, tmp_path, capsys, fmt):
    truth = scene["truth"]
    pts = truth.rim_image_points(200)
    pts = pts[
        (pts[:, 0] > 0) & (pts[:, 0] < SIZE[0] - 1) & (pts[:, 1] > 0) & (pts[:, 1] < SIZE[1] - 1)
    ]
    path = tmp_path / f"rim.{fmt}"
    if fmt == "json":
        path.write_text(json.dumps(pts.tolist()))
    else:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
        fs.write("boundary_points", pts)
        fs.release()
    calib = tmp_path / "calib.yaml"
    code = run(scene["image"], scene["k"], calib, "--boundary-points", str(path))
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert f"{len(pts)} boundary points" in captured.out
    assert axis_error_deg(MisalignedHyperbolicCamera.load(calib), truth) < 0.2


BAD_POINTS = {
    "missing": (None, "does not exist"),
    "not json": ("[[1, 2], ", "not valid JSON"),
    "not pairs": ("[[1, 2, 3], [4, 5, 6]]", "list of [x, y] pixels"),
    "too few": ("[[1, 2], [3, 4], [5, 6]]", "at least 6"),
    "a number": ("42", "list of [x, y] pixels"),
    "filestorage without the field": ('{"points_elsewhere": 1}', "'boundary_points'"),
}


@pytest.mark.parametrize("content, words", BAD_POINTS.values(), ids=BAD_POINTS.keys())
def test_bad_boundary_points_file_is_one_line_and_writes_nothing(
    scene, tmp_path, capsys, content, words
):
    path = tmp_path / "rim.json"
    if content is not None:
        path.write_text(content)
    before = sorted(p.name for p in tmp_path.iterdir())
    code = run(scene["image"], scene["k"], tmp_path / "calib.yaml", "--boundary-points", str(path))
    assert code == 1
    line = error_line(capsys.readouterr().err)
    assert words in line and "rim.json" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_photo_without_a_mirror_exits_one(tmp_path, capsys):
    skdata = pytest.importorskip("skimage.data")
    cup = np.ascontiguousarray(skdata.coffee()[:, :, ::-1])
    cv2.imwrite(str(tmp_path / "cup.png"), cup)
    h, w = cup.shape[:2]
    m = synthetic.default_mirror()
    f = 0.5 * 0.85 * min(w, h) * (m.z_rim + m.c) / m.rim_radius
    k = write_K(tmp_path / "k.yaml", [[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]])
    code = run(str(tmp_path / "cup.png"), k, tmp_path / "calib.yaml")
    assert code == 1
    error_line(capsys.readouterr().err)
    assert not (tmp_path / "calib.yaml").exists()


def test_help_documents_the_new_options(capsys):
    assert main(["calibrate", "--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    for words in (
        "--rim-hint CX,CY,R",
        "--boundary-points FILE",
        "--max-tilt DEG",
        "--max-offset MM",
        "--force",
        "JSON list of [x, y] pixels",
        "'boundary_points'",
    ):
        assert words in out


def test_intrinsics_as_numbers_instead_of_a_file(tmp_path, capsys):
    """--fx --fy --cx --cy [--dist] stand for an intrinsics file."""
    from omnicam import synthetic

    truth = synthetic.misaligned_rig()
    image = tmp_path / "mirror.png"
    cv2.imwrite(str(image), synthetic.render_environment(truth, supersample=1))
    K = truth.K
    out = tmp_path / "rig.yaml"
    code = main(
        [
            "calibrate",
            str(image),
            "--mirror",
            str(truth.mirror.a),
            str(truth.mirror.b),
            str(truth.mirror.rim_radius),
            "--fx",
            repr(float(K[0, 0])),
            "--fy",
            repr(float(K[1, 1])),
            "--cx",
            repr(float(K[0, 2])),
            "--cy",
            repr(float(K[1, 2])),
            "-o",
            str(out),
            "--force",
        ]
    )
    assert code == 0, capsys.readouterr().err
    cam = MisalignedHyperbolicCamera.load(out)
    np.testing.assert_allclose(cam.K, K)
    assert cam.D is None
    code = main(
        [
            "calibrate",
            str(image),
            "--mirror",
            "28",
            "23",
            "30",
            "--fx",
            "400",
            "-o",
            str(tmp_path / "x.yaml"),
        ]
    )
    assert code == 2 and "--fx --fy --cx --cy" in capsys.readouterr().err


def test_one_image_without_mirror_says_to_give_it_or_use_chessboards(tmp_path, capsys):
    img = tmp_path / "m.png"
    cv2.imwrite(str(img), np.zeros((64, 64, 3), np.uint8))
    k = write_K(tmp_path / "k.yaml", [[50, 0, 31.5], [0, 50, 31.5], [0, 0, 1]])
    code = main(["calibrate", str(img), "--intrinsics", k, "-o", str(tmp_path / "c.yaml")])
    assert code == 2
    line = error_line(capsys.readouterr().err)
    assert "--mirror" in line and "--chessboard" in line
    assert not (tmp_path / "c.yaml").exists()


def test_rim_radius_is_refused_beside_a_mirror(tmp_path, capsys):
    img = tmp_path / "m.png"
    cv2.imwrite(str(img), np.zeros((64, 64, 3), np.uint8))
    args = ["calibrate", "--chessboard", "6x7", "--square", "30", str(img), *MIRROR]
    code = main([*args, "--rim-radius", "30", "-o", str(tmp_path / "c.yaml")])
    assert code == 2
    assert "--rim-radius" in error_line(capsys.readouterr().err)


# -- retrying, each warning once (issue 18 item 7) ------------------------------------
def test_a_refused_attempt_does_not_block_the_next_one(scene, tmp_path, capsys):
    """Refused: no calibration file, the overlay as calib_overlay_refused.png. The retry with
    the right K needs no --overwrite; a second refusal replaces the refused overlay."""
    k2 = write_K(tmp_path / "k2.yaml", scale_K(scene["truth"].K, SIZE, (640, 480)))
    calib = tmp_path / "calib.yaml"
    assert run(scene["image"], k2, calib) == 1
    capsys.readouterr()
    assert run(scene["image"], k2, calib) == 1  # again: the refused overlay is replaced
    error_line(capsys.readouterr().err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["calib_overlay_refused.png", "k2.yaml"]
    code = run(scene["image"], scene["k"], calib)
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert calib.is_file() and (tmp_path / "calib_overlay.png").is_file()


def test_each_implausibility_warning_is_printed_once(scene, tmp_path, capsys):
    """They were in the report's WARNINGS and again on stderr: now on stderr alone (they decide
    the refusal), the report keeping the others."""
    k2 = write_K(tmp_path / "k2.yaml", scale_K(scene["truth"].K, SIZE, (640, 480)))
    assert run(scene["image"], k2, tmp_path / "calib.yaml") == 1
    captured = capsys.readouterr()
    both = captured.out + captured.err
    found = [
        ln.split("implausible: ", 1)[1] for ln in captured.err.splitlines() if "implausible: " in ln
    ]
    assert len(found) >= 2, captured.err
    for w in found:
        assert both.count(w) == 1, w
    assert "no warnings" not in captured.out
    lines = [ln for ln in both.splitlines() if ln.strip()]
    assert len(lines) <= 25, both


# -- K guessed from the rim and the mirror (issue 18 item 5) -------------------------------------
def test_guessed_K_images_the_rim_where_it_was_found(scene):
    """guess_K is the aligned rig's K: expected_rim of it is the rim found (centre and size)."""
    from omnicam.calibration.plausibility import expected_rim, guess_K

    truth = synthetic.aligned_rig(image_size=SIZE)
    rim = fit_rim(truth.rim_image_points(720), robust=False)
    K = guess_K(rim, truth.mirror)
    np.testing.assert_allclose(K, truth.K, rtol=1e-6, atol=1e-6)
    m = synthetic.misaligned_rig(3.0, 30.0, (1.5, -1.0, 1.0), image_size=SIZE)
    rim = fit_rim(m.rim_image_points(720), robust=False)
    expected = expected_rim(guess_K(rim, m.mirror), m.mirror)
    np.testing.assert_allclose(expected.center, rim.center, atol=1e-6)
    assert expected.radius == pytest.approx(float(np.sqrt(np.prod(rim.axes))), rel=1e-3)


def test_guess_k_calibrates_an_aligned_rig_and_the_file_says_it_was_guessed(tmp_path, capsys):
    truth = synthetic.aligned_rig(image_size=SIZE)
    image = tmp_path / "aligned.png"
    cv2.imwrite(str(image), synthetic.render_environment(truth, seed=3))
    calib = tmp_path / "rig.yaml"
    code = main(["calibrate", str(image), *MIRROR, "--guess-k", "-o", str(calib), "--force"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert captured.out.startswith("K guessed: fx = fy = ")
    assert "with a guessed K" in captured.out.splitlines()[-1]
    cam = MisalignedHyperbolicCamera.load(calib)
    np.testing.assert_allclose(cam.K, truth.K, atol=0.1)  # measured: within 0.03 px
    from omnicam.formats.calibration_file import read_verdict

    verdict = read_verdict(calib)
    assert verdict.K_source == "guessed" and "rim's centre" in verdict.K_note
    assert main(["info", str(calib)]) == 0
    out = capsys.readouterr().out
    assert "GUESSED from the rim and the mirror" in out and "with a guessed K" in out


@pytest.mark.parametrize(
    "extra, words",
    [
        (["--fx", "400"], "--fx/--fy/--cx/--cy"),
        (["--intrinsics", "k.yaml"], "--intrinsics"),
        (["--dist", "0.1", "0", "0", "0"], "--dist"),
    ],
)
def test_guess_k_beside_intrinsics_is_refused(scene, tmp_path, capsys, extra, words):
    code = main(["calibrate", scene["image"], *MIRROR, "--guess-k", *extra, "-o", "x.yaml"])
    assert code == 2
    line = error_line(capsys.readouterr().err)
    assert "--guess-k" in line and words in line


def test_no_intrinsics_offers_the_guess(scene, tmp_path, capsys):
    code = main(["calibrate", scene["image"], *MIRROR, "-o", str(tmp_path / "x.yaml")])
    assert code == 2
    assert "--guess-k" in error_line(capsys.readouterr().err)


# -- the verdict travels with the file (issue 18 item 3) -----------------------------------------
def test_the_file_records_where_K_came_from_and_the_verdict(scene, tmp_path, capsys):
    from omnicam.formats.calibration_file import read_verdict

    calib = tmp_path / "calib.yaml"
    assert run(scene["image"], scene["k"], calib) == 0
    capsys.readouterr()
    v = read_verdict(calib)
    assert (v.method, v.K_source, v.K_file, v.forced) == ("image", "file", scene["k"], False)
    assert v.confidence is not None and v.axis_std_deg > 0 and v.origin_std_mm > 0
    # forced past implausible findings: recorded, and unwarp says it in one line
    k2 = write_K(tmp_path / "k2.yaml", scale_K(scene["truth"].K, SIZE, (640, 480)))
    forced = tmp_path / "forced.yaml"
    assert run(scene["image"], k2, forced, "--force") == 0
    capsys.readouterr()
    v = read_verdict(forced)
    assert v.forced and v.implausible and "another resolution" in " ".join(v.implausible)
    assert not set(v.implausible) & set(v.warnings)
    code = main(
        [
            "unwarp",
            scene["image"],
            "-c",
            str(forced),
            "--panorama",
            "256x64",
            "-o",
            str(tmp_path / "p.png"),
        ]
    )
    captured = capsys.readouterr()
    assert code == 0, captured.err
    doubt = [ln for ln in captured.err.splitlines() if "forced.yaml: calibrated" in ln]
    assert len(doubt) == 1 and "forced past" in doubt[0] and "omnicam info" in doubt[0]
    # a plain calibration: unwarp says only that it has warnings, if it has, in one line
    code = main(
        [
            "unwarp",
            scene["image"],
            "-c",
            str(calib),
            "--panorama",
            "256x64",
            "-o",
            str(tmp_path / "q.png"),
        ]
    )
    said = [ln for ln in capsys.readouterr().err.splitlines() if "calibrated" in ln]
    plain = read_verdict(calib)
    assert code == 0 and len(said) == (1 if plain.warnings else 0)
    assert not any("skewed" in ln for ln in said)


def test_from_an_earlier_guess_the_K_stays_guessed(tmp_path, capsys):
    """--from takes K from a file; when that file's K was guessed, the new one is too."""
    from omnicam.formats.calibration_file import read_verdict

    truth = synthetic.aligned_rig(image_size=SIZE)
    image = tmp_path / "aligned.png"
    cv2.imwrite(str(image), synthetic.render_environment(truth, seed=3))
    first, second = tmp_path / "rig.yaml", tmp_path / "again.yaml"
    assert main(["calibrate", str(image), *MIRROR, "--guess-k", "-o", str(first), "--force"]) == 0
    assert main(["calibrate", str(image), "--from", str(first), "-o", str(second), "--force"]) == 0
    capsys.readouterr()
    v = read_verdict(second)
    assert v.K_source == "guessed" and v.K_file == str(first)


def test_the_reflections_circle_given_is_honoured(tmp_path, capsys):
    """--lens-z and --lens-r reach the calibration: the file records the circle given (the
    barrel's front edge of tests/barrel.py, r = 9 at z = 12), and the tilt it pins is right."""
    import barrel

    rng = np.random.default_rng(5)
    truth = synthetic.random_misaligned_rig(rng, 5.0, 5.0)
    image = tmp_path / "barrel.png"
    cv2.imwrite(str(image), barrel.render(truth))
    m = truth.mirror
    k = write_K(tmp_path / "k.yaml", truth.K, truth.image_size)
    mirror = ["--mirror", f"{m.a!r}", f"{m.b!r}", f"{m.rim_radius!r}"]
    args = ["calibrate", str(image), *mirror, "--intrinsics", k, "--lens-z", "12", "--lens-r", "9"]
    code = main([*args, "-o", str(tmp_path / "c.yaml")])
    assert code == 0, capsys.readouterr().err
    cam = MisalignedHyperbolicCamera.load(tmp_path / "c.yaml")
    assert cam.camera_reflection == (9.0, 12.0)
    assert axis_error_deg(cam, truth) < 0.15
    assert main(["calibrate", str(image), "--lens-r", "0", "-o", str(tmp_path / "x.yaml")]) == 2
    assert "expected a positive number" in capsys.readouterr().err
