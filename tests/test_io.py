"""Calibration files: cv2.FileStorage round trips, strict validation, atomic saves."""

import os

import cv2
import numpy as np
import pytest
from conftest import RIGS

from omnicam import MisalignedHyperbolicCamera


@pytest.mark.parametrize("ext", [".yaml", ".yml", ".xml", ".json"])
@pytest.mark.parametrize("name", ["aligned", "misaligned", "skew", "rational"])
def test_save_load_round_trip_is_exact(tmp_path, ext, name):
    cam = RIGS[name]
    path = tmp_path / f"calib{ext}"
    cam.save(path)
    loaded = MisalignedHyperbolicCamera.load(path)
    assert loaded == cam
    text = path.read_text()
    assert "misaligned_hyperbolic" in text and "format_version" in text


def test_loaded_camera_is_in_the_gauge(tmp_path):
    cam = RIGS["misaligned"]
    path = tmp_path / "c.yaml"
    cam.save(path)
    # rewrite rvec with an extra spin about the mirror axis: same rig, other gauge
    spun = cv2.Rodrigues(cam.R @ cv2.Rodrigues(np.array([0.0, 0.0, 1.1]))[0])[0]
    path.write_text(
        path.read_text().replace(_yaml_matrix(cam.rvec.reshape(3, 1)), _yaml_matrix(spun))
    )
    assert "1.1" not in _yaml_matrix(cam.rvec.reshape(3, 1))
    np.testing.assert_allclose(MisalignedHyperbolicCamera.load(path).rvec, cam.rvec, atol=1e-12)


