"""``omnicam unwarp``: several views per call, sequences, previews, 360 output, warnings, and
video output that is never lost (Ctrl-C, a full disk)."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
import warnings

import cv2
import numpy as np
import pytest
from conftest import leftovers as hidden
from conftest import make_frame, one_error_line, video_frames, write_video

from omnicam import synthetic
from omnicam.cli import main
from omnicam.spherical import equirect_view
from omnicam.views import K_from_fov, PanoramaView, rotation_from_ypr

SIZE = (200, 200)


@pytest.fixture(scope="module")
def rig():
    return synthetic.misaligned_rig(image_size=SIZE)


@pytest.fixture(scope="module")
def data(tmp_path_factory, rig):
    folder = tmp_path_factory.mktemp("unwarp-data")
    calib = folder / "rig.yaml"
    rig.save(calib)
    image = folder / "frame.png"
    cv2.imwrite(str(image), make_frame(3))
    return {"calib": calib, "video": write_video(folder / "clip.avi", 10), "image": image}


# -- several views, one decode -------------------------------------------------------------
def test_two_views_of_an_image_each_with_its_own_options_and_output(data, rig, tmp_path, capsys):
    a, b = tmp_path / "pano.png", tmp_path / "view.png"
    code = main(
        [
            "unwarp",
            str(data["image"]),
            "-c",
            str(data["calib"]),
            "--panorama",
            "120x30",
            "--elevation",
            "-50",
            "10",
            "-o",
            str(a),
            "--perspective",
            "40x30",
            "--fov",
            "70",
            "--yaw",
            "20",
            "-o",
            str(b),
        ]
    )
    assert code == 0, capsys.readouterr().err
    src = cv2.imread(str(data["image"]))
    m = rig.init_panorama_maps((120, 30), elevation_range=(-50, 10))
    np.testing.assert_array_equal(cv2.imread(str(a)), cv2.remap(src, *m, cv2.INTER_LINEAR))
    m = rig.init_perspective_maps(K_from_fov(70, (40, 30)), (40, 30), R=rotation_from_ypr(20))
    np.testing.assert_array_equal(cv2.imread(str(b)), cv2.remap(src, *m, cv2.INTER_LINEAR))


def test_several_video_views_decode_each_frame_once(data, tmp_path, capsys, monkeypatch):
    from omnicam.cli import unwarp

    reads = []
    real_open = unwarp.open_capture

    class Counting:  # not a subclass: cv2.VideoCapture's subclasses crash the garbage collector
        def __init__(self, cap):
            self.cap = cap

        def read(self):
            reads.append(1)
            return self.cap.read()

        def __getattr__(self, name):
            return getattr(self.cap, name)

    monkeypatch.setattr(unwarp, "open_capture", lambda s: Counting(real_open(s)))
    outs = [tmp_path / "a.avi", tmp_path / "b.mp4", tmp_path / "c.avi"]
    code = main(
        [
            "unwarp",
            str(data["video"]),
            "-c",
            str(data["calib"]),
            "-q",
            "--panorama",
            "64x16",
            "-o",
            str(outs[0]),
            "--perspective",
            "48x32",
            "--fov",
            "90",
            "-o",
            str(outs[1]),
            "--panorama",
            "96x24",
            "--projection",
            "equirectangular",
            "-o",
            str(outs[2]),
        ]
    )
    assert code == 0, capsys.readouterr().err
    assert video_frames(outs[0]) == (10, (64, 16))
    assert video_frames(outs[1]) == (10, (48, 32))
    assert video_frames(outs[2]) == (10, (96, 24))
    assert len(reads) == 11  # ten frames and the end of the input
    assert hidden(tmp_path) == []


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--panorama", "64x16", "-o", "a.avi", "--panorama", "32x8"], "has no -o"),
        (
            ["--panorama", "64x16", "-o", "a.avi", "--panorama", "32x8", "-o", "a.avi"],
            "same output",
        ),
        (["--panorama", "64x16", "--fov", "90", "-o", "a.avi"], "--fov"),
        (
            [
                "--panorama",
                "64x16",
                "--elevation",
                "-40",
                "10",
                "--elevation",
                "-30",
                "5",
                "-o",
                "a.avi",
            ],
            "twice",
        ),
        (["-o", "a.avi"], "give a view"),
    ],
    ids=["missing -o", "same output", "option of another view", "option twice", "no view"],
)
def test_bad_multi_view_command_lines_are_usage_errors(
    data, tmp_path, capsys, argv, words, monkeypatch
):
    monkeypatch.chdir(tmp_path)
    code = main(["unwarp", str(data["video"]), "-c", str(data["calib"]), *argv])
    assert code == 2
    assert words in one_error_line(capsys.readouterr().err)
    assert list(tmp_path.iterdir()) == []


def test_options_before_the_first_view_belong_to_it(data, rig, tmp_path, capsys):
    out = tmp_path / "p.png"
    code = main(
        [
            "unwarp",
            str(data["image"]),
            "-c",
            str(data["calib"]),
            "-o",
            str(out),
            "--elevation",
            "-50",
            "10",
            "--panorama",
            "120x30",
        ]
    )
    assert code == 0, capsys.readouterr().err
    m = rig.init_panorama_maps((120, 30), elevation_range=(-50, 10))
    src = cv2.imread(str(data["image"]))
    np.testing.assert_array_equal(cv2.imread(str(out)), cv2.remap(src, *m, cv2.INTER_LINEAR))


# -- sequences and previews ----------------------------------------------------------------
def test_video_to_an_image_sequence_and_previews(data, rig, tmp_path, capsys):
    pattern = tmp_path / "out_%03d.png"
    code = main(
        [
            "unwarp",
            str(data["video"]),
            "-c",
            str(data["calib"]),
            "-q",
            "--panorama",
            "64x16",
            "-o",
            str(pattern),
            "--preview",
            "4",
        ]
    )
    assert code == 0, capsys.readouterr().err
    frames = sorted(p.name for p in tmp_path.glob("out_*.png"))
    assert frames == [f"out_{i:03d}.png" for i in range(10)]
    cap = cv2.VideoCapture(str(data["video"]))
    m = rig.init_panorama_maps((64, 16))
    for i in range(10):
        _, frame = cap.read()
        np.testing.assert_array_equal(
            cv2.imread(str(tmp_path / f"out_{i:03d}.png")), cv2.remap(frame, *m, cv2.INTER_LINEAR)
        )
    cap.release()
    previews = sorted(p.name for p in tmp_path.glob("*.preview_*.png"))
    assert previews == [
        "out.preview_000000.png",
        "out.preview_000004.png",
        "out.preview_000008.png",
    ]
    assert hidden(tmp_path) == []


def test_sequence_output_refuses_to_overwrite_without_overwrite(data, tmp_path, capsys):
    (tmp_path / "out_000.png").write_bytes(b"precious")
    code = main(
        [
            "unwarp",
            str(data["video"]),
            "-c",
            str(data["calib"]),
            "-q",
            "--panorama",
            "64x16",
            "-o",
            str(tmp_path / "out_%03d.png"),
        ]
    )
    assert code == 1
    assert "exists" in one_error_line(capsys.readouterr().err)
    assert (tmp_path / "out_000.png").read_bytes() == b"precious"


# -- 360 -----------------------------------------------------------------------------------
def test_equirect_jpeg_carries_photo_sphere_xmp(data, tmp_path, capsys):
    from omnicam.formats.spherical_metadata import read_jpeg_xmp

    out = tmp_path / "360.jpg"
    code = main(
        [
            "unwarp",
            str(data["image"]),
            "-c",
            str(data["calib"]),
            "--equirect",
            "128x64",
            "-o",
            str(out),
        ]
    )
    assert code == 0, capsys.readouterr().err
    assert cv2.imread(str(out)).shape == (64, 128, 3)
    xmp = read_jpeg_xmp(out.read_bytes()).decode()
    assert 'GPano:ProjectionType="equirectangular"' in xmp
    assert 'GPano:FullPanoWidthPixels="128"' in xmp


def test_equirect_mp4_carries_spherical_video_metadata(data, tmp_path, capsys):
    from omnicam.formats.spherical_metadata import find_boxes, parse_boxes

    out = tmp_path / "360.mp4"
    code = main(
        [
            "unwarp",
            str(data["video"]),
            "-c",
            str(data["calib"]),
            "-q",
            "--equirect",
            "128x64",
            "-o",
            str(out),
        ]
    )
    assert code == 0, capsys.readouterr().err
    assert video_frames(out) == (10, (128, 64))
    boxes = parse_boxes(out.read_bytes())
    trak = find_boxes(boxes, [b"moov", b"trak"])[0]
    assert any(c.kind == b"uuid" for c in trak.children)
    entry = find_boxes(boxes, [b"moov", b"trak", b"mdia", b"minf", b"stbl", b"stsd"])[0]
    assert any(c.kind == b"sv3d" for c in entry.children[0].children)
    assert hidden(tmp_path) == []


def _ffprobe_codec(path):
    return subprocess.run(
        ["ffprobe", "-v", "error", "-show_entries", "stream=codec_name", "-of", "csv=p=0"]
        + [str(path)],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()


@pytest.mark.skipif(shutil.which("ffprobe") is None, reason="ffprobe is not installed")
def test_each_video_output_names_its_codec_in_one_line(data, tmp_path, capsys):
    from omnicam.video import H264

    outs = [tmp_path / "a.mp4", tmp_path / "b.avi", tmp_path / "c.webm"]
    argv = ["unwarp", str(data["video"]), "-c", str(data["calib"])]
    for out, size in zip(outs, ("64x16", "32x8", "32x8")):
        argv += ["--panorama", size, "-o", str(out)]
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == 0, err
    lines = out.splitlines()
    assert len(lines) == 3
    probed = [_ffprobe_codec(p) for p in outs]
    edge = "; lower edge -60.0 deg: the fixed default, no camera reflection recorded"
    assert lines[1] == f"wrote {outs[1]} (10 frames, 32x8, codec MJPG{edge})"
    assert probed[1] == "mjpeg"
    assert lines[2] == f"wrote {outs[2]} (10 frames, 32x8, VP9 (VP90){edge})"
    assert probed[2] == "vp9"
    if probed[0] == "h264":  # an OpenCV with an H.264 encoder
        assert re.fullmatch(
            rf"wrote {outs[0]} \(10 frames, 64x16, H\.264 \((\w+)\){re.escape(edge)}\)", lines[0]
        )
        assert re.search(r"H\.264 \((\w+)\)", lines[0]).group(1) in H264
    else:
        assert probed[0] == "mpeg4"
        assert lines[0] == f"wrote {outs[0]} (10 frames, 64x16, codec mp4v{edge})"


@pytest.mark.skipif(shutil.which("ffprobe") is None, reason="ffprobe is not installed")
def test_the_mp4_fallback_is_said_once(data, tmp_path, capsys):
    outs = [tmp_path / "a.mp4", tmp_path / "b.mov", tmp_path / "c.avi"]
    argv = ["unwarp", str(data["video"]), "-c", str(data["calib"]), "--quiet"]
    for out in outs:
        argv += ["--panorama", "32x8", "-o", str(out)]
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == 0, err
    if _ffprobe_codec(outs[0]) == "h264":
        assert err == ""
        pytest.skip("this OpenCV writes H.264: nothing falls back")
    assert [_ffprobe_codec(p) for p in outs] == ["mpeg4", "mpeg4", "mjpeg"]
    assert err.splitlines() == [
        f"omnicam: warning: this OpenCV has no H.264 encoder, so {outs[0]} and {outs[1]} are "
        f"in mp4v, which browsers do not play; for a video they play, write .webm (VP9)"
    ]
    # a codec asked for is not a fallback
    code = main([*argv, "--overwrite", "--fourcc", "mp4v"])
    assert code == 0
    assert capsys.readouterr().err == ""


def test_each_panorama_line_says_where_its_lower_edge_came_from(data, rig, tmp_path, capsys):
    """A calibration that records the camera's reflection: the default panorama starts above it
    and its line says so; a given band says nothing."""
    from omnicam.views import default_elevation_range

    calib = tmp_path / "body.yaml"
    body = rig.replace(camera_reflection=(22.0, 50.0))  # a wide barrel: it shows up to -45 deg
    body.save(calib)
    outs = [tmp_path / "a.png", tmp_path / "b.png", tmp_path / "c_%02d.png"]
    views = ["--panorama", "64x16", "-o", str(outs[0])]
    views += ["--panorama", "64x16", "--elevation", "-50", "10", "-o", str(outs[1])]
    assert main(["unwarp", str(data["image"]), "-c", str(calib), *views]) == 0
    lo = default_elevation_range(body).lo
    assert -50.0 < lo < -40.0
    assert capsys.readouterr().out.splitlines() == [
        f"wrote {outs[0]} (64x16; lower edge {lo:.1f} deg: the camera's reflection as detected)",
        f"wrote {outs[1]} (64x16)",
    ]
    src = cv2.imread(str(data["image"]))
    expected = cv2.remap(src, *body.init_panorama_maps((64, 16)), cv2.INTER_LINEAR)
    np.testing.assert_array_equal(cv2.imread(str(outs[0])), expected)
    args = ["unwarp", str(data["video"]), "-c", str(calib), "--panorama", "32x8", "-o"]
    assert main([*args, str(outs[2]), "--max-frames", "2"]) == 0
    edge = f"lower edge {lo:.1f} deg: the camera's reflection as detected"
    assert capsys.readouterr().out.splitlines() == [f"wrote 2 frames as {outs[2]} ({edge})"]


@pytest.mark.parametrize("flag, size", [("--panorama", "121x30"), ("--equirect", "64x32")])
def test_yaw_turns_a_panorama_and_a_360_view(data, rig, tmp_path, capsys, flag, size):
    """``--yaw`` is the panorama's ``yaw``: its centre column looks at azimuth -yaw."""
    out = tmp_path / "v.png"
    argv = ["unwarp", str(data["image"]), "-c", str(data["calib"]), flag, size, "--yaw", "40"]
    assert main([*argv, "-o", str(out)]) == 0, capsys.readouterr().err
    w, h = (int(v) for v in size.split("x"))
    make = PanoramaView if flag == "--panorama" else equirect_view
    view = make((w, h), yaw=40.0)
    src = cv2.imread(str(data["image"]))
    expected = cv2.remap(src, *view.maps(rig), cv2.INTER_LINEAR)
    np.testing.assert_array_equal(cv2.imread(str(out)), expected)


