"""Messages that name the thing and what to do (issue: a newcomer's first hour, item 8)."""

import os
import subprocess
import sys
import warnings

import cv2
import numpy as np
import pytest

from omnicam import MisalignedHyperbolicCamera, read_verdict, synthetic
from omnicam.camera import scale_K
from omnicam.stream import Unwarper
from omnicam.views import PanoramaView, PerspectiveView, rotation_from_ypr

VIEWS = {"pano": PanoramaView((64, 16))}


@pytest.fixture(scope="module")
def unwarper():
    return Unwarper.from_camera(synthetic.misaligned_rig(), VIEWS)


@pytest.mark.parametrize("dtype", [np.bool_, np.int8, np.int32, np.float16, np.complex64])
def test_a_frame_of_a_dtype_remap_does_not_take_is_a_value_error_naming_it(unwarper, dtype):
    w, h = unwarper.source_size
    with pytest.raises(ValueError, match=f"frame has dtype {np.dtype(dtype)}"):
        unwarper(np.zeros((h, w), dtype))


def test_a_reader_that_goes_away_ends_the_command_quietly():
    info = [sys.executable, "-m", "omnicam", "info", "calib_files/hyperomni_aligned.yaml"]
    with subprocess.Popen(info, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=REPO) as p:
        p.stdout.close()  # as `| head -1` does once it has its line
        err = p.stderr.read().decode()
        assert p.wait() in (0, 141)
    assert "Error" not in err and "unexpected" not in err, err