def _yaml_matrix(m):
    fs = cv2.FileStorage(".yaml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    fs.write("x", np.asarray(m, np.float64))
    text = fs.releaseAndGetString()
    return text.split("x:", 1)[1].strip()


def test_missing_file_raises_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.yaml"):
        MisalignedHyperbolicCamera.load(tmp_path / "nope.yaml")


def _saved(tmp_path, ext=".yaml"):
    path = tmp_path / f"c{ext}"
    RIGS["distorted"].save(path)
    return path, path.read_text()


@pytest.mark.parametrize(
    "edit, field",
    [
        (lambda t: "", "readable"),
        (lambda t: "{{{ not yaml", "readable"),
        (lambda t: t.replace("format_version: 1", "format_version: 7"), "format_version"),
        (lambda t: t.replace("format_version: 1", "format_version: one"), "format_version"),
        (lambda t: t.replace("misaligned_hyperbolic", "parabolic"), "model"),
        (lambda t: t.replace("   a: ", "   aa: "), "mirror.a"),
        (lambda t: t.replace("   b: ", "   b: -"), "mirror"),
        (lambda t: t.replace("rows: 3\n   cols: 3", "rows: 1\n   cols: 9"), None),
        (lambda t: t.replace("K: !!opencv-matrix", "Kx: !!opencv-matrix"), "'K'"),
        (lambda t: t.replace("K: !!opencv-matrix", "K: 3\nKold: !!opencv-matrix"), "'K'"),
        (lambda t: t.replace("data: [ 582.64687717031461,", "data: [ .nan,"), "finite"),
        (lambda t: t.replace("tvec:", "tvecs:"), "'tvec'"),
        (lambda t: t.replace("   - 500\n   - 500", "   - 500\n   - 0"), "image_size"),
        (lambda t: t.replace("   - 500\n   - 500", "   - 500"), "image_size"),
    ],
)
def test_malformed_file_raises_value_error_naming_file_and_field(tmp_path, edit, field):
    path, text = _saved(tmp_path)
    new = edit(text)
    assert new != text, "the edit must change the file"
    path.write_text(new)
    with pytest.raises(ValueError) as err:
        MisalignedHyperbolicCamera.load(path)
    assert str(path) in str(err.value)
    if field:
        assert field in str(err.value)


def test_distortion_of_wrong_length_in_file_is_rejected(tmp_path):
    path, text = _saved(tmp_path)
    new = text.replace("cols: 5", "cols: 3").replace("-0.12, 0.050000000000000003, 0.001,", "")
    assert "cols: 3\n   dt: d\n   data: [ -0.0015, -0.01 ]" not in text
    path.write_text(new.replace("[  -0.0015, -0.01 ]", "[ 0.1, -0.0015, -0.01 ]"))
    with pytest.raises(ValueError, match="'D'"):
        MisalignedHyperbolicCamera.load(path)


def test_unknown_extension_is_rejected(tmp_path):
    with pytest.raises(ValueError, match="extension"):
        RIGS["aligned"].save(tmp_path / "c.txt")
    with pytest.raises(ValueError, match="extension"):
        MisalignedHyperbolicCamera.load(tmp_path / "c.txt")


def test_failed_save_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    path = tmp_path / "c.yaml"
    RIGS["aligned"].save(path)
    before = path.read_bytes()
    real = cv2.FileStorage

    class Broken:
        def __init__(self, *args):
            self.fs = real(*args)

        def isOpened(self):
            return True

        def __getattr__(self, name):
            if name == "endWriteStruct":
                raise RuntimeError("disk full")
            return getattr(self.fs, name)

    import omnicam.formats.filestorage

    monkeypatch.setattr(omnicam.formats.filestorage.cv2, "FileStorage", Broken)
    with pytest.raises(RuntimeError, match="disk full"):
        RIGS["misaligned"].save(path)
    monkeypatch.undo()
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["c.yaml"]


def test_save_into_missing_folder_raises_value_error(tmp_path):
    with pytest.raises(ValueError, match="does not exist"):
        RIGS["aligned"].save(tmp_path / "no" / "c.yaml")


def test_saved_file_has_the_usual_permissions(tmp_path):
    umask = os.umask(0o022)
    try:
        RIGS["aligned"].save(tmp_path / "c.yaml")
    finally:
        os.umask(umask)
    assert (tmp_path / "c.yaml").stat().st_mode & 0o777 == 0o644


def test_intrinsics_file_round_trip(tmp_path):
    cam = RIGS["rational"]
    from omnicam.formats.intrinsics import read_intrinsics, write_intrinsics

    write_intrinsics(tmp_path / "k.json", cam.K, cam.D, cam.image_size)
    K, D, size = read_intrinsics(tmp_path / "k.json")
    np.testing.assert_array_equal(K, cam.K)
    np.testing.assert_array_equal(D, cam.D)
    assert size == cam.image_size


@pytest.mark.parametrize(
    "text, field",
    [
        ("%YAML:1.0\nD: [0.1, 0.2]\n", "'K'"),
        ("%YAML:1.0\nK: [1, 0, 0, 0, 1, 0, 0, 0, 1]\nD: [0.1, 0.2, 0.3]\n", "'D'"),
        ("%YAML:1.0\nK: [0, 0, 0, 0, 1, 0, 0, 0, 1]\n", "'K'"),
        ("%YAML:1.0\nK: [1, 0, 0, 0, 1, 0, 0, 0, 1]\nimage_size: [640]\n", "image_size"),
    ],
)
def test_bad_intrinsics_file_raises_value_error_naming_the_field(tmp_path, text, field):
    from omnicam.formats.intrinsics import read_intrinsics

    path = tmp_path / "k.yaml"
    path.write_text(text)
    with pytest.raises(ValueError, match=field) as err:
        read_intrinsics(path)
    assert str(path) in str(err.value)


# -- inputs that crashed or fooled cv2.FileStorage: refused first, naming the file ----------
def _load_error(path):
    with pytest.raises(ValueError) as err:
        MisalignedHyperbolicCamera.load(path)
    return str(err.value)


def test_non_utf8_file_name_is_refused_before_opencv_sees_it(tmp_path):
    good = tmp_path / "c.yaml"
    RIGS["aligned"].save(good)
    bad = os.path.join(os.fsencode(tmp_path), b"c\xff.yaml")
    os.link(os.fsencode(good), bad)
    assert "not valid UTF-8" in _load_error(os.fsdecode(bad))
    with pytest.raises(ValueError, match="not valid UTF-8"):
        RIGS["aligned"].save(os.fsdecode(bad))
    assert sorted(os.listdir(os.fsencode(tmp_path))) == [b"c.yaml", b"c\xff.yaml"]


@pytest.mark.parametrize(
    "name, text",
    [
        ("deep.json", "[" * 100_000 + "]" * 100_000),
        (
            "deep.xml",
            '<?xml version="1.0"?>\n<opencv_storage>'
            + "<a>" * 30_000
            + "</a>" * 30_000
            + "</opencv_storage>\n",
        ),
        ("deep.yaml", "%YAML:1.0\n---\nK: " + "[" * 100_000 + "]" * 100_000 + "\n"),
    ],
)
def test_deep_nesting_is_refused_without_crashing(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    message = _load_error(path)
    assert str(path) in message and "nested too deeply" in message


def test_matrix_value_out_of_its_dt_range_is_refused_not_saturated(tmp_path):
    path, text = _saved(tmp_path)
    K = RIGS["distorted"].K
    new = text.replace(
        "K: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ "
        + _yaml_matrix(K).split("data: [ ", 1)[1].split("]", 1)[0]
        + "]",
        "K: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: u\n"
        "   data: [ 583, 0, 250, 0, 583, 250, 0, 0, 1 ]",
    )
    assert new != text
    path.write_text(new)
    message = _load_error(path)
    assert "'K'" in message and "583" in message


def test_integers_beyond_32_bits_are_refused_not_wrapped(tmp_path):
    path, text = _saved(tmp_path)
    path.write_text(text.replace("format_version: 1", "format_version: 4294967297"))
    assert "4294967297" in _load_error(path)


@pytest.mark.parametrize("kind", ["folder", "fifo", "device"])
def test_a_non_regular_file_named_yaml_is_not_a_regular_file(tmp_path, kind):
    path = tmp_path / "c.yaml"
    if kind == "folder":
        path.mkdir()
    elif kind == "fifo":
        os.mkfifo(path)
    else:
        path.symlink_to("/dev/null")
    assert "is not a regular file" in _load_error(path)
    from omnicam.formats.intrinsics import read_intrinsics

    with pytest.raises(ValueError, match="is not a regular file"):
        read_intrinsics(path)


@pytest.mark.parametrize(
    "data, words",
    [
        (b"%YAML:1.0\n#" + b"x" * (2 << 20), "too large"),
        (bytes(range(256)) * 4, "binary"),
        (b'%YAML:1.0\nmodel: "misaligned_\xffhyperbolic"\n', "not UTF-8"),
        (b"", "empty"),
    ],
)
def test_oversized_binary_and_non_utf8_files_are_refused(tmp_path, data, words):
    for ext in (".yaml", ".json"):
        path = tmp_path / f"c{ext}"
        path.write_bytes(data)
        message = _load_error(path)
        assert words in message and str(path) in message


def test_opencv_prints_nothing_of_its_own_for_a_garbage_file(tmp_path, capfd):
    path = tmp_path / "c.yaml"
    path.write_text("%YAML:1.0\n---\nK: [ 1, 2\n  : : ]]] {{\n")
    _load_error(path)
    out, err = capfd.readouterr()
    assert out == "" and err == ""


def test_save_that_does_not_read_back_equal_keeps_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "c.json"
    RIGS["aligned"].save(path)
    before = path.read_bytes()
    import omnicam.formats.calibration_file

    monkeypatch.setattr(omnicam.formats.calibration_file, "_same_camera", lambda a, b: False)
    with pytest.raises(ValueError, match="does not read back"):
        RIGS["misaligned"].save(path)
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["c.json"]


def _tmpfs(tmp_path, size="64k"):
    if os.geteuid() != 0:
        pytest.skip("needs root to mount a tmpfs")
    import subprocess

    mnt = tmp_path / "mnt"
    mnt.mkdir()
    if (
        subprocess.run(
            ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mnt)], capture_output=True
        ).returncode
        != 0
    ):
        pytest.skip("mount -t tmpfs is not permitted here")
    return mnt