def test_a_panorama_taller_than_wide_is_one_line_naming_the_size(data, tmp_path, capsys):
    out = tmp_path / "p.png"
    argv = ["unwarp", str(data["image"]), "-c", str(data["calib"]), "--panorama", "60x240"]
    code = main([*argv, "-o", str(out)])
    assert code == 2
    line = one_error_line(capsys.readouterr().err)
    assert "--panorama" in line and "taller than wide" in line and "size=(240, 60)" in line
    assert not out.exists()


def test_equirect_must_be_two_to_one_on_the_command_line(data, tmp_path, capsys):
    code = main(
        [
            "unwarp",
            str(data["image"]),
            "-c",
            str(data["calib"]),
            "--equirect",
            "128x60",
            "-o",
            str(tmp_path / "x.jpg"),
        ]
    )
    assert code == 2
    assert "2:1" in one_error_line(capsys.readouterr().err)


# -- views that see nothing ----------------------------------------------------------------
def test_view_mostly_outside_the_band_warns_in_the_api(rig):
    with pytest.warns(RuntimeWarning, match="visible_elevation_range"):
        rig.init_perspective_maps(K_from_fov(60, (40, 30)), (40, 30), R=rotation_from_ypr(0, 70, 0))
    with pytest.warns(RuntimeWarning, match="visible_elevation_range"):
        rig.init_panorama_maps((64, 16), elevation_range=(30, 80))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rig.init_panorama_maps((64, 16))  # the default band: no warning