def test_out_of_memory_is_one_line_with_advice(monkeypatch, capsys):
    from omnicam import cli

    def huge(args):
        raise MemoryError

    monkeypatch.setattr(cli.info, "cmd_info", huge)
    assert cli.main(["info", "calib_files/hyperomni_aligned.yaml"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "out of memory" in err[0] and "smaller" in err[0]


REPO = __file__.rsplit("/tests/", 1)[0]
CALIB = os.path.join(REPO, "calib_files", "hyperomni_misaligned.yaml")


def test_an_export_whose_own_error_is_large_warns_on_one_line_naming_the_better_format(
    tmp_path, capsys
):
    from omnicam.cli import main

    assert (
        main(
            [
                "export",
                "calib_files/hyperomni_misaligned.yaml",
                "--to",
                "ocamcalib",
                "-o",
                str(tmp_path / "oc.txt"),
            ]
        )
        == 0
    )
    captured = capsys.readouterr()
    assert captured.out.startswith(f"wrote {tmp_path / 'oc.txt'} (ocamcalib): world2cam RMS")
    warning = [line for line in captured.err.splitlines() if "warning" in line]
    assert len(warning) == 1  # the sample misaligned rig: 2.3 px RMS in OCamCalib's model
    assert "fits this camera best is omnidir" in warning[0] and "omnicam maps" in warning[0]


def test_an_output_under_a_file_says_it_is_a_file_not_a_missing_folder(tmp_path, capsys):
    from omnicam.cli import main

    (tmp_path / "notes.txt").write_text("x")
    out = tmp_path / "notes.txt" / "rig.yaml"
    assert (
        main(["export", "calib_files/hyperomni_aligned.yaml", "--to", "omnidir", "-o", str(out)])
        == 1
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "notes.txt is a file, not a folder" in err[0], err


def test_a_calibration_file_that_cannot_be_written_is_said_once(tmp_path, capsys):
    from omnicam.cli._common import CliError, save_calibration

    cam = synthetic.misaligned_rig()
    with pytest.raises(CliError) as e:
        save_calibration(cam, str(tmp_path / "missing" / "rig.yaml"), True)
    assert str(e.value).count("cannot write") == 1, str(e.value)


# -- files: what cv2.FileStorage writes is read; every refusal names the file and the field ----
def _opencv_json(path, rim_radius=30.0, K=None, confidence=0.5):
    """A calibration file written by cv2.FileStorage itself (JSON), as a user's script would."""
    cam = synthetic.misaligned_rig()
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_FORMAT_JSON)
    fs.write("format_version", 1)
    fs.write("model", "misaligned_hyperbolic")
    fs.startWriteStruct("mirror", cv2.FILE_NODE_MAP)
    for name, value in (("a", cam.mirror.a), ("b", cam.mirror.b), ("rim_radius", rim_radius)):
        fs.write(name, value)
    fs.endWriteStruct()
    fs.write("K", cam.K if K is None else K)
    fs.write("rvec", cam.rvec.reshape(3, 1))
    fs.write("tvec", cam.tvec.reshape(3, 1))
    fs.startWriteStruct("verdict", cv2.FILE_NODE_MAP)
    fs.write("confidence", confidence)
    fs.endWriteStruct()
    fs.release()
    return cam


def test_a_json_file_opencv_wrote_with_a_nan_where_nan_means_unknown_is_read(tmp_path):
    path = tmp_path / "cv.json"
    cam = _opencv_json(path, confidence=float("nan"))
    assert ".Nan" in path.read_text()  # OpenCV's spelling, which is not JSON
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)  # and OpenCV reads it back
    assert np.isnan(fs.getNode("verdict").getNode("confidence").real())
    fs.release()
    assert MisalignedHyperbolicCamera.load(path) == cam.replace(image_size=None)
    assert read_verdict(path).confidence is None  # NaN: unknown, as the verdict says


K_BAD = synthetic.misaligned_rig().K.copy()
K_BAD[0, 2] = np.inf


@pytest.mark.parametrize(
    "kw, field, token",
    [
        ({"rim_radius": float("nan")}, "'mirror.rim_radius'", ".Nan"),
        ({"rim_radius": float("inf")}, "'mirror.rim_radius'", ".Inf"),
        ({"K": -K_BAD}, "'K'", "-.Inf"),
    ],
)
def test_a_nan_or_inf_opencv_wrote_in_a_field_that_needs_a_number_names_the_field(
    tmp_path, kw, field, token
):
    path = tmp_path / "cv.json"
    _opencv_json(path, **kw)
    assert token in path.read_text()
    with pytest.raises(ValueError) as e:
        MisalignedHyperbolicCamera.load(path)
    message = str(e.value)
    assert str(path) in message and f"field {field} must be finite" in message, message
    assert "not valid JSON" not in message


def _json_lines(text, field, value):
    """``text`` (a saved JSON calibration file) with ``field``'s first number replaced."""
    head, tail = text.split(f'"{field}"', 1)
    i = next(i for i, ch in enumerate(tail) if ch.isdigit() or ch == "-")
    j = i + next(k for k, ch in enumerate(tail[i:]) if ch in ",\n ]}")
    return head + f'"{field}"' + tail[:i] + value + tail[j:]


@pytest.mark.parametrize(
    "ext, edit, words",
    [
        (".json", lambda t: _json_lines(t, "format_version", "1" * 5000), "format_version"),
        (".json", lambda t: _json_lines(t, "data", "9" * 5000), "field 'K'"),
        (
            ".yaml",
            lambda t: t.replace("format_version: 1", "format_version: 1" + "0" * 30),
            "field 'format_version'",
        ),
        (
            ".json",
            lambda t: t.replace('"model"', '"deep": ' + "[" * 40 + "]" * 40 + ', "model"'),
            "field 'deep'",
        ),
        (
            ".yaml",
            lambda t: t.replace("rvec:", "deep: " + "[" * 40 + "]" * 40 + "\nrvec:"),
            "field 'deep'",
        ),
        (
            ".xml",
            lambda t: t.replace("<rvec", "<deep>" + "<a>" * 40 + "</a>" * 40 + "</deep>\n<rvec"),
            "field 'deep'",
        ),
        (".json", lambda t: t.replace('"rows": 3,', '"rows": 3', 1), "field 'K'"),
    ],
    ids=[
        "json-int-5000-digits",
        "json-int-in-K",
        "yaml-int",
        "json-deep",
        "yaml-deep",
        "xml-deep",
        "json-syntax",
    ],
)
def test_a_refused_file_names_the_file_the_line_and_the_field(tmp_path, ext, edit, words):
    path = tmp_path / f"c{ext}"
    synthetic.misaligned_rig().save(path)
    text = path.read_text()
    new = edit(text)
    assert new != text
    path.write_text(new)
    with pytest.raises(ValueError) as e:
        MisalignedHyperbolicCamera.load(path)
    message = str(e.value)
    assert str(path) in message and words in message and "line " in message, message
    assert len(message) < 400 and "\n" not in message  # one line, never thousands of digits


@pytest.mark.parametrize("ext", [".yaml", ".xml", ".json"])
def test_text_that_is_not_utf8_names_the_line_the_byte_and_the_field(tmp_path, ext):
    path = tmp_path / f"c{ext}"
    synthetic.misaligned_rig().save(path)
    data = path.read_bytes()
    at = data.index(b"misaligned_hyperbolic") + 3
    path.write_bytes(data[:at] + b"\xe9" + data[at:])  # latin-1, say
    with pytest.raises(ValueError) as e:
        MisalignedHyperbolicCamera.load(path)
    line = data[:at].count(b"\n") + 1
    message = str(e.value)
    assert f"not UTF-8 text at line {line}, field 'model' (byte {at})" in message, message
    assert str(path) in message and "save it as UTF-8" in message


# -- complex numbers: refused by name, never cut to their real part ---------------------------
def _complex(value):
    return np.asarray(value, dtype=float).astype(complex)  # imaginary parts 0: numpy would cut


def _calibrate(**kw):
    cam = synthetic.misaligned_rig()
    args = dict(
        K=cam.K,
        mirror=cam.mirror,
        boundary_points=cam.rim_image_points(60),
        image_size=cam.image_size,
        refine=False,
    )
    args.update(kw)
    return MisalignedHyperbolicCamera.calibrate(**args)


_CAM = synthetic.misaligned_rig()
_P3 = np.array([[10.0, 5.0, 30.0], [0.0, 2.0, 31.0]])
COMPLEX_CASES = {
    "calibrate(boundary_points)": (
        "boundary_points",
        lambda: _calibrate(boundary_points=_complex(_CAM.rim_image_points(60))),
    ),
    "calibrate(rim_hint)": (
        "rim_hint",
        lambda: _calibrate(
            boundary_points=None,
            image=np.zeros((64, 64), np.uint8),
            image_size=None,
            rim_hint=_complex([32, 32, 20]),
        ),
    ),
    "calibrate(K)": ("K", lambda: _calibrate(K=_complex(_CAM.K))),
    "calibrate(D)": ("D", lambda: _calibrate(D=_complex([0.0] * 5))),
    "calibrate(far_lines)": (
        r"far_lines\[0\]",
        lambda: _calibrate(far_lines=[_complex(np.ones((4, 2)))]),
    ),
    "calibrate(max_tilt_deg)": ("max_tilt_deg", lambda: _calibrate(max_tilt_deg=np.complex128(10))),
    "Camera(tvec)": ("tvec", lambda: _CAM.replace(tvec=_complex(_CAM.tvec))),
    "mirror.normal": ("points", lambda: _CAM.mirror.normal(_complex(_P3))),
    "mirror.intersect": ("origins", lambda: _CAM.mirror.intersect(_complex(_P3), _P3)),
    "mirror.reflect": ("unit_normals", lambda: _CAM.mirror.reflect(_P3, _complex(_P3))),
    "mirror.surface_z": ("X", lambda: _CAM.mirror.surface_z(_complex([1.0]), [2.0])),
    "rotation_from_ypr": ("yaw", lambda: rotation_from_ypr(yaw=np.complex128(10))),
    "PerspectiveView(fov)": ("fov_deg", lambda: PerspectiveView((32, 16), fov=np.complex128(60))),
    "scale_K": ("K", lambda: scale_K(_complex(_CAM.K), (500, 500), (250, 250))),
}


@pytest.mark.parametrize("case", list(COMPLEX_CASES))
def test_complex_numbers_are_refused_naming_the_argument_not_cut_with_a_warning(case):
    name, call = COMPLEX_CASES[case]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a ComplexWarning would fail here, not pass
        with pytest.raises(ValueError, match=rf"^{name} must be .*complex"):
            call()


def test_the_mirror_reads_real_arrays_as_before():
    m = _CAM.mirror
    assert np.array_equal(m.normal(_P3), m.normal(_P3.tolist()))
    assert m.normal(_P3.astype(np.float32)).dtype == np.float64
    with pytest.raises(ValueError, match="points must be .*real numbers"):
        m.normal(np.ones((2, 3), bool))


# -- images and videos: the message says what the file is ---------------------------------------
@pytest.fixture(scope="module")
def jpeg():
    image = synthetic.render_environment(synthetic.misaligned_rig(), supersample=1, seed=1)
    ok, data = cv2.imencode(".jpg", image)
    assert ok
    return data.tobytes()


INPUTS = {  # name -> (file name, bytes, words of the one error line)
    "text as .txt": ("notes.txt", b"a note\nanother\n", "input {p} is a text file, not an image"),
    "text as .png": ("notes.png", b"a note\n", "cannot read image {p}: it is a text file"),
    "16-byte mp4": (
        "clip.mp4",
        bytes(range(16)),
        "input {p} is not a video OpenCV can open (16 bytes)",
    ),
    "16-byte mp4 header": (  # OpenCV's HEIF reader claims it: it is still no image
        "head.mp4",
        b"\0\0\0\x18ftypisom" + bytes(4),
        "input {p} is an MP4 or QuickTime video OpenCV cannot open (16 bytes): truncated or "
        "corrupt",
    ),
    "corrupt png": (
        "p.png",
        b"\x89PNG\r\n\x1a\n" + bytes(100),
        "cannot read image {p}: a PNG image OpenCV cannot decode (108 bytes)",
    ),
    "truncated jpeg": (
        "half.jpg",
        lambda jpeg: jpeg[: len(jpeg) // 2],
        "cannot read image {p}: a truncated JPEG",
    ),
}


@pytest.mark.parametrize("case", list(INPUTS))
@pytest.mark.parametrize("out", ["o.png", "o.avi"])
def test_unwarp_names_what_an_unusable_input_is(tmp_path, capsys, jpeg, case, out):
    from omnicam.cli import main

    name, data, words = INPUTS[case]
    path = tmp_path / name
    path.write_bytes(data(jpeg) if callable(data) else data)
    if out == "o.avi" and not name.endswith((".txt", ".mp4")):
        out = "o.png"  # an image input refuses a video output first: not this test's matter
    argv = ["unwarp", str(path), "-c", CALIB, "--panorama", "64x16", "-o", str(tmp_path / out)]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words.format(p=path) in err[0], err
    assert not (tmp_path / out).exists()


@pytest.mark.parametrize("name, what", [("in.png", "image"), ("in.mp4", "input")])
def test_an_unreadable_input_is_permission_denied_not_an_unknown_format(
    tmp_path, capsys, monkeypatch, name, what
):
    from omnicam import _validate
    from omnicam.cli import main

    path = tmp_path / name
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(100) if what == "image" else bytes(range(16)))

    def denied(file, *args, **kwargs):  # what open() does without read permission (as root
        if os.fspath(file) == str(path):  # chmod 000 is no obstacle, so it is simulated)
            raise PermissionError(13, "Permission denied", str(path))
        return open(file, *args, **kwargs)

    monkeypatch.setattr(_validate, "open", denied, raising=False)
    argv = ["unwarp", str(path), "-c", CALIB, "--panorama", "64x16", "-o", str(tmp_path / "o.png")]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"omnicam: error: cannot read {what} {path}: permission denied"], err