@pytest.mark.parametrize("ext", [".yaml", ".xml", ".json"])
def test_save_on_a_full_disk_raises_and_keeps_the_old_file(tmp_path, ext):
    import subprocess

    mnt = _tmpfs(tmp_path)
    try:
        path = mnt / f"c{ext}"
        RIGS["aligned"].save(path)
        before = path.read_bytes()
        with open(mnt / "filler", "wb", buffering=0) as f:
            try:
                while True:
                    f.write(b"\0" * 1024)
            except OSError:
                pass
        with pytest.raises(ValueError, match=f"c{ext}"):
            RIGS["distorted"].save(path)
        assert path.read_bytes() == before
        assert sorted(os.listdir(mnt)) == [f"c{ext}", "filler"]
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


def test_save_into_a_read_only_folder_raises_and_keeps_the_old_file(tmp_path):
    import subprocess

    mnt = _tmpfs(tmp_path)
    try:
        path = mnt / "c.yaml"
        RIGS["aligned"].save(path)
        before = path.read_bytes()
        subprocess.run(["mount", "-o", "remount,ro", str(mnt)], check=True)
        with pytest.raises(ValueError, match="c.yaml"):
            RIGS["distorted"].save(path)
        assert path.read_bytes() == before
        assert MisalignedHyperbolicCamera.load(path) == RIGS["aligned"]
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


