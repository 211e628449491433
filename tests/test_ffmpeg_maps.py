"""Maps for ffmpeg's remap filter (16-bit PGM), .npy and FileStorage; ffmpeg itself if present."""

import shutil
import subprocess

import cv2
import numpy as np
import pytest

from omnicam import synthetic
from omnicam.cli import main
from omnicam.formats.maps import (
    UNSEEN_PGM,
    ffmpeg_maps,
    write_ffmpeg_maps,
    write_filestorage_maps,
    write_npy_maps,
)

RIG = synthetic.misaligned_rig(image_size=(160, 160))
SIZE = (96, 32)
FFMPEG = shutil.which("ffmpeg")


@pytest.fixture(scope="module")
def maps():
    # a band reaching above what the mirror sees, so some output pixels are unseen
    return RIG.init_panorama_maps(SIZE, elevation_range=(-60.0, 40.0), m1type=cv2.CV_32FC1)


def _header(path):
    with open(path, "rb") as f:
        return f.read(20)


def test_pgm_header_maxval_and_big_endian_values(tmp_path, maps):
    px, py = write_ffmpeg_maps(tmp_path / "m", *maps, RIG.image_size)
    assert _header(px).startswith(b"P5\n96 32\n65535\n")
    xmap = cv2.imread(str(px), cv2.IMREAD_UNCHANGED)
    ymap = cv2.imread(str(py), cv2.IMREAD_UNCHANGED)
    assert xmap.dtype == ymap.dtype == np.uint16
    with open(px, "rb") as f:
        raw = f.read()[len(b"P5\n96 32\n65535\n") :]
    assert len(raw) == 96 * 32 * 2
    assert raw[0] * 256 + raw[1] == xmap[0, 0]  # most significant byte first
    map_x, map_y = maps
    seen = xmap != UNSEEN_PGM
    assert seen.any() and (~seen).any()
    np.testing.assert_array_equal(xmap[seen], np.rint(map_x[seen]))
    np.testing.assert_array_equal(ymap[seen], np.rint(map_y[seen]))
    assert np.array_equal(seen, ymap != UNSEEN_PGM)
    assert (map_x[~seen] < -0.5).all()  # unseen in the float table (UNSEEN = -10)


def test_rounded_coordinates_outside_the_frame_are_unseen():
    mx = np.array([[-0.6, -0.4, 9.4, 9.6]], np.float32)
    my = np.zeros_like(mx)
    xmap, ymap = ffmpeg_maps(mx, my, (10, 10))
    assert xmap.tolist() == [[UNSEEN_PGM, 0, 9, UNSEEN_PGM]]
    assert ymap.tolist() == [[UNSEEN_PGM, 0, 0, UNSEEN_PGM]]


def test_npy_and_filestorage_maps_round_trip(tmp_path, maps):
    px, py = write_npy_maps(tmp_path / "m", *maps)
    np.testing.assert_array_equal(np.load(px), maps[0])
    np.testing.assert_array_equal(np.load(py), maps[1])
    path = write_filestorage_maps(tmp_path / "m.yaml", *maps)
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    np.testing.assert_array_equal(fs.getNode("map_x").mat(), maps[0])
    fs.release()


