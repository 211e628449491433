"""The ``omnicam`` command line, called as ``main([...])`` (py360convert style), on small inputs."""

from __future__ import annotations

import json
import os
import sys

import cv2
import numpy as np
import pytest
from conftest import leftovers, make_frame, one_error_line, video_frames, write_video

import omnicam
from omnicam import synthetic
from omnicam.cli import main
from omnicam.formats.intrinsics import read_intrinsics

SIZE = (200, 200)  # frames of the small test videos and images


# -- fixtures ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def rig():
    return synthetic.misaligned_rig(image_size=SIZE)


@pytest.fixture(scope="module")
def data(tmp_path_factory, rig):
    """A calibration file, a 10-frame MJPG video and a PNG image, all 200x200."""
    folder = tmp_path_factory.mktemp("cli-data")
    calib = folder / "rig.yaml"
    rig.save(calib)
    video = write_video(folder / "clip.avi", 10)
    image = folder / "frame.png"
    cv2.imwrite(str(image), make_frame(3))
    return {"calib": calib, "video": video, "image": image, "folder": folder}


# -- unwarp -----------------------------------------------------------------------------------
def test_unwarp_video_panorama_keeps_frame_count_and_size(data, tmp_path, capsys):
    out = tmp_path / "pano.avi"
    code = main(
        [
            "unwarp",
            str(data["video"]),
            "-c",
            str(data["calib"]),
            "--panorama",
            "96x24",
            "-o",
            str(out),
        ]
    )
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert video_frames(out) == (10, (96, 24))
    assert "fps" in captured.err and "10/10" in captured.err  # the progress bar
    assert leftovers(tmp_path) == []


def test_unwarp_video_perspective_keeps_frame_count_and_size(data, tmp_path, capsys):
    out = tmp_path / "view.avi"
    code = main(
        [
            "unwarp",
            str(data["video"]),
            "-c",
            str(data["calib"]),
            "--perspective",
            "48x32",
            "--fov",
            "90",
            "--yaw",
            "30",
            "--pitch",
            "-10",
            "--roll",
            "5",
            "--quiet",
            "-o",
            str(out),
        ]
    )
    assert code == 0, capsys.readouterr().err
    assert video_frames(out) == (10, (48, 32))


def test_unwarp_image_sequence_pattern(data, tmp_path, capsys):
    for i in range(5):
        cv2.imwrite(str(tmp_path / f"img_{i:03d}.png"), make_frame(i))
    out = tmp_path / "seq.avi"
    code = main(
        [
            "unwarp",
            str(tmp_path / "img_%03d.png"),
            "-c",
            str(data["calib"]),
            "--panorama",
            "64x16",
            "-q",
            "-o",
            str(out),
        ]
    )
    assert code == 0, capsys.readouterr().err
    assert video_frames(out) == (5, (64, 16))


def test_unwarp_video_max_frames(data, tmp_path, capsys):
    out = tmp_path / "short.avi"
    code = main(
        [
            "unwarp",
            str(data["video"]),
            "-c",
            str(data["calib"]),
            "--panorama",
            "64x16",
            "--max-frames",
            "3",
            "-o",
            str(out),
        ]
    )
    assert code == 0, capsys.readouterr().err
    assert video_frames(out) == (3, (64, 16))


def test_unwarp_image_is_cv2_remap_with_the_calibration_tables(data, rig, tmp_path, capsys):
    out = tmp_path / "pano.png"
    code = main(
        [
            "unwarp",
            str(data["image"]),
            "-c",
            str(data["calib"]),
            "--panorama",
            "120x30",
            "--elevation",
            "-60",
            "10",
            "--projection",
            "equirectangular",
            "-o",
            str(out),
        ]
    )
    assert code == 0, capsys.readouterr().err
    got = cv2.imread(str(out))
    m1, m2 = rig.init_panorama_maps(
        (120, 30), elevation_range=(-60, 10), projection="equirectangular"
    )
    expected = cv2.remap(cv2.imread(str(data["image"])), m1, m2, cv2.INTER_LINEAR)
    assert got.shape == (30, 120, 3)
    np.testing.assert_array_equal(got, expected)