def test_far_lines_round_trip_also_from_opencv_shaped_arrays(tmp_path):
    from omnicam.formats.point_files import read_far_lines, write_far_lines

    lines = [np.arange(10.0).reshape(5, 1, 2) + i for i in range(3)]
    write_far_lines(tmp_path / "l.json", lines)
    back = read_far_lines(tmp_path / "l.json")
    assert all(np.array_equal(b, a.reshape(-1, 2)) for a, b in zip(lines, back, strict=True))
    with pytest.raises(ValueError, match="far_lines"):
        write_far_lines(tmp_path / "l.json", [[[1.0, 2.0]] * 2])


def test_image_size_written_as_an_opencv_matrix_is_read(tmp_path):
    from omnicam.formats.intrinsics import read_intrinsics

    K = RIGS["aligned"].K
    for ext in (".yaml", ".xml", ".json"):
        fs = cv2.FileStorage(str(tmp_path / f"k{ext}"), cv2.FILE_STORAGE_WRITE)
        fs.write("camera_matrix", K)
        fs.write("image_size", np.array([[640], [480]], np.int32))
        fs.release()
        assert read_intrinsics(tmp_path / f"k{ext}")[2] == (640, 480)


# -- the verdict: how far to trust a calibration, recorded in the file (issue 18 item 3) ----------
def _doubtful_verdict():
    from omnicam.formats.verdict import Verdict

    return Verdict(
        K_source="guessed",
        K_note="fx = fy = 582.6 px, principal point at the rim's centre",
        confidence=0.0,
        ambiguous=True,
        forced=True,
        axis_std_deg=0.127,
        origin_std_mm=0.15,
        rim_rms_px=0.57,
        warnings=("no far_lines given: the choice is ambiguous",),
        implausible=("the camera centre is 13.0 from the mirror's lower focus (limit 10)",),
    )


@pytest.mark.parametrize("ext", [".yaml", ".yml", ".xml", ".json"])
def test_the_verdict_round_trips_in_every_format(tmp_path, ext):
    from omnicam.formats.calibration_file import read_verdict
    from omnicam.formats.verdict import Verdict

    chessboard = Verdict(
        method="chessboard",
        K_source="chessboard",
        K_file="start.yaml",
        axis_std_deg=0.02,
        origin_std_mm=0.03,
        rms_px=0.21,
        heldout_median_px=0.3,
        heldout_max_px=0.45,
        heldout_folds=5,
        ray_std_deg=(0.01, 0.04),
        forced=True,
        implausible=("all boards are on one side of the mirror",),
    )
    for i, verdict in enumerate((_doubtful_verdict(), chessboard)):
        path = tmp_path / f"c{i}{ext}"
        RIGS["misaligned"].save(path, verdict)
        assert read_verdict(path) == verdict
        assert MisalignedHyperbolicCamera.load(path) == RIGS["misaligned"]  # load: unchanged


