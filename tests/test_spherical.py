"""360 output: the equirectangular layout, Photo Sphere XMP in JPEG, spherical MP4 metadata."""

import math
import re
import shutil
import struct
import subprocess

import cv2
import numpy as np
import pytest

from omnicam import synthetic
from omnicam.formats.spherical_metadata import (
    SPHERICAL_UUID,
    find_boxes,
    inject_spherical_mp4,
    jpeg_with_photosphere_xmp,
    parse_boxes,
    read_jpeg_xmp,
)
from omnicam.spherical import equirect_view
from omnicam.views import UNSEEN, visible_elevation_range

RIG = synthetic.misaligned_rig(image_size=(160, 160))


def test_equirect_pixels_look_at_their_longitude_and_latitude():
    W, H = 72, 36
    yaw = 25.0
    mx, my = equirect_view((W, H), yaw=yaw).maps(RIG, cv2.CV_32FC1)
    _, hi = visible_elevation_range(RIG)
    for i, j in [(20, 36), (30, 5), (25, 60), (35, 0)]:
        lon = 360.0 * (j + 0.5) / W - 180.0
        lat = 90.0 - 180.0 * (i + 0.5) / H
        az = math.radians(-yaw - lon)  # azimuth -yaw at the centre, turning right as j grows
        d = np.array(
            [
                math.cos(math.radians(lat)) * math.cos(az),
                math.cos(math.radians(lat)) * math.sin(az),
                math.sin(math.radians(lat)),
            ]
        )
        exact = RIG.project_directions(d[None])[0]
        if np.isfinite(exact).all():
            np.testing.assert_allclose([mx[i, j], my[i, j]], exact, atol=0.01)
        else:
            assert mx[i, j] == UNSEEN
    # the top rows are above what the mirror sees
    assert (mx[0] == UNSEEN).all() and hi < 90.0 - 180.0 * 0.5 / H