def test_unwarp_image_with_depth_builds_finite_depth_tables(data, rig, tmp_path, capsys):
    out = tmp_path / "near.png"
    code = main(
        [
            "unwarp",
            str(data["image"]),
            "-c",
            str(data["calib"]),
            "--perspective",
            "40x30",
            "--fov",
            "70",
            "--depth",
            "500",
            "-o",
            str(out),
        ]
    )
    assert code == 0, capsys.readouterr().err
    from omnicam.views import K_from_fov, rotation_from_ypr

    m1, m2 = rig.init_perspective_maps(
        K_from_fov(70, (40, 30)), (40, 30), R=rotation_from_ypr(0, 0, 0), depth=500.0
    )
    expected = cv2.remap(cv2.imread(str(data["image"])), m1, m2, cv2.INTER_LINEAR)
    np.testing.assert_array_equal(cv2.imread(str(out)), expected)


def test_unwarp_scales_the_calibration_to_the_frame_size(rig, tmp_path, capsys):
    calib = tmp_path / "big.yaml"
    rig.scaled((400, 400)).save(calib)  # calibrated at twice the resolution of the frames
    image = tmp_path / "small.png"
    cv2.imwrite(str(image), make_frame(1))
    out = tmp_path / "pano.png"
    code = main(["unwarp", str(image), "-c", str(calib), "--panorama", "80x20", "-o", str(out)])
    assert code == 0, capsys.readouterr().err
    m1, m2 = rig.scaled((400, 400)).scaled(SIZE).init_panorama_maps((80, 20))
    expected = cv2.remap(make_frame(1), m1, m2, cv2.INTER_LINEAR)
    np.testing.assert_array_equal(cv2.imread(str(out)), expected)


def test_unwarp_warns_when_the_frames_have_another_aspect_ratio(rig, data, tmp_path, capsys):
    calib = tmp_path / "wide.yaml"
    rig.scaled((400, 300)).save(calib)
    out = tmp_path / "pano.avi"
    code = main(
        [
            "unwarp",
            str(data["video"]),
            "-c",
            str(calib),
            "--panorama",
            "64x16",
            "-q",
            "-o",
            str(out),
        ]
    )
    err = capsys.readouterr().err
    assert code == 0, err
    assert "warning" in err and "aspect ratio" in err and len(err.splitlines()) == 1
    assert video_frames(out) == (10, (64, 16))


@pytest.mark.parametrize("kind", ["image", "video"])
def test_existing_output_is_replaced_only_with_overwrite(data, tmp_path, capsys, kind):
    out = tmp_path / ("out.png" if kind == "image" else "out.avi")
    out.write_bytes(b"precious")
    argv = [
        "unwarp",
        str(data[kind]),
        "-c",
        str(data["calib"]),
        "--panorama",
        "64x16",
        "-o",
        str(out),
    ]
    assert main(argv) != 0
    line = one_error_line(capsys.readouterr().err)
    assert "exists" in line and "--overwrite" in line
    assert out.read_bytes() == b"precious"

    assert main(argv + ["--overwrite"]) == 0, capsys.readouterr().err
    if kind == "image":
        assert cv2.imread(str(out)).shape == (16, 64, 3)
    else:
        assert video_frames(out) == (10, (64, 16))
    assert leftovers(tmp_path) == []