def test_a_file_without_a_verdict_reads_as_before_and_has_none(tmp_path):
    from omnicam import samples
    from omnicam.formats.calibration_file import read_verdict

    path = tmp_path / "c.yaml"
    RIGS["aligned"].save(path)
    assert "verdict" not in path.read_text()
    assert read_verdict(path) is None
    with samples.path("hyperomni_misaligned") as shipped:  # written before verdicts
        assert read_verdict(shipped) is None
        MisalignedHyperbolicCamera.load(shipped)


def test_a_file_with_a_verdict_keeps_format_version_1_and_reads_unknown_fields(tmp_path):
    """Compatible: the verdict is an optional map; a later field inside it is ignored."""
    from omnicam.formats.calibration_file import FORMAT_VERSION, read_verdict

    assert FORMAT_VERSION == 1
    path = tmp_path / "c.yaml"
    RIGS["misaligned"].save(path, _doubtful_verdict())
    text = path.read_text()
    assert "format_version: 1" in text and "ambiguous: 1" in text  # flags as 0/1, not true
    path.write_text(text.replace("verdict:\n", "verdict:\n   from_the_future: 3\n"))
    assert read_verdict(path) == _doubtful_verdict()


def test_save_with_a_report_records_its_verdict(tmp_path):
    from omnicam import synthetic
    from omnicam.formats.calibration_file import read_verdict
    from omnicam.formats.verdict import Verdict

    truth = synthetic.misaligned_rig()
    cam, report = MisalignedHyperbolicCamera.calibrate(
        truth.K, truth.mirror, boundary_points=truth.rim_image_points(360)
    )
    cam.save(tmp_path / "c.json", report)
    v = read_verdict(tmp_path / "c.json")
    assert v == Verdict.from_report(report)
    assert (v.method, v.K_source, v.forced) == ("image", "given", False)
    assert v.confidence == report.confidence and v.ambiguous == report.ambiguous
    assert v.axis_std_deg == report.axis_std_deg and v.origin_std_mm == report.origin_std_mm
    assert v.warnings == tuple(report.warnings)
    with pytest.raises(ValueError, match="verdict must be a Verdict or a calibration report"):
        cam.save(tmp_path / "d.json", {"confidence": 1.0})
    assert not (tmp_path / "d.json").exists()


def test_the_doubts_of_a_verdict_are_short_phrases():
    from omnicam.formats.verdict import Verdict

    assert Verdict().doubts() == ()
    assert _doubtful_verdict().doubts() == (
        "with a guessed K",
        "ambiguous (confidence 0.00)",
        "forced past 1 implausibility warning",
        "with 1 warning",
    )
    assert Verdict(implausible=("a", "b")).doubts() == ("with 2 implausibility warnings",)


def test_warning_texts_that_opencv_or_the_prescan_would_misread_still_round_trip(tmp_path):
    """OpenCV writes the string 'true' unquoted and a leading quote as if quoted; the pre-scan
    refuses ': true,' and 10-digit integers anywhere. Such texts are written readably."""
    from omnicam.formats.calibration_file import read_verdict
    from omnicam.formats.verdict import Verdict

    texts = ["x: true, y", "true", "null", "'quoted'", '"half', "n 12345678901234", "a\nb"]
    verdict = Verdict(warnings=texts)
    assert verdict.warnings[0] == "x: `true`, y" and verdict.warnings[-1] == "a b"
    for ext in (".yaml", ".xml", ".json"):
        path = tmp_path / f"c{ext}"
        RIGS["aligned"].save(path, verdict)
        assert read_verdict(path) == verdict


