"""Unwarper: the views of frames equal bare cv2.remap with the same tables; video in and out."""

import contextlib
import shutil
import subprocess

import cv2
import numpy as np
import pytest

from omnicam import Unwarper, synthetic
from omnicam import video as video_module
from omnicam._quiet import opencv_silenced
from omnicam.video import H264, OutputError, VideoOutput, open_capture, video_codec
from omnicam.views import UNSEEN, PanoramaView, PerspectiveView

VIEWS = {"pano": PanoramaView((256, 64)), "front": PerspectiveView((96, 72), fov=90.0, yaw=30.0)}


@pytest.fixture(scope="module")
def cam():
    return synthetic.misaligned_rig()


@pytest.fixture(scope="module")
def unwarper(cam):
    return Unwarper.from_camera(cam, VIEWS)


def frames(n, size=(500, 500), seed=0):
    rng = np.random.default_rng(seed)
    w, h = size
    base = cv2.resize(rng.integers(0, 256, (h // 10, w // 10, 3), dtype=np.uint8), (w, h))
    return [np.roll(base, 7 * i, axis=1) for i in range(n)]


def write_video(path, imgs, fps=10.0):
    h, w = imgs[0].shape[:2]
    wr = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (w, h))
    assert wr.isOpened()
    for im in imgs:
        wr.write(im)
    wr.release()


def test_unwarp_equals_bare_remap_into_preallocated_outputs(unwarper):
    first = None
    for frame in frames(3):
        out = unwarper.unwarp(frame)
        assert list(out) == ["pano", "front"]
        for name, img in out.items():
            m1, m2 = unwarper.maps[name]
            ref = cv2.remap(frame, m1, m2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
            np.testing.assert_array_equal(img, ref)
        if first is None:
            first = out["pano"]
        assert out["pano"] is first  # the same buffer every frame
    assert unwarper.view_size("pano") == (256, 64) and unwarper(frame)["front"].shape == (72, 96, 3)


def test_unwarp_copy_true_returns_arrays_later_frames_do_not_touch(unwarper):
    a, b = frames(2)
    kept = unwarper.unwarp(a, copy=True)
    again = unwarper.unwarp(b)
    assert kept["pano"] is not again["pano"]
    m1, m2 = unwarper.maps["pano"]
    np.testing.assert_array_equal(kept["pano"], cv2.remap(a, m1, m2, cv2.INTER_LINEAR))
    assert not np.array_equal(kept["pano"], again["pano"])


@pytest.mark.parametrize(
    "bad", [None, [[1, 2], [3, 4]], np.zeros((0, 5, 3), np.uint8)], ids=["None", "list", "empty"]
)
def test_unwarp_refuses_what_is_not_an_image_with_value_error(unwarper, bad):
    with pytest.raises(ValueError, match="frame"):
        unwarper.unwarp(bad)


def test_unseen_pixels_get_the_border_value(cam):
    with pytest.warns(RuntimeWarning, match="visible_elevation_range"):  # it sees nothing
        u = Unwarper.from_camera(
            cam, {"up": PerspectiveView((40, 30), fov=60.0, pitch=85.0)}, border_value=(1, 2, 3)
        )
    out = u.unwarp(frames(1)[0])["up"]
    assert (out == (1, 2, 3)).all()


def test_grey_and_float_frames_and_interpolation_options(cam):
    u = Unwarper.from_camera(cam, VIEWS, m1type=cv2.CV_32FC1, interpolation=cv2.INTER_NEAREST)
    grey = cv2.cvtColor(frames(1)[0], cv2.COLOR_BGR2GRAY)
    out = u.unwarp(grey)
    assert out["pano"].shape == (64, 256) and out["pano"].dtype == np.uint8
    m1, m2 = u.maps["pano"]
    np.testing.assert_array_equal(out["pano"], cv2.remap(grey, m1, m2, cv2.INTER_NEAREST))
    out = u.unwarp(grey.astype(np.float32))  # reallocated for the new dtype
    assert out["pano"].dtype == np.float32


def test_given_maps_and_bad_maps():
    mx = np.full((4, 5), UNSEEN, np.float32)
    u = Unwarper({"v": (mx, mx.copy())})
    assert u.source_size is None and u.unwarp(np.zeros((9, 9), np.uint8))["v"].shape == (4, 5)
    with pytest.raises(ValueError, match="maps"):
        Unwarper({})
    with pytest.raises(ValueError, match="'v'"):
        Unwarper({"v": (mx, None)})
    with pytest.raises(ValueError, match="'v'"):
        Unwarper({"v": (mx.astype(np.float64), mx)})
    with pytest.raises(ValueError, match="interpolation"):
        Unwarper({"v": (mx, mx)}, interpolation=99)


def test_frame_of_another_size_raises_and_frame_size_rescales(cam):
    u = Unwarper.from_camera(cam, VIEWS)
    assert u.source_size == (500, 500)
    with pytest.raises(ValueError, match="frame_size"):
        u.unwarp(np.zeros((250, 250, 3), np.uint8))
    half = Unwarper.from_camera(cam, VIEWS, frame_size=(250, 250))
    assert half.source_size == (250, 250)
    ref = Unwarper.from_camera(cam.scaled((250, 250)), VIEWS)
    for name in VIEWS:
        np.testing.assert_array_equal(half.maps[name][0], ref.maps[name][0])


def test_from_camera_rejects_bad_view_specs(cam):
    with pytest.raises(ValueError, match="'x'"):
        Unwarper.from_camera(cam, {"x": (256, 64)})
    with pytest.raises(ValueError, match="projection"):
        PanoramaView((256, 64), projection="fisheye")
    with pytest.raises(ValueError, match="fov"):
        PerspectiveView((64, 48), fov=200.0)


def test_stream_over_a_video_writes_every_view(tmp_path, unwarper):
    src = tmp_path / "in.avi"
    imgs = frames(6)
    write_video(src, imgs)
    outs = {"pano": tmp_path / "pano.avi", "front": tmp_path / "front.avi"}
    seen = []
    for i, views in unwarper.stream(src, outs, fourcc="MJPG"):
        seen.append(i)
        assert views["pano"].shape == (64, 256, 3)
    assert seen == list(range(6))
    for name, path in outs.items():
        cap = cv2.VideoCapture(str(path))
        n = 0
        while True:
            ok, fr = cap.read()
            if not ok:
                break
            n += 1
            assert fr.shape[1::-1] == unwarper.view_size(name)
        cap.release()
        assert n == 6
    assert (
        unwarper.run(str(src), {"pano": tmp_path / "again.avi"}, fourcc="MJPG", max_frames=4) == 4
    )


def test_stopping_early_keeps_a_valid_file(tmp_path, unwarper):
    src = tmp_path / "in.avi"
    write_video(src, frames(8))
    out = tmp_path / "partial.avi"
    with contextlib.closing(unwarper.stream(src, {"front": out}, fourcc="MJPG")) as gen:
        for i, _ in gen:
            if i == 2:
                break
    cap = cv2.VideoCapture(str(out))
    n = 0
    while cap.read()[0]:
        n += 1
    cap.release()
    assert n == 3


def test_stream_bad_sources_and_outputs(tmp_path, unwarper):
    with pytest.raises(ValueError, match="no such file"):
        next(unwarper.stream(tmp_path / "missing.mp4"))
    junk = tmp_path / "junk.avi"
    junk.write_bytes(b"not a video")
    with pytest.raises(ValueError, match="cannot open .*junk.avi"):
        next(unwarper.stream(junk))
    with pytest.raises(ValueError, match="unknown view"):
        next(unwarper.stream(junk, {"nope": tmp_path / "o.avi"}))
    with pytest.raises(ValueError, match="source"):
        open_capture(3.5)


def test_stream_refuses_odd_sized_video_outputs(tmp_path):
    cam = synthetic.aligned_rig((64, 64))
    unwarper = Unwarper.from_camera(cam, {"pano": PanoramaView((33, 8))})
    out = tmp_path / "p.avi"
    with pytest.raises(ValueError) as e:
        next(unwarper.stream(0, outputs={"pano": out}))
    assert str(e.value) == (
        f"cannot write video {out} at 33x8: a video needs an even width and height (OpenCV "
        f"drops an odd last row or column); give 34x8 (or another even size)"
    )


def test_perspective_view_and_maps_take_k_new_size_r_in_one_order(cam):
    from omnicam.views import K_from_fov, rotation_from_ypr

    K = K_from_fov(90.0, (40, 30))
    R = rotation_from_ypr(30.0, -10.0)
    a = PerspectiveView(K, (40, 30), R).maps(cam)  # init_perspective_maps' order
    b = cam.init_perspective_maps(K, (40, 30), R)
    np.testing.assert_array_equal(a[0], b[0])
    with pytest.raises(ValueError, match="K_new given twice"):
        PerspectiveView(K, (40, 30), K_new=K)


def test_perspective_arguments_in_the_wrong_order_say_the_order(cam):
    from omnicam.views import K_from_fov

    K = K_from_fov(90.0, (40, 30))
    with pytest.raises(ValueError, match=r"init_perspective_maps\(camera, K_new, size"):
        cam.init_perspective_maps((40, 30), K)
    with pytest.raises(ValueError, match="K_new="):
        PerspectiveView((40, 30), K)
    a = PerspectiveView(K_new=K, size=(40, 30)).maps(cam)  # keywords: one spelling for both
    b = cam.init_perspective_maps(K_new=K, size=(40, 30))
    np.testing.assert_array_equal(a[0], b[0])


# -- the safe video writer: temporary file, checked, published atomically ---------------------
def hidden(folder):
    """Temporary files (``.NAME.omnicam-tmp-...``) left in ``folder``."""
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def decoded(path):
    return video_module.count_frames(path)


def test_stream_writes_a_temporary_file_and_replaces_the_output_only_at_the_end(tmp_path, unwarper):
    src = tmp_path / "in.avi"
    write_video(src, frames(5))
    out = tmp_path / "pano.avi"
    write_video(out, frames(2, (256, 64)))
    before = out.read_bytes()
    s = unwarper.stream(src, {"pano": out}, fourcc="MJPG")
    for _ in s:
        assert out.read_bytes() == before  # the earlier output, untouched while writing
        assert len(hidden(tmp_path)) == 1  # the frames go beside it
    assert decoded(out) == 5 and hidden(tmp_path) == []
    assert s.written["pano"] == (str(out), 5, "MJPG", True)


@pytest.mark.parametrize("where", ["in the stream", "in the caller's loop"])
def test_an_exception_keeps_the_earlier_output_and_leaves_no_temporary_file(
    tmp_path, cam, monkeypatch, where
):
    src = tmp_path / "in.avi"
    write_video(src, frames(6))
    out = tmp_path / "pano.avi"
    write_video(out, frames(2, (256, 64)))
    before = out.read_bytes()
    u = Unwarper.from_camera(cam, VIEWS)
    if where == "in the stream":  # after two frames were written, say a frame of another size
        real, calls = u.unwarp, []

        def failing(frame):
            calls.append(1)
            if len(calls) == 3:
                raise ValueError("a frame of another size")
            return real(frame)

        monkeypatch.setattr(u, "unwarp", failing)
    with pytest.raises(ValueError, match="another size"):
        with u.stream(src, {"pano": out, "front": tmp_path / "front.avi"}) as s:
            for i, _ in s:
                if i == 2:
                    raise ValueError("another size, found by the caller")
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.avi", "pano.avi"]
    assert s.written == {}


def test_ctrl_c_keeps_the_frames_so_far_beside_an_earlier_output(tmp_path, cam, monkeypatch):
    src = tmp_path / "in.avi"
    write_video(src, frames(6))
    out, new = tmp_path / "pano.avi", tmp_path / "front.avi"
    write_video(out, frames(2, (256, 64)))
    before = out.read_bytes()
    u = Unwarper.from_camera(cam, VIEWS)
    real, calls = u.unwarp, []

    def interrupted(frame):
        calls.append(1)
        if len(calls) == 4:
            raise KeyboardInterrupt
        return real(frame)

    monkeypatch.setattr(u, "unwarp", interrupted)
    s = u.stream(src, {"pano": out, "front": new}, fourcc="MJPG")
    with pytest.raises(KeyboardInterrupt):
        for _ in s:
            pass
    assert out.read_bytes() == before
    partial = tmp_path / "pano.partial.avi"
    assert decoded(partial) == 3 and decoded(new) == 3  # no earlier front.avi: kept in it
    assert s.written["pano"] == (str(partial), 3, "MJPG", False)
    assert s.written["front"] == (str(new), 3, "MJPG", False)
    assert hidden(tmp_path) == []


def test_closing_the_stream_early_keeps_the_frames_and_abort_removes_them(tmp_path, unwarper):
    src = tmp_path / "in.avi"
    write_video(src, frames(8))
    with unwarper.stream(src, {"pano": tmp_path / "kept.avi"}) as s:
        for i, _ in s:
            if i == 2:
                break
    assert s.written["pano"].complete is False and decoded(tmp_path / "kept.avi") == 3
    s = unwarper.stream(src, {"pano": tmp_path / "gone.avi"})
    next(s)
    s.abort()
    assert not (tmp_path / "gone.avi").exists() and hidden(tmp_path) == []


def test_overwrite_false_refuses_an_existing_output(tmp_path, unwarper):
    src = tmp_path / "in.avi"
    write_video(src, frames(2))
    out = tmp_path / "pano.avi"
    out.write_bytes(b"mine")
    with pytest.raises(OutputError, match="exists"):
        unwarper.run(src, {"pano": out}, overwrite=False)
    assert out.read_bytes() == b"mine" and hidden(tmp_path) == []


class DroppingWriter:
    """A cv2.VideoWriter that loses every frame after the first ``keep`` (as on a full disk)."""

    keep = 2

    def __init__(self, *args):
        self.w, self.n = REAL_WRITER(*args), 0

    def isOpened(self):
        return self.w.isOpened()

    def write(self, frame):
        self.n += 1
        if self.n <= self.keep:
            self.w.write(frame)

    def release(self):
        self.w.release()


REAL_WRITER = cv2.VideoWriter


def test_video_output_refuses_a_file_that_lost_frames(tmp_path, monkeypatch):
    out = tmp_path / "v.avi"
    out.write_bytes(b"earlier")
    monkeypatch.setattr(cv2, "VideoWriter", DroppingWriter)
    with pytest.raises(OutputError, match="only 2 of 5 frames"):
        with VideoOutput(out, (64, 32), 10.0, "MJPG") as video:
            for frame in frames(5, (64, 32)):
                video.write(frame)
    assert out.read_bytes() == b"earlier" and hidden(tmp_path) == []


def test_video_output_refuses_odd_sizes_and_bad_frame_rates(tmp_path):
    with pytest.raises(ValueError, match=r"v\.avi at 63x31: .*even.*give 64x32"):
        VideoOutput(tmp_path / "v.avi", (63, 31), 10.0)
    with pytest.raises(ValueError, match="fps"):
        VideoOutput(tmp_path / "v.avi", (64, 32), float("nan"))
    assert list(tmp_path.iterdir()) == []


# -- the codec: H.264 where this OpenCV writes it, and said ---------------------------------
def _codec_in_file(path):
    return subprocess.run(
        [
            "ffprobe",
            "-v",
            "error",
            "-select_streams",
            "v:0",
            "-show_entries",
            "stream=codec_name",
            "-of",
            "csv=p=0",
            str(path),
        ],
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    ).stdout.strip()


@pytest.mark.skipif(shutil.which("ffprobe") is None, reason="ffprobe is not installed")
@pytest.mark.parametrize("ext", [".mp4", ".mov", ".webm", ".avi"])
def test_the_codec_the_stream_reports_is_the_one_in_the_file(tmp_path, unwarper, ext):
    src = tmp_path / "in.avi"
    write_video(src, frames(3))
    out = tmp_path / f"pano{ext}"
    s = unwarper.stream(src, {"pano": out})
    assert sum(1 for _ in s) == 3
    fourcc = s.fourcc["pano"]
    assert s.written["pano"].fourcc == fourcc
    expected = video_module.VIDEO_CODECS[ext]
    assert fourcc in expected
    if fourcc != expected[0]:  # fell back: the codecs before it really do not write here
        for code in expected[: expected.index(fourcc)]:
            with pytest.raises(OutputError, match=code):
                video_codec(tmp_path / f"probe{ext}", (256, 64), fourcc=code)
    names = {"mp4v": "mpeg4", "MJPG": "mjpeg", "VP90": "vp9", "VP80": "vp8"}
    names.update(dict.fromkeys(H264, "h264"))
    assert _codec_in_file(out) == names[fourcc]
    assert hidden(tmp_path) == []


def _writes_here(path, fourcc):
    """Whether this OpenCV writes a frame with ``fourcc`` into ``path`` that reads back
    (cv2 itself, not video_codec, which is under test)."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), 10.0, (64, 32))
    try:
        if not writer.isOpened():
            return False
        writer.write(np.zeros((32, 64, 3), np.uint8))
    finally:
        writer.release()
    return path.exists() and video_module.count_frames(path) == 1


@pytest.mark.skipif(shutil.which("ffprobe") is None, reason="ffprobe is not installed")
def test_mp4_gets_h264_where_this_opencv_writes_it(tmp_path):
    with opencv_silenced():
        h264 = [c for c in ("avc1", "H264", "X264") if _writes_here(tmp_path / f"{c}.mp4", c)]
    if not h264:
        pytest.skip(
            "this OpenCV's FFmpeg has no H.264 encoder (the opencv-python wheels ship none); "
            "the fallback is tested by test_the_mp4_fallback_is_said_once"
        )
    out = tmp_path / "v.mp4"
    with VideoOutput(out, (64, 32), 10.0) as video:
        video.write(np.zeros((32, 64, 3), np.uint8))
    assert video.fourcc == h264[0]
    assert _codec_in_file(out) == "h264"
    assert not video_module.fell_back(out, video.fourcc)


@pytest.mark.skipif(shutil.which("ffprobe") is None, reason="ffprobe is not installed")
def test_webm_gets_vp9_where_this_opencv_writes_it(tmp_path):
    with opencv_silenced():
        vp = [c for c in ("VP90", "VP80") if _writes_here(tmp_path / f"{c}.webm", c)]
    if not vp:
        pytest.skip("this OpenCV's FFmpeg has neither a VP9 nor a VP8 encoder")
    out = tmp_path / "v.webm"
    with VideoOutput(out, (64, 32), 10.0) as video:
        video.write(np.zeros((32, 64, 3), np.uint8))
    assert video.fourcc == vp[0]
    assert _codec_in_file(out) == {"VP90": "vp9", "VP80": "vp8"}[vp[0]]
    assert video_module.web_codec(video.fourcc) in ("VP9", "VP8")


def test_only_a_default_codec_browsers_do_not_play_is_a_fallback():
    assert video_module.fell_back("a.mp4", "mp4v")
    assert video_module.fell_back("a.MOV", "mp4v")
    assert not video_module.fell_back("a.mp4", "avc1")
    assert not video_module.fell_back("a.webm", "VP80")
    assert not video_module.fell_back("a.avi", "MJPG")  # .avi's first choice is no web codec


class OpensButWritesNothing:
    """A writer for the codec ``"avc1"`` that opens and writes nothing (as some builds do)."""

    def __init__(self, path, fourcc, *args):
        self.real = (
            None if fourcc == cv2.VideoWriter_fourcc(*"avc1") else REAL_WRITER(path, fourcc, *args)
        )

    def isOpened(self):
        return True if self.real is None else self.real.isOpened()

    def write(self, frame):
        if self.real is not None:
            self.real.write(frame)

    def release(self):
        if self.real is not None:
            self.real.release()


def test_a_codec_that_opens_but_writes_nothing_is_passed_over(tmp_path, monkeypatch):
    monkeypatch.setattr(cv2, "VideoWriter", OpensButWritesNothing)
    path = tmp_path / "v.avi"
    assert video_codec(path, (64, 32), fourcc=("avc1", "MJPG")) == "MJPG"
    with pytest.raises(OutputError, match="cannot write codec avc1 into .avi"):
        video_codec(path, (64, 32), fourcc="avc1")
    assert list(tmp_path.iterdir()) == []


def test_a_given_codec_is_used_and_a_bad_one_refused(tmp_path):
    assert video_codec(tmp_path / "v.avi", (64, 32), fourcc="MJPG") == "MJPG"
    with pytest.raises(ValueError, match="4-character"):
        video_codec(tmp_path / "v.avi", (64, 32), fourcc="MJPEG")
    with pytest.raises(OutputError, match="zzzz"):
        VideoOutput(tmp_path / "v.avi", (64, 32), 10.0, fourcc="zzzz")
    assert list(tmp_path.iterdir()) == []