def test_truncated_video_keeps_the_frames_so_far(data, tmp_path, capsys):
    full = write_video(tmp_path / "full.avi", 10)
    truncated = tmp_path / "truncated.avi"
    raw = full.read_bytes()
    truncated.write_bytes(raw[: len(raw) * 6 // 10])
    n_in, _ = video_frames(truncated)
    assert 0 < n_in < 10  # the fixture really is truncated, and OpenCV still decodes the start
    out = tmp_path / "out.avi"
    code = main(
        ["unwarp", str(truncated), "-c", str(data["calib"]), "--panorama", "64x16", "-o", str(out)]
    )
    err = capsys.readouterr().err
    assert code == 0, err
    assert "warning" in err and "truncated" in err
    assert video_frames(out) == (n_in, (64, 16))  # a valid, finalised file
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("where", ["between frames", "while reading"])
def test_ctrl_c_keeps_the_frames_so_far(data, tmp_path, capsys, monkeypatch, where):
    import omnicam.cli as cli
    import omnicam.stream as stream

    if where == "between frames":  # in the CLI's loop, while the Unwarper's generator waits
        real_update = cli.Progress.update

        def interrupt(self, frames, force=False):
            real_update(self, frames, force)
            if frames == 4 and not force:  # once, as the user's Ctrl-C
                raise KeyboardInterrupt

        monkeypatch.setattr(cli.Progress, "update", interrupt)
    else:  # inside the Unwarper's generator, before the 5th frame is written
        real_unwarp = stream.Unwarper.unwarp
        calls = []

        def interrupt(self, frame):
            calls.append(1)
            if len(calls) == 5:
                raise KeyboardInterrupt
            return real_unwarp(self, frame)

        monkeypatch.setattr(stream.Unwarper, "unwarp", interrupt)
    out = tmp_path / "out.avi"
    code = main(
        [
            "unwarp",
            str(data["video"]),
            "-c",
            str(data["calib"]),
            "--panorama",
            "64x16",
            "-o",
            str(out),
        ]
    )
    err = capsys.readouterr().err
    assert code == 130
    assert "interrupted: kept the 4 frames" in err and "Traceback" not in err
    assert video_frames(out) == (4, (64, 16))
    assert leftovers(tmp_path) == []


def test_outputs_get_the_mode_of_a_new_file_not_the_temp_file_mode(data, tmp_path, capsys):
    umask = os.umask(0o022)
    try:
        for name in ("out.png", "out.avi"):
            src = data["image"] if name.endswith(".png") else data["video"]
            assert (
                main(
                    [
                        "unwarp",
                        str(src),
                        "-c",
                        str(data["calib"]),
                        "--panorama",
                        "64x16",
                        "-q",
                        "-o",
                        str(tmp_path / name),
                    ]
                )
                == 0
            )
            assert (tmp_path / name).stat().st_mode & 0o777 == 0o644
    finally:
        os.umask(umask)


# -- bad input: one line, non-zero exit, nothing written ---------------------------------------
BAD_UNWARP = {
    "malformed panorama size": ["--panorama", "12x"],
    "zero panorama size": ["--panorama", "0x16"],
    "unknown view spec": ["--cube", "64x64"],
    "both views": ["--panorama", "64x16", "--perspective", "64x64", "--fov", "90"],
    "no view": [],
    "perspective without fov": ["--perspective", "64x48"],
    "fov out of range": ["--perspective", "64x48", "--fov", "180"],
    "elevation reversed": ["--panorama", "64x16", "--elevation", "10", "-40"],
    "elevation with perspective": [
        "--perspective",
        "64x48",
        "--fov",
        "90",
        "--elevation",
        "-40",
        "10",
    ],
    "fov with panorama": ["--panorama", "64x16", "--fov", "90"],
    "unknown projection": ["--panorama", "64x16", "--projection", "fisheye"],
    "negative depth": ["--panorama", "64x16", "--depth", "-5"],
    "non-numeric yaw": ["--perspective", "64x48", "--fov", "90", "--yaw", "left"],
}


@pytest.mark.parametrize("view", BAD_UNWARP.values(), ids=BAD_UNWARP.keys())
def test_bad_view_spec_is_one_line_and_writes_nothing(data, tmp_path, capsys, view):
    out = tmp_path / "out.avi"
    code = main(["unwarp", str(data["video"]), "-c", str(data["calib"]), *view, "-o", str(out)])
    assert code == 2
    one_error_line(capsys.readouterr().err)
    assert list(tmp_path.iterdir()) == []


# -- refusals: exit 1, one line naming the problem, nothing written or changed -----------------
def tree(folder):
    """Every path under ``folder`` with its bytes (None for a folder): what a refusal keeps."""
    return {
        str(p.relative_to(folder)): None if p.is_dir() else p.read_bytes()
        for p in sorted(folder.rglob("*"))
    }


def unwarp(*extra, src="{video}", calib="{calib}", out="{tmp}/out.avi", panorama="64x16"):
    """``omnicam unwarp`` arguments (``{video}``, ``{image}``, ``{calib}``, ``{tmp}`` filled in)."""
    return ["unwarp", src, "-c", calib, "--panorama", panorama, "-o", out, *extra]


def write_file(name, content):
    def setup(tmp, rig, monkeypatch):
        (tmp / name).write_bytes(content)

    return setup


def make_folder(name):
    def setup(tmp, rig, monkeypatch):
        (tmp / name).mkdir()

    return setup


def read_only_folder(name):
    def setup(tmp, rig, monkeypatch):
        folder = tmp / name
        folder.mkdir()
        folder.chmod(0o500)
        return lambda: folder.chmod(0o700)

    return setup


def refuse_to_create(tmp, rig, monkeypatch):
    """No new file in ``tmp``: a read-only mount, even for root."""
    real_open = os.open

    def refuse_in_tmp(path, flags, *args, **kwargs):
        if flags & os.O_CREAT and os.path.samefile(os.path.dirname(os.path.abspath(path)), tmp):
            raise PermissionError(13, "Permission denied")
        return real_open(path, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", refuse_in_tmp)


def two_frame_clip(tmp, rig, monkeypatch):
    write_video(tmp / "clip.avi", 2)


def existing_calibration(tmp, rig, monkeypatch):
    write_intrinsics(tmp / "k.yaml", rig.K, image_size=SIZE)
    (tmp / "calib.yaml").write_text("precious")


MALFORMED = b"%YAML:1.0\n---\nformat_version: 1\nmodel: misaligned_hyperbolic\n"
POSIX_USER = pytest.mark.skipif(
    sys.platform == "win32" or os.geteuid() == 0, reason="needs POSIX permissions as a normal user"
)

#: (setup, argv, words in the error line), one row per refusal
REFUSALS = [
    pytest.param(None, unwarp(panorama="96x25"), "even", id="odd video size"),
    pytest.param(None, unwarp(calib="{tmp}/nope.yaml"), "nope.yaml", id="missing calibration"),
    pytest.param(
        write_file("bad.yaml", MALFORMED),
        unwarp(calib="{tmp}/bad.yaml"),
        "bad.yaml",
        id="malformed calibration",
    ),
    pytest.param(
        write_file("broken.avi", b""),
        unwarp(src="{tmp}/broken.avi"),
        "broken.avi",
        id="empty video",
    ),
    pytest.param(
        write_file("broken.avi", b"RIFF\x00\x00\x00\x00AVI garbage" * 20),
        unwarp(src="{tmp}/broken.avi"),
        "broken.avi",
        id="garbage video",
    ),
    pytest.param(None, unwarp(src="{tmp}/nope.mp4"), "does not exist", id="missing input"),
    pytest.param(None, unwarp(src="7"), "camera 7", id="camera index that cannot be opened"),
    pytest.param(
        None,
        unwarp(src="http://127.0.0.1:9/x.mjpg"),
        "stream",
        id="stream URL that cannot be opened",
    ),
    pytest.param(make_folder("out.avi"), unwarp("--overwrite"), "folder", id="output is a folder"),
    pytest.param(
        refuse_to_create,
        unwarp("-q", src="{image}", out="{tmp}/out.png"),
        "Permission denied",
        id="image output that cannot be created",
    ),
    pytest.param(
        refuse_to_create,
        unwarp("-q"),
        "Permission denied",
        id="video output that cannot be created",
    ),
    pytest.param(
        None,
        unwarp(out="{tmp}/no/such/out.avi"),
        "does not exist",
        id="output folder missing",
    ),
    pytest.param(
        read_only_folder("ro"),
        unwarp(out="{tmp}/ro/out.avi"),
        "not writable",
        id="output folder not writable",
        marks=POSIX_USER,
    ),
    pytest.param(
        None, unwarp(src="{image}", out="{tmp}/out.nope"), "out.nope", id="image to out.nope"
    ),
    pytest.param(None, unwarp(out="{tmp}/out.png"), "out.png", id="video to out.png"),
    pytest.param(None, unwarp(out="{tmp}/out.nope"), "out.nope", id="video to out.nope"),
    pytest.param(
        two_frame_clip,
        unwarp("--overwrite", src="{tmp}/clip.avi", out="{tmp}/clip.avi"),
        None,
        id="output same as input",
    ),
    pytest.param(None, ["info", "{tmp}/nope.yaml"], "nope.yaml", id="info of a missing file"),
    pytest.param(
        existing_calibration,
        ["calibrate", "{image}", "--mirror", "23.4", "28.1", "30"]
        + ["--intrinsics", "{tmp}/k.yaml", "-o", "{tmp}/calib.yaml"],
        "--overwrite",
        id="calibrate to an existing file without --overwrite",
    ),
]


@pytest.mark.parametrize("setup, argv, words", REFUSALS)
def test_refusal_is_exit_1_and_one_line_and_leaves_the_folder_as_it_was(
    data, rig, tmp_path, capsys, monkeypatch, setup, argv, words
):
    undo = setup(tmp_path, rig, monkeypatch) if setup is not None else None
    before = tree(tmp_path)
    names = {k: str(data[k]) for k in ("video", "image", "calib")}
    try:
        code = main([a.format(tmp=tmp_path, **names) for a in argv])
    finally:
        if undo is not None:
            undo()
    assert code == 1
    line = one_error_line(capsys.readouterr().err)
    if words is not None:
        assert words in line
    assert tree(tmp_path) == before


def test_no_command_and_unknown_command(capsys):
    assert main([]) == 2
    one_error_line(capsys.readouterr().err)
    assert main(["explode"]) == 2
    one_error_line(capsys.readouterr().err)


def test_help_exits_zero(capsys):
    assert main(["unwarp", "--help"]) == 0
    assert "--panorama" in capsys.readouterr().out


# -- info -------------------------------------------------------------------------------------
def test_info_prints_mirror_intrinsics_posture_and_viewpoint(data, rig, capsys):
    assert main(["info", str(data["calib"])]) == 0
    out = capsys.readouterr().out
    assert "a = 23.4 mm, b = 28.1 mm, rim radius = 30 mm" in out
    assert f"fx = {rig.K[0, 0]:.4f}" in out
    assert "axis tilt      3.0000 deg, towards 30.00 deg" in out
    offset = rig.camera_center - np.array([0.0, 0.0, -rig.mirror.c])
    assert f"|offset| = {np.linalg.norm(offset):.4f} mm" in out
    viewpoint, rms = rig.best_fit_viewpoint()
    assert f"{rms:.4f} mm" in out
    assert f"{viewpoint[2]:.4f}" in out


def test_info_says_when_a_file_records_no_verdict(data, capsys):
    assert main(["info", str(data["calib"])]) == 0
    assert "verdict        none recorded" in capsys.readouterr().out


def test_info_prints_the_verdict_and_says_what_is_doubtful(rig, tmp_path, capsys):
    from omnicam.formats.verdict import Verdict

    calib = tmp_path / "rig.yaml"
    verdict = Verdict(
        K_source="file",
        K_file="K.yaml",
        confidence=0.0,
        ambiguous=True,
        forced=True,
        axis_std_deg=0.127,
        origin_std_mm=0.15,
        warnings=("no far_lines given",),
        implausible=("the camera centre is 13.0 from the lower focus",),
    )
    rig.save(calib, verdict)
    assert main(["info", str(calib)]) == 0
    out = capsys.readouterr().out
    assert (
        "verdict        DOUBTFUL: calibrated ambiguous (confidence 0.00), forced past 1 "
        "implausibility warning, with 1 warning (from one image of the mirror)"
    ) in out
    assert "K from         read from a file: K.yaml" in out
    assert "posture        chosen with confidence 0.0000 AMBIGUOUS" in out
    assert "uncertainty    mirror axis 0.127 deg, camera centre 0.15 mm" in out
    assert "implausible    - the camera centre is 13.0 from the lower focus" in out
    assert "warning        - no --far-lines given" in out  # as the command line says it
    rig.save(calib, Verdict(confidence=1.0))
    assert main(["info", str(calib)]) == 0
    assert "verdict        no doubt recorded" in capsys.readouterr().out


def test_info_says_the_camera_reflection_and_where_a_panoramas_lower_edge_comes_from(
    data, rig, tmp_path, capsys
):
    from omnicam.views import default_elevation_range

    assert main(["info", str(data["calib"])]) == 0
    assert (
        "reflection     none recorded; default panorama: lower edge -60.0 deg: the fixed "
        "default, no camera reflection recorded\n"
    ) in capsys.readouterr().out
    calib = tmp_path / "body.yaml"
    body = rig.replace(camera_reflection=(22.0, 50.0))  # a wide barrel: it shows up to -45 deg
    body.save(calib)
    assert main(["info", str(calib)]) == 0
    lo = default_elevation_range(body).lo
    assert -50.0 < lo < -40.0
    assert (
        f"reflection     circle r 22.000 mm at z 50.000 mm (camera frame), as detected; "
        f"default panorama: lower edge {lo:.1f} deg: the camera's reflection as detected\n"
    ) in capsys.readouterr().out


def test_info_of_aligned_rig_has_zero_tilt_offset_and_rms(tmp_path, capsys):
    calib = tmp_path / "aligned.json"
    synthetic.aligned_rig(image_size=(120, 120)).save(calib)
    assert main(["info", str(calib)]) == 0
    out = capsys.readouterr().out
    assert "axis tilt      0.0000 deg" in out
    assert "|offset| = 0.0000 mm" in out
    assert "viewpoint RMS  0.0000 mm" in out


# -- calibrate: inputs ------------------------------------------------------------------------
def write_intrinsics(path, K, D=None, image_size=None, names=("K", "D")):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write(names[0], np.asarray(K, np.float64))
    if D is not None:
        fs.write(names[1], np.asarray(D, np.float64).reshape(1, -1))
    if image_size is not None:
        if names[0] == "camera_matrix":  # OpenCV's calibration sample
            fs.write("image_width", int(image_size[0]))
            fs.write("image_height", int(image_size[1]))
        else:
            fs.startWriteStruct("image_size", cv2.FileNode_SEQ)
            for v in image_size:
                fs.write("", int(v))
            fs.endWriteStruct()
    fs.release()
    return path


def test_read_intrinsics_accepts_our_names_and_opencv_sample_names(tmp_path, rig):
    D = [0.01, -0.002, 0.0, 0.0, 0.0]
    ours = write_intrinsics(tmp_path / "k.yaml", rig.K, D, (640, 480))
    K, got_D, size = read_intrinsics(str(ours))
    np.testing.assert_array_equal(K, rig.K)
    np.testing.assert_array_equal(got_D, D)
    assert size == (640, 480)
    sample = write_intrinsics(
        tmp_path / "k.xml", rig.K, D, (640, 480), names=("camera_matrix", "distortion_coefficients")
    )
    K, got_D, size = read_intrinsics(str(sample))
    np.testing.assert_array_equal(K, rig.K)
    np.testing.assert_array_equal(got_D, D)
    assert size == (640, 480)
    bare = write_intrinsics(tmp_path / "bare.json", rig.K, np.zeros(5))
    assert read_intrinsics(str(bare))[1:] == (None, None)  # all-zero D is no distortion
    rig.save(tmp_path / "calib.yaml")  # an omnicam calibration file works too
    K, D, size = read_intrinsics(str(tmp_path / "calib.yaml"))
    np.testing.assert_array_equal(K, rig.K)
    assert size == rig.image_size


@pytest.fixture()
def calib_inputs(tmp_path, rig, data):
    """IMAGE, K.yaml, LINES.json for the calibrate command (image: any readable picture)."""
    k = write_intrinsics(tmp_path / "k.yaml", rig.K, image_size=SIZE)
    lines = tmp_path / "lines.json"
    lines.write_text(
        json.dumps([[[10, 20], [30, 40], [50, 55]], [[100.5, 10], [120, 12.25], [140, 15]]])
    )
    return {"image": str(data["image"]), "k": str(k), "lines": str(lines)}


BAD_CALIBRATE = {
    "mirror with 2 numbers": ["--mirror", "23.4", "28.1"],
    "negative mirror": ["--mirror", "23.4", "-28.1", "30"],
    "missing intrinsics": ["--intrinsics", "{tmp}/nope.yaml"],
    "intrinsics without K": ["--intrinsics", "{tmp}/empty.yaml"],
    "intrinsics not a FileStorage": ["--intrinsics", "{tmp}/junk.yaml"],
    "far lines not JSON": ["--far-lines", "{tmp}/junk.json"],
    "far lines wrong shape": ["--far-lines", "{tmp}/shape.json"],
    "far line of 2 points": ["--far-lines", "{tmp}/short.json"],
    "missing far lines": ["--far-lines", "{tmp}/nope.json"],
    "missing image": ["IMAGE={tmp}/nope.png"],
    "bad calibration extension": ["-o", "{tmp}/calib.txt"],
}


@pytest.mark.parametrize("change", BAD_CALIBRATE.values(), ids=BAD_CALIBRATE.keys())
def test_calibrate_bad_input_is_one_line_and_writes_nothing(calib_inputs, tmp_path, capsys, change):
    (tmp_path / "empty.yaml").write_text("%YAML:1.0\n---\nD: [0, 0, 0, 0]\n")
    (tmp_path / "junk.yaml").write_text("this: is: not: a: FileStorage\n\t-")
    (tmp_path / "junk.json").write_text("[[1, 2], ")
    (tmp_path / "shape.json").write_text("[[[1, 2, 3], [4, 5, 6]]]")
    (tmp_path / "short.json").write_text("[[[1, 2], [4, 5]]]")
    before = sorted(p.name for p in tmp_path.iterdir())
    opts = {
        "--mirror": ["23.4", "28.1", "30"],
        "--intrinsics": [calib_inputs["k"]],
        "--far-lines": [calib_inputs["lines"]],
        "-o": [str(tmp_path / "calib.yaml")],
    }
    image = calib_inputs["image"]
    change = [c.format(tmp=tmp_path) for c in change]
    if change[0].startswith("IMAGE="):
        image = change[0][len("IMAGE=") :]
    else:
        opts[change[0]] = change[1:]
    argv = ["calibrate", image] + [x for k, v in opts.items() for x in (k, *v)]
    code = main(argv)
    assert code != 0
    one_error_line(capsys.readouterr().err)
    assert sorted(p.name for p in tmp_path.iterdir()) == before


# -- calibrate and demo: the whole pipeline ---------------------------------------------------
@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A 300x300 render of the demo scene by a misaligned rig, and its far-line pixels."""
    from omnicam.synthetic.demo import demo_environment, demo_far_lines

    folder = tmp_path_factory.mktemp("calibrate")
    truth = synthetic.misaligned_rig(image_size=(300, 300))
    image = folder / "mirror.png"
    cv2.imwrite(str(image), synthetic.render_environment(truth, demo_environment(), supersample=2))
    lines = folder / "lines.json"  # pixels along the scene's far straight lines
    lines.write_text(json.dumps([line.tolist() for line in demo_far_lines(truth)]))
    return {"truth": truth, "image": str(image), "lines": str(lines)}


def axis_error_deg(cam, truth):
    return float(np.degrees(np.arccos(np.clip(cam.R[:, 2] @ truth.R[:, 2], -1.0, 1.0))))


def test_calibrate_writes_calibration_and_overlay(scene, tmp_path, capsys):
    from omnicam import MisalignedHyperbolicCamera

    truth = scene["truth"]
    k = write_intrinsics(tmp_path / "k.yaml", truth.K, image_size=truth.image_size)
    calib = tmp_path / "calib.yaml"
    code = main(
        [
            "calibrate",
            scene["image"],
            "--mirror",
            "23.4",
            "28.1",
            "30",
            "--intrinsics",
            str(k),
            "--far-lines",
            scene["lines"],
            "-o",
            str(calib),
        ]
    )
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "confidence" in captured.out  # the report
    assert cv2.imread(str(tmp_path / "calib_overlay.png")).shape == (300, 300, 3)
    cam = MisalignedHyperbolicCamera.load(calib)
    assert cam.image_size == (300, 300)
    assert axis_error_deg(cam, truth) < 0.2
    assert np.linalg.norm(cam.camera_center - truth.camera_center) < 0.5


def test_calibrate_rescales_K_given_at_another_resolution(scene, tmp_path, capsys):
    from omnicam import MisalignedHyperbolicCamera

    truth = scene["truth"]
    big = truth.scaled((600, 600))  # intrinsics calibrated at twice the resolution
    k = write_intrinsics(
        tmp_path / "k.xml",
        big.K,
        image_size=(600, 600),
        names=("camera_matrix", "distortion_coefficients"),
    )
    calib = tmp_path / "calib.json"
    overlay = tmp_path / "look.jpg"
    code = main(
        [
            "calibrate",
            scene["image"],
            "--mirror",
            "23.4",
            "28.1",
            "30",
            "--intrinsics",
            str(k),
            "--far-lines",
            scene["lines"],
            "--no-refine",
            "--overlay",
            str(overlay),
            "-o",
            str(calib),
        ]
    )
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "K rescaled" in captured.err
    assert overlay.is_file() and not (tmp_path / "calib_overlay.png").exists()
    cam = MisalignedHyperbolicCamera.load(calib)
    np.testing.assert_allclose(cam.K, truth.K, atol=1e-9)
    assert axis_error_deg(cam, truth) < 0.3


@pytest.mark.slow
def test_demo_writes_every_output(tmp_path, capsys):
    out = tmp_path / "demo"
    code = main(["demo", "-o", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    names = sorted(p.name for p in out.iterdir())
    for expected in (
        "calibration.yaml",
        "mirror.png",
        "overlay.png",
        "panorama.png",
        "perspective.png",
    ):
        assert expected in names
    assert "posture error" in captured.out
    from omnicam import MisalignedHyperbolicCamera

    cam = MisalignedHyperbolicCamera.load(out / "calibration.yaml")
    truth = synthetic.misaligned_rig()
    assert axis_error_deg(cam, truth) < 0.2
    assert np.linalg.norm(cam.camera_center - truth.camera_center) < 0.5
    assert cv2.imread(str(out / "panorama.png")).shape == (256, 1024, 3)
    assert cv2.imread(str(out / "perspective.png")).shape == (480, 640, 3)
    assert main(["info", str(out / "calibration.yaml")]) == 0


def test_python_dash_m_runs_the_command():
    import subprocess

    out = subprocess.run(
        [sys.executable, "-m", "omnicam", "--version"], capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0
    assert omnicam.__version__ in out.stdout + out.stderr