@pytest.mark.parametrize(
    "edit, field",
    [
        (lambda t: t.replace("confidence: 0.", "confidence: 2."), "verdict.confidence"),
        (lambda t: t.replace("confidence: 0.", "confidence: high"), "verdict.confidence"),
        (lambda t: t.replace("K_source: guessed", "K_source: magic"), "verdict.K_source"),
        (lambda t: t.replace("ambiguous: 1", "ambiguous: 7"), "verdict.ambiguous"),
        (lambda t: t.replace("axis_std_deg: ", "axis_std_deg: -"), "verdict.axis_std_deg"),
        (lambda t: t.replace("verdict:\n", "verdict: 3\nold:\n"), "verdict"),
    ],
)
def test_a_malformed_verdict_raises_naming_the_file_and_the_field(tmp_path, edit, field):
    from omnicam.formats.calibration_file import read_verdict

    path = tmp_path / "c.yaml"
    RIGS["aligned"].save(path, _doubtful_verdict())
    text = path.read_text()
    new = edit(text)
    assert new != text
    path.write_text(new)
    with pytest.raises(ValueError) as err:
        read_verdict(path)
    assert str(path) in str(err.value) and repr(field) in str(err.value), str(err.value)
    MisalignedHyperbolicCamera.load(path)  # the camera itself still reads


# -- the camera's own reflection, recorded in the file (issue 18 item 6) --------------------------
@pytest.mark.parametrize("ext", [".yaml", ".yml", ".xml", ".json"])
def test_the_camera_reflection_round_trips_in_every_format(tmp_path, ext):
    cam = RIGS["distorted"].replace(camera_reflection=(9.25, 12.125))
    path = tmp_path / f"c{ext}"
    cam.save(path)
    assert "camera_reflection" in path.read_text()
    loaded = MisalignedHyperbolicCamera.load(path)
    assert loaded == cam and loaded.camera_reflection == (9.25, 12.125)
    assert loaded.camera_reflection.r == 9.25 and loaded.camera_reflection.z == 12.125


def test_a_file_without_the_camera_reflection_reads_as_before_and_has_none(tmp_path):
    from omnicam import samples

    path = tmp_path / "c.yaml"
    RIGS["misaligned"].save(path)
    assert "camera_reflection" not in path.read_text()
    assert MisalignedHyperbolicCamera.load(path).camera_reflection is None
    with samples.path("hyperomni_misaligned") as shipped:  # written before the field
        assert "camera_reflection" not in shipped.read_text()
        assert MisalignedHyperbolicCamera.load(shipped).camera_reflection is None


def test_the_camera_reflection_keeps_format_version_1_and_ignores_unknown_keys(tmp_path):
    """An optional map (docs/conventions.md, "Compatibility"): a later key inside it is ignored,
    and a reader that ignores the whole map reads the same camera."""
    cam = RIGS["misaligned"].replace(camera_reflection=(9.0, 12.0))
    path = tmp_path / "c.yaml"
    cam.save(path)
    text = path.read_text()
    assert "format_version: 1" in text
    path.write_text(text.replace("camera_reflection:\n", "camera_reflection:\n   glass: 3.\n"))
    assert MisalignedHyperbolicCamera.load(path) == cam
    start = text.index("camera_reflection:")
    end = text.index("\n", text.index("   z:", start))
    path.write_text(text[:start] + text[end + 1 :])  # what an older writer left
    assert MisalignedHyperbolicCamera.load(path) == RIGS["misaligned"]


@pytest.mark.parametrize(
    "edit",
    [
        lambda t: t.replace("   r: 9.", "   r: -9."),
        lambda t: t.replace("   r: 9.", "   r: 0."),
        lambda t: t.replace("   r: 9.", "   radius: 9."),
        lambda t: t.replace("   z: 12.", "   z: .nan"),
        lambda t: t.replace("   z: 12.", "   z: far"),
        lambda t: t.replace("camera_reflection:\n", "camera_reflection: 3\nold:\n"),
    ],
)
def test_a_malformed_camera_reflection_raises_naming_the_file_and_the_field(tmp_path, edit):
    path = tmp_path / "c.yaml"
    RIGS["misaligned"].replace(camera_reflection=(9.0, 12.0)).save(path)
    text = path.read_text()
    new = edit(text)
    assert new != text
    path.write_text(new)
    with pytest.raises(ValueError) as err:
        MisalignedHyperbolicCamera.load(path)
    assert str(path) in str(err.value) and "camera_reflection" in str(err.value), str(err.value)