def test_view_mostly_outside_the_band_warns_in_the_cli(data, tmp_path, capsys):
    code = main(
        [
            "unwarp",
            str(data["image"]),
            "-c",
            str(data["calib"]),
            "--perspective",
            "40x30",
            "--fov",
            "60",
            "--pitch",
            "70",
            "-o",
            str(tmp_path / "sky.png"),
        ]
    )
    captured = capsys.readouterr()
    assert code == 0, captured.err
    lines = [ln for ln in captured.err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("omnicam: warning: ")
    assert "visible_elevation_range" in lines[0]


# -- video output that is never lost -------------------------------------------------------
class DroppingWriter:
    """cv2.VideoWriter as on a full disk: it stops storing frames without saying so."""

    keep = 3
    real = cv2.VideoWriter

    def __init__(self, path, *args):
        self.w = self.real(path, *args)
        self.n = 0

    def isOpened(self):
        return self.w.isOpened()

    def write(self, frame):
        self.n += 1
        if self.n <= self.keep:
            self.w.write(frame)

    def release(self):
        self.w.release()


def test_frames_lost_on_write_fail_and_keep_the_old_output(data, tmp_path, capsys, monkeypatch):
    from omnicam.cli import unwarp

    out = tmp_path / "out.avi"
    write_video(out, 2, (64, 16))
    before = out.read_bytes()
    monkeypatch.setattr(unwarp.cv2, "VideoWriter", DroppingWriter)
    code = main(
        [
            "unwarp",
            str(data["video"]),
            "-c",
            str(data["calib"]),
            "-q",
            "--panorama",
            "64x16",
            "-o",
            str(out),
            "--overwrite",
        ]
    )
    line = one_error_line(capsys.readouterr().err)
    assert code == 1
    assert "only 3 of 10 frames" in line and "unchanged" in line
    assert out.read_bytes() == before
    assert hidden(tmp_path) == []


def test_full_disk_stops_early_and_keeps_the_old_output(data, tmp_path, capsys, monkeypatch):
    from omnicam import video

    out = tmp_path / "out.avi"
    write_video(out, 2, (64, 16))
    before = out.read_bytes()
    long_video = write_video(tmp_path / "long.avi", 40)
    monkeypatch.setattr(video, "_free_bytes", lambda path: 1000)
    code = main(
        [
            "unwarp",
            str(long_video),
            "-c",
            str(data["calib"]),
            "-q",
            "--panorama",
            "64x16",
            "-o",
            str(out),
            "--overwrite",
        ]
    )
    line = one_error_line(capsys.readouterr().err)
    assert code == 1 and "no space left" in line and "after 16 frames" in line
    assert out.read_bytes() == before
    assert hidden(tmp_path) == []


def test_ctrl_c_with_an_earlier_output_keeps_it_and_writes_a_partial_file(
    data, tmp_path, capsys, monkeypatch
):
    from omnicam import cli

    out = tmp_path / "out.avi"
    write_video(out, 2, (64, 16))
    before = out.read_bytes()
    real_update = cli.Progress.update

    def interrupt(self, frames, force=False):
        real_update(self, frames, force)
        if frames == 4 and not force:
            os.kill(os.getpid(), signal.SIGINT)  # a real signal, delivered to our handler

    monkeypatch.setattr(cli.Progress, "update", interrupt)
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
            "--overwrite",
        ]
    )
    err = capsys.readouterr().err
    assert code == 130, err
    assert "Traceback" not in err
    assert out.read_bytes() == before
    partial = tmp_path / "out.partial.avi"
    assert video_frames(partial) == (4, (64, 16))
    assert "out.partial.avi" in err and "unchanged" in err
    assert hidden(tmp_path) == []