def _run(args):
    r = subprocess.run(
        ["ffmpeg", "-v", "error", "-y", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert r.returncode == 0, r.stderr


@pytest.mark.skipif(FFMPEG is None, reason="ffmpeg is not installed")
@pytest.mark.parametrize("fmt", ["gray", "rgb24"])
def test_ffmpeg_remap_equals_cv2_remap_nearest_pixel_for_pixel(tmp_path, maps, fmt):
    rng = np.random.default_rng(3)
    src = rng.integers(0, 256, (160, 160) if fmt == "gray" else (160, 160, 3), dtype=np.uint8)
    cv2.imwrite(str(tmp_path / "src.png"), src)
    px, py = write_ffmpeg_maps(tmp_path / "m", *maps, RIG.image_size)
    _run(
        [
            "-i",
            tmp_path / "src.png",
            "-i",
            px,
            "-i",
            py,
            "-lavfi",
            f"format={fmt},remap",
            "-frames:v",
            "1",
            tmp_path / "out.png",
        ]
    )
    got = cv2.imread(str(tmp_path / "out.png"), cv2.IMREAD_UNCHANGED)
    if fmt == "gray" and got.ndim == 3:  # ffmpeg may store gray PNG as RGB: all planes equal
        assert (got == got[..., :1]).all()
        got = got[..., 0]
    ref = cv2.remap(src, *maps, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    assert np.array_equal(got, ref)


@pytest.mark.skipif(FFMPEG is None, reason="ffmpeg is not installed")
def test_ffmpeg_yuv444p_pipeline_equals_cv2_remap_per_plane(tmp_path, maps):
    """The printed pipeline (format=yuv444p,remap): each plane is cv2.remap of the source's
    plane, with ffmpeg's black (16, 128, 128) where the mirror sees nothing."""
    rng = np.random.default_rng(4)
    src = rng.integers(0, 256, (160, 160, 3), dtype=np.uint8)
    cv2.imwrite(str(tmp_path / "src.png"), src)
    _run(
        [
            "-i",
            tmp_path / "src.png",
            "-vf",
            "format=yuv444p",
            "-f",
            "rawvideo",
            tmp_path / "src.yuv",
        ]
    )
    yuv = np.fromfile(tmp_path / "src.yuv", np.uint8).reshape(3, 160, 160)
    px, py = write_ffmpeg_maps(tmp_path / "m", *maps, RIG.image_size)
    _run(
        [
            "-i",
            tmp_path / "src.png",
            "-i",
            px,
            "-i",
            py,
            "-lavfi",
            "format=yuv444p,remap",
            "-f",
            "rawvideo",
            "-pix_fmt",
            "yuv444p",
            tmp_path / "out.yuv",
        ]
    )
    got = np.fromfile(tmp_path / "out.yuv", np.uint8).reshape(3, SIZE[1], SIZE[0])
    for plane, fill in zip(range(3), (16, 128, 128)):
        ref = cv2.remap(
            yuv[plane], *maps, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=fill
        )
        assert np.array_equal(got[plane], ref), plane


def test_cli_maps_writes_pgms_and_prints_the_ffmpeg_command(tmp_path, capsys):
    calib = tmp_path / "rig.yaml"
    RIG.save(calib)
    code = main(
        [
            "maps",
            str(calib),
            "--panorama",
            "96x32",
            "--elevation",
            "-60",
            "40",
            "--ffmpeg",
            "-o",
            str(tmp_path / "pano"),
        ]
    )
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "format=yuv444p,remap" in out and "pano_x.pgm" in out and "pano_y.pgm" in out
    assert _header(tmp_path / "pano_x.pgm").startswith(b"P5\n96 32\n65535\n")
    xmap = cv2.imread(str(tmp_path / "pano_x.pgm"), cv2.IMREAD_UNCHANGED)
    assert xmap.dtype == np.uint16 and xmap.shape == (32, 96)


def test_cli_maps_supersampling_makes_k_times_larger_maps(tmp_path, capsys):
    calib = tmp_path / "rig.yaml"
    RIG.save(calib)
    code = main(
        [
            "maps",
            str(calib),
            "--perspective",
            "40x30",
            "--fov",
            "80",
            "--ffmpeg",
            "--supersample",
            "2",
            "-o",
            str(tmp_path / "p"),
        ]
    )
    out, err = capsys.readouterr()
    assert code == 0, err
    xmap = cv2.imread(str(tmp_path / "p_x.pgm"), cv2.IMREAD_UNCHANGED)
    assert xmap.shape == (60, 80)
    assert "scale=40:30" in out


def test_cli_maps_npy(tmp_path, capsys):
    calib = tmp_path / "rig.yaml"
    RIG.save(calib)
    assert (
        main(["maps", str(calib), "--panorama", "96x32", "--npy", "-o", str(tmp_path / "m")]) == 0
    ), capsys.readouterr().err
    ref = RIG.init_panorama_maps((96, 32), m1type=cv2.CV_32FC1)
    np.testing.assert_array_equal(np.load(tmp_path / "m_x.npy"), ref[0])


@pytest.mark.parametrize(
    "argv",
    [["--panorama", "48x16"], ["--perspective", "40x30", "--fov", "80"], ["--equirect", "64x32"]],
)
def test_supersampled_maps_average_to_the_plain_ones(argv):
    """The k x k blocks of the fine maps are centred on the coarse pixels."""
    import argparse

    from omnicam.cli.maps import _scaled_view
    from omnicam.cli.unwarp import add_view_arguments, view_specs

    p = argparse.ArgumentParser()
    add_view_arguments(p)
    p.set_defaults(ordered=None)
    spec = view_specs(p.parse_args([*argv, "-o", "x"]))[0]
    coarse = spec.view.maps(RIG, cv2.CV_32FC1)
    fine = _scaled_view(spec, RIG, 2).maps(RIG, cv2.CV_32FC1)
    h, w = coarse[0].shape
    for c, f in zip(coarse, fine):
        assert f.shape == (2 * h, 2 * w)
        seen = (c != -10) & (f.reshape(h, 2, w, 2) != -10).all(axis=(1, 3))
        mean = f.reshape(h, 2, w, 2).mean(axis=(1, 3))
        assert seen.sum() > 0.3 * seen.size
        assert np.abs(mean[seen] - c[seen]).max() < 0.1


@pytest.mark.skipif(FFMPEG is None, reason="ffmpeg is not installed")
def test_the_printed_command_runs(tmp_path, maps):
    import shlex

    from omnicam.formats.maps import ffmpeg_command

    src = tmp_path / "in.png"
    cv2.imwrite(str(src), np.full((160, 160, 3), 90, np.uint8))
    px, py = write_ffmpeg_maps(tmp_path / "m", *maps, RIG.image_size)
    cmd = ffmpeg_command(px, py, SIZE, 1, input_name=str(src), output_name=str(tmp_path / "o.png"))
    assert '-lavfi "format=yuv444p,remap"' in cmd
    args = shlex.split(cmd)
    r = subprocess.run(
        [args[0], "-v", "error", "-y", *args[1:]],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert r.returncode == 0, r.stderr
    assert cv2.imread(str(tmp_path / "o.png")).shape == (SIZE[1], SIZE[0], 3)


def test_the_printed_command_ends_in_yuv420p_for_videos_only():
    from omnicam.formats.maps import ffmpeg_command

    video = ffmpeg_command("x.pgm", "y.pgm", SIZE, 1, output_name="o.mp4")
    assert '-lavfi "format=yuv444p,remap,format=yuv420p"' in video
    sampled = ffmpeg_command("x.pgm", "y.pgm", SIZE, 2, output_name="o.mkv")
    assert sampled.endswith(f'scale={SIZE[0]}:{SIZE[1]}:flags=area,format=yuv420p" o.mkv')
    for still in ("o.png", "o.jpg", "frames_%04d.png"):
        assert "yuv420p" not in ffmpeg_command("x.pgm", "y.pgm", SIZE, output_name=still)
    odd = ffmpeg_command("x.pgm", "y.pgm", (95, 33), output_name="o.mp4")
    assert '"format=yuv444p,remap,crop=94:32:0:0,format=yuv420p"' in odd


def _probe(path):
    out = subprocess.run(
        [
            "ffprobe",
            "-v",
            "error",
            "-select_streams",
            "v:0",
            "-show_entries",
            "stream=codec_name,pix_fmt,width,height",
            "-of",
            "default=noprint_wrappers=1",
            str(path),
        ],
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    ).stdout
    return dict(line.split("=", 1) for line in out.split())


@pytest.mark.skipif(
    FFMPEG is None or shutil.which("ffprobe") is None, reason="ffmpeg is not installed"
)
@pytest.mark.parametrize("size", [SIZE, (95, 33)], ids=["even", "odd"])
def test_the_printed_video_command_makes_yuv420p_h264(tmp_path, size):
    """What browsers and players take: H.264 in 4:2:0 (ffmpeg's default codec for .mp4)."""
    import shlex

    from omnicam.formats.maps import ffmpeg_command

    if (
        "libx264"
        not in subprocess.run(
            [FFMPEG, "-hide_banner", "-encoders"], capture_output=True, text=True, check=False
        ).stdout
    ):
        pytest.skip("this ffmpeg has no libx264")
    src = tmp_path / "in.png"
    cv2.imwrite(str(src), np.full((160, 160, 3), 90, np.uint8))
    maps = RIG.init_panorama_maps(size, elevation_range=(-60.0, 40.0), m1type=cv2.CV_32FC1)
    px, py = write_ffmpeg_maps(tmp_path / "m", *maps, RIG.image_size)
    out = tmp_path / "o.mp4"
    args = shlex.split(ffmpeg_command(px, py, size, input_name=str(src), output_name=str(out)))
    r = subprocess.run(
        [args[0], "-v", "error", "-y", *args[1:]],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert r.returncode == 0, r.stderr
    info = _probe(out)
    assert info["codec_name"] == "h264" and info["pix_fmt"] == "yuv420p"
    assert (int(info["width"]), int(info["height"])) == (size[0] // 2 * 2, size[1] // 2 * 2)