def test_a_truncated_jpeg_is_refused_and_one_with_data_after_its_end_is_read(tmp_path, jpeg):
    from omnicam.images import read_image

    whole = tmp_path / "whole.jpg"
    whole.write_bytes(jpeg)
    tail = tmp_path / "motion.jpg"  # as phones append a video after the picture
    tail.write_bytes(jpeg + bytes(range(256)) * 8)
    assert np.array_equal(read_image(tail), read_image(whole))
    for cut in (len(jpeg) // 10, len(jpeg) // 2, len(jpeg) - 2):
        part = tmp_path / f"cut{cut}.jpg"
        part.write_bytes(jpeg[:cut])
        assert cv2.imread(str(part)) is not None  # OpenCV itself says nothing
        with pytest.raises(ValueError, match=f"cut{cut}.jpg.*a truncated JPEG \\({cut} bytes"):
            read_image(part)


def _intrinsics(tmp_path):
    from omnicam import write_intrinsics

    cam = synthetic.misaligned_rig()
    path = tmp_path / "k.yaml"
    write_intrinsics(path, cam.K, None, cam.image_size)
    return str(path)


@pytest.mark.parametrize(
    "image, words",
    [
        (np.full((100, 800, 3), 90, np.uint8), "calibration of {p} failed: no ellipse found"),
        (np.full((800, 100, 3), 90, np.uint8), "calibration of {p} failed: no ellipse found"),
    ],
    ids=["8x-wide", "8x-tall"],
)
def test_calibrate_names_the_image_and_an_aspect_ratio_no_mirror_frame_has(
    tmp_path, capsys, image, words
):
    from omnicam.cli import main

    path = tmp_path / "strip.png"
    cv2.imwrite(str(path), image)
    argv = ["calibrate", str(path), "--mirror", "23.4", "28.1", "30"]
    argv += ["--intrinsics", _intrinsics(tmp_path), "-o", str(tmp_path / "c.yaml")]
    assert main(argv) == 1
    err = [ln for ln in capsys.readouterr().err.splitlines() if "error" in ln]
    h, w = image.shape[:2]
    assert len(err) == 1 and words.format(p=path) in err[0], err
    assert f"the image is {w}x{h} (8.0:1), no camera's frame of a mirror" in err[0]


def test_calibrate_refuses_a_truncated_jpeg_by_name(tmp_path, capsys, jpeg):
    from omnicam.cli import main

    path = tmp_path / "half.jpg"
    path.write_bytes(jpeg[: len(jpeg) // 2])
    argv = ["calibrate", str(path), "--mirror", "23.4", "28.1", "30"]
    argv += ["--intrinsics", _intrinsics(tmp_path), "-o", str(tmp_path / "c.yaml")]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"cannot read image {path}: a truncated JPEG" in err[0], err
    assert not (tmp_path / "c.yaml").exists()


def test_an_odd_sized_video_output_names_the_file_its_size_and_an_even_one(
    tmp_path, capsys, monkeypatch
):
    from omnicam.cli import main, unwarp

    def no_tables(*args, **kwargs):
        raise AssertionError("the size is refused before the tables are built")

    monkeypatch.setattr(unwarp.Unwarper, "from_camera", no_tables)

    src = tmp_path / "in.avi"
    writer = cv2.VideoWriter(str(src), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (64, 64))
    for _ in range(2):
        writer.write(np.zeros((64, 64, 3), np.uint8))
    writer.release()
    out = tmp_path / "o.mp4"
    argv = ["unwarp", str(src), "-c", CALIB, "--panorama", "63x16", "-o", str(out), "--quiet"]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert f"cannot write video {out} at 63x16" in err[0] and "give 64x16" in err[0], err
    assert "'0'" not in err[0]  # the view's internal key means nothing to the user
    assert sorted(os.listdir(tmp_path)) == ["in.avi"]


def test_a_video_opencv_cannot_open_is_named_with_its_size(tmp_path):
    from omnicam.video import open_capture

    path = tmp_path / "clip.mp4"
    path.write_bytes(bytes(16))
    with pytest.raises(ValueError, match=r"clip.mp4: not a video OpenCV can open \(16 bytes\)"):
        open_capture(str(path))


def test_complex_rim_points_and_hints_are_refused_by_name():
    from omnicam import calibrate_pattern, detect_rim

    image = np.random.default_rng(0).integers(0, 255, (64, 64), dtype=np.uint8)
    with pytest.raises(ValueError, match="hint .*complex"):
        detect_rim(image, hint=(32 + 1j, 32, 20))
    rim = np.c_[np.cos(np.arange(12)), np.sin(np.arange(12))] * 20 + 32 + 0.5j
    with pytest.raises(ValueError, match="boundary_points .*complex"):
        calibrate_pattern(
            None,
            (6, 7),
            30.0,
            image_points=[np.zeros((42, 2))] * 3,
            boundary_points=rim,
            image_size=(64, 64),
            K=np.array([[50.0, 0, 32], [0, 50, 32], [0, 0, 1]]),
        )