def _omnicam():
    exe = os.path.join(os.path.dirname(sys.executable), "omnicam")
    return exe if os.path.exists(exe) else None


def _long_video(folder, n=400):
    return write_video(folder / "long.avi", n, (400, 400))


@pytest.mark.skipif(
    _omnicam() is None or sys.platform == "win32",
    reason="needs the omnicam console script and POSIX signals",
)
def test_sigint_mid_stream_in_a_real_process(data, tmp_path):
    src = _long_video(tmp_path)
    calib = tmp_path / "rig.yaml"
    synthetic.misaligned_rig(image_size=(400, 400)).save(calib)
    out = tmp_path / "out.avi"
    p = subprocess.Popen(
        [
            _omnicam(),
            "unwarp",
            str(src),
            "-c",
            str(calib),
            "-q",
            "--panorama",
            "512x128",
            "-o",
            str(out),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.time() + 120
    while time.time() < deadline and p.poll() is None:  # wait until frames are being written
        tmp = [f for f in tmp_path.iterdir() if f.name.startswith(".out")]
        if tmp and tmp[0].stat().st_size > 0:
            break
        time.sleep(0.005)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    if p.returncode == 0:
        pytest.skip("the run ended before the signal arrived")
    assert p.returncode == 130, err
    line = one_error_line(err.replace("omnicam: warning: ", "omnicam: error: "))
    n = int(re.search(r"kept the (\d+) frames", line).group(1))
    assert "there was no earlier output" in line
    assert 0 < n < 400
    assert video_frames(out) == (n, (512, 128))
    assert hidden(tmp_path) == []


@pytest.mark.skipif(
    _omnicam() is None or sys.platform == "win32",
    reason="needs the omnicam console script and POSIX signals",
)
@pytest.mark.parametrize("delay", [0.15, 0.3])
def test_sigint_while_starting_is_one_line_and_exit_130(data, tmp_path, delay):
    src = _long_video(tmp_path, 60)
    p = subprocess.Popen(
        [
            _omnicam(),
            "unwarp",
            str(src),
            "-c",
            str(data["calib"]),
            "-q",
            "--panorama",
            "64x16",
            "-o",
            str(tmp_path / "out.avi"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    time.sleep(delay)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    if p.returncode == 0:
        pytest.skip("the run ended before the signal arrived")
    assert p.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "interrupted" in lines[0]
    assert hidden(tmp_path) == []


@pytest.fixture
def small_tmpfs(tmp_path):
    """A 300 KiB tmpfs (root only; skipped where mounting is not allowed)."""
    mnt = tmp_path / "full"
    mnt.mkdir()
    if sys.platform != "linux" or os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root on Linux")
    r = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=300k", "tmpfs", str(mnt)],
        capture_output=True,
        check=False,
    )
    if r.returncode != 0:
        pytest.skip("cannot mount a tmpfs here")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", str(mnt)], check=False)


@pytest.mark.parametrize(
    "ext, min_free",
    [("avi", None), ("avi", 0), ("mp4", 0)],
    ids=["free-space check", "read-back check avi", "read-back check mp4"],
)
def test_a_really_full_disk_never_replaces_the_old_output(
    data, tmp_path, small_tmpfs, capsys, monkeypatch, ext, min_free
):
    from omnicam import video

    if min_free is not None:
        monkeypatch.setattr(video, "MIN_FREE_BYTES", min_free)  # only the read-back check
    src = write_video(tmp_path / "src.avi", 200)
    out = small_tmpfs / f"out.{ext}"
    write_video(out, 20, (128, 32))
    before = out.read_bytes()
    code = main(
        [
            "unwarp",
            str(src),
            "-c",
            str(data["calib"]),
            "-q",
            "--panorama",
            "512x128",
            "-o",
            str(out),
            "--overwrite",
        ]
    )
    line = one_error_line(capsys.readouterr().err)
    assert code == 1 and "unchanged" in line
    assert ("no space left" in line) if min_free is None else ("can be read back" in line)
    assert out.read_bytes() == before
    assert sorted(p.name for p in small_tmpfs.iterdir()) == [out.name]


@pytest.mark.parametrize(
    "tilt, offset", [(0.0, (0.0, 0.0, 0.0)), (3.0, (1.5, -1.0, 1.0)), (5.0, (3.0, -4.0, 0.0))]
)
def test_default_panorama_leaves_out_the_cameras_own_reflection(tilt, offset):
    """No pixel of the default panorama sees a camera body of radius 30 mm (a ball about the
    camera centre; the synthetic renders use 10 mm), while the nadir rows of a full band do."""
    cam = synthetic.misaligned_rig(tilt, 30.0, offset, image_size=(320, 320))

    def body_pixels(mx, my):
        seen = mx != -10
        P, d = cam.unproject(np.stack([mx[seen], my[seen]], axis=1).astype(np.float64))
        w = P - cam.camera_center
        b = np.einsum("ij,ij->i", w, d)
        disc = b * b - (np.einsum("ij,ij->i", w, w) - 30.0**2)
        return int(np.count_nonzero((disc >= 0) & (-b - np.sqrt(np.maximum(disc, 0)) > 0)))

    assert body_pixels(*cam.init_panorama_maps((360, 90), m1type=cv2.CV_32FC1)) == 0
    full = cam.init_panorama_maps(
        (360, 90), elevation_range=(-90, 10), projection="equirectangular", m1type=cv2.CV_32FC1
    )
    assert body_pixels(*full) > 0