def test_equirect_centre_column_is_the_cameras_forward():
    W, H = 64, 32
    mx, my = equirect_view((W, H)).maps(RIG, cv2.CV_32FC1)
    # between the two centre columns lies the azimuth of the camera's optical axis (3 deg
    # tilted): their mean source pixel is that horizon's
    x, y, _ = RIG.R[2]
    az = math.atan2(y, x)
    i = H // 2  # latitude -2.8 deg
    lat = math.radians(90.0 - 180.0 * (i + 0.5) / H)
    d = [math.cos(lat) * math.cos(az), math.cos(lat) * math.sin(az), math.sin(lat)]
    exact = RIG.project_directions(np.array([d]))[0]
    mid = 0.5 * (
        np.array([mx[i, W // 2 - 1], my[i, W // 2 - 1]]) + np.array([mx[i, W // 2], my[i, W // 2]])
    )
    np.testing.assert_allclose(mid, exact, atol=0.2)


def test_equirect_must_be_two_to_one():
    with pytest.raises(ValueError, match="2:1"):
        equirect_view((100, 40))


def test_photosphere_xmp_is_an_app1_segment_after_soi_and_parses_back():
    _, jpg = cv2.imencode(".jpg", np.zeros((32, 64, 3), np.uint8))
    out = jpeg_with_photosphere_xmp(jpg.tobytes(), (64, 32))
    assert out[:2] == b"\xff\xd8"
    xmp = read_jpeg_xmp(out).decode("utf-8")
    fields = dict(re.findall(r'GPano:(\w+)="([^"]*)"', xmp))
    assert fields["ProjectionType"] == "equirectangular"
    assert fields["FullPanoWidthPixels"] == "64" and fields["FullPanoHeightPixels"] == "32"
    assert fields["CroppedAreaImageWidthPixels"] == "64"
    assert fields["CroppedAreaLeftPixels"] == "0" and fields["CroppedAreaTopPixels"] == "0"
    # still a JPEG OpenCV decodes, pixel for pixel the same
    back = cv2.imdecode(np.frombuffer(out, np.uint8), cv2.IMREAD_UNCHANGED)
    ref = cv2.imdecode(jpg, cv2.IMREAD_UNCHANGED)
    assert np.array_equal(back, ref)
    # the APP1 segment comes right after SOI or after JFIF's APP0
    pos = 2
    if out[2:4] == b"\xff\xe0":
        pos = 4 + struct.unpack(">H", out[4:6])[0]
    assert out[pos : pos + 2] == b"\xff\xe1"


def _mp4(path, frames=4, size=(64, 32)):
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10, size)
    assert w.isOpened()
    for i in range(frames):
        w.write(np.full((size[1], size[0], 3), 40 * i, np.uint8))
    w.release()
    return path.read_bytes()


def _decoded(path):
    cap = cv2.VideoCapture(str(path))
    out = []
    while True:
        ok, f = cap.read()
        if not ok:
            break
        out.append(f)
    cap.release()
    return out


def test_spherical_mp4_boxes_v1_and_v2_parse_back(tmp_path):
    data = _mp4(tmp_path / "v.mp4")
    new = inject_spherical_mp4(data)
    (tmp_path / "v360.mp4").write_bytes(new)
    boxes = parse_boxes(new)
    traks = find_boxes(boxes, [b"moov", b"trak"])
    uuids = [b for t in traks for b in t.children if b.kind == b"uuid"]
    assert len(uuids) == 1 and uuids[0].payload[:16] == SPHERICAL_UUID
    xml = uuids[0].payload[16:].decode()
    assert "<GSpherical:Spherical>true</GSpherical:Spherical>" in xml
    assert "<GSpherical:ProjectionType>equirectangular</GSpherical:ProjectionType>" in xml
    entries = find_boxes(boxes, [b"moov", b"trak", b"mdia", b"minf", b"stbl", b"stsd"])[0]
    entry = entries.children[0]
    sv3d = [c for c in entry.children if c.kind == b"sv3d"]
    assert len(sv3d) == 1
    kinds = [c.kind for c in sv3d[0].children]
    assert kinds == [b"svhd", b"proj"]
    proj = sv3d[0].children[1]
    assert [c.kind for c in proj.children] == [b"prhd", b"equi"]
    equi = proj.children[1].payload
    assert struct.unpack(">IIIII", equi) == (0, 0, 0, 0, 0)  # version/flags, 4 zero bounds
    # the file still decodes to the same frames
    a, b = _decoded(tmp_path / "v.mp4"), _decoded(tmp_path / "v360.mp4")
    assert len(a) == len(b) == 4 and all(np.array_equal(x, y) for x, y in zip(a, b))
    # injecting twice does not duplicate the boxes
    again = parse_boxes(inject_spherical_mp4(new))
    traks = find_boxes(again, [b"moov", b"trak"])
    assert sum(c.kind == b"uuid" for t in traks for c in t.children) == 1


@pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="ffmpeg is not installed")
def test_moov_before_mdat_gets_its_chunk_offsets_moved(tmp_path):
    _mp4(tmp_path / "v.mp4")
    subprocess.run(
        [
            "ffmpeg",
            "-v",
            "error",
            "-y",
            "-i",
            str(tmp_path / "v.mp4"),
            "-c",
            "copy",
            "-movflags",
            "+faststart",
            str(tmp_path / "fs.mp4"),
        ],
        check=True,
    )
    data = (tmp_path / "fs.mp4").read_bytes()
    kinds = [b.kind for b in parse_boxes(data)]
    assert kinds.index(b"moov") < kinds.index(b"mdat")
    (tmp_path / "fs360.mp4").write_bytes(inject_spherical_mp4(data))
    a, b = _decoded(tmp_path / "fs.mp4"), _decoded(tmp_path / "fs360.mp4")
    assert len(a) == len(b) == 4 and all(np.array_equal(x, y) for x, y in zip(a, b))


@pytest.mark.skipif(shutil.which("ffprobe") is None, reason="ffprobe is not installed")
def test_ffprobe_sees_an_equirectangular_spherical_stream(tmp_path):
    (tmp_path / "v360.mp4").write_bytes(inject_spherical_mp4(_mp4(tmp_path / "v.mp4")))
    out = subprocess.run(
        ["ffprobe", "-v", "error", "-show_streams", str(tmp_path / "v360.mp4")],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert "Spherical Mapping" in out and "projection=equirectangular" in out


def test_not_an_mp4_is_refused():
    with pytest.raises(ValueError, match="moov"):
        inject_spherical_mp4(struct.pack(">I4s", 16, b"ftyp") + b"isom\x00\x00\x02\x00")
