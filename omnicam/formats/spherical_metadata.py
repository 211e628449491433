"""The metadata 360 viewers look for, in the files of :mod:`omnicam.spherical`'s views.

* Stills: Google Photo Sphere XMP (``GPano:`` namespace, ``ProjectionType equirectangular``,
  ``FullPano*`` and ``CroppedArea*`` fields) in an ``APP1`` segment of a JPEG
  (:func:`jpeg_with_photosphere_xmp`).
* Videos: the Spherical Video metadata of Google's ``spatial-media`` tools -- version 1, an
  RDF/XML ``uuid`` box (``ffcc8263-f855-4a93-8814-587a02521fdd``) in the video ``trak``; and
  version 2, an ``sv3d`` box (``svhd``, ``proj`` with ``prhd`` and ``equi``) in the video sample
  entry (:func:`inject_spherical_mp4`). Chunk offsets (``stco``/``co64``) are moved when
  ``moov`` precedes ``mdat``.
"""

from __future__ import annotations

import struct
import uuid

import numpy as np

__all__ = [
    "SPHERICAL_UUID",
    "find_boxes",
    "inject_spherical_mp4",
    "jpeg_with_photosphere_xmp",
    "parse_boxes",
    "photosphere_xmp",
    "read_jpeg_xmp",
    "spherical_v1_xml",
]


SPHERICAL_UUID = uuid.UUID("ffcc8263-f855-4a93-8814-587a02521fdd").bytes


XMP_HEADER = b"http://ns.adobe.com/xap/1.0/\x00"


SOFTWARE = "omnicam"


# -- stills: Photo Sphere XMP ------------------------------------------------------------------
def photosphere_xmp(full_size, cropped=None) -> bytes:
    """The GPano XMP packet of an equirectangular image.

    Parameters
    ----------
    full_size : (int, int)
        ``(W, H)`` of the full 360 x 180 panorama.
    cropped : (left, top, width, height) or None
        The part of it the image holds; ``None``: all of it.
    """
    W, H = (int(v) for v in full_size)
    left, top, cw, ch = (0, 0, W, H) if cropped is None else (int(v) for v in cropped)
    fields = {
        "UsePanoramaViewer": "True",
        "ProjectionType": "equirectangular",
        "PoseHeadingDegrees": "0.0",
        "CroppedAreaLeftPixels": left,
        "CroppedAreaTopPixels": top,
        "CroppedAreaImageWidthPixels": cw,
        "CroppedAreaImageHeightPixels": ch,
        "FullPanoWidthPixels": W,
        "FullPanoHeightPixels": H,
        "StitchingSoftware": SOFTWARE,
    }
    attrs = "\n    ".join(f'GPano:{k}="{v}"' for k, v in fields.items())
    return (
        '<?xpacket begin="\ufeff" id="W5M0MpCehiHzreSzNTczkc9d"?>\n'
        '<x:xmpmeta xmlns:x="adobe:ns:meta/">\n'
        ' <rdf:RDF xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#">\n'
        '  <rdf:Description rdf:about="" xmlns:GPano="http://ns.google.com/photos/1.0/panorama/"'
        f"\n    {attrs}/>\n"
        " </rdf:RDF>\n</x:xmpmeta>\n"
        '<?xpacket end="w"?>'
    ).encode()


def jpeg_with_photosphere_xmp(jpeg, full_size, cropped=None) -> bytes:
    """The JPEG bytes with an ``APP1`` XMP segment after ``SOI`` (and after ``APP0`` JFIF)."""
    jpeg = bytes(jpeg)
    if jpeg[:2] != b"\xff\xd8":
        raise ValueError("jpeg must start with the SOI marker FF D8")
    payload = XMP_HEADER + photosphere_xmp(full_size, cropped)
    if len(payload) + 2 > 65535:
        raise ValueError("XMP packet too large for one APP1 segment")
    segment = b"\xff\xe1" + struct.pack(">H", len(payload) + 2) + payload
    pos = 2
    if jpeg[2:4] == b"\xff\xe0":  # keep JFIF's APP0 first, as the JFIF standard asks
        pos = 4 + struct.unpack(">H", jpeg[4:6])[0]
    return jpeg[:pos] + segment + jpeg[pos:]


def read_jpeg_xmp(jpeg) -> bytes | None:
    """The XMP packet of a JPEG (bytes), or None: walks the marker segments before SOS."""
    jpeg = bytes(jpeg)
    pos = 2
    while pos + 4 <= len(jpeg) and jpeg[pos] == 0xFF:
        marker = jpeg[pos + 1]
        if marker == 0xDA:  # start of scan: no more metadata
            break
        length = struct.unpack(">H", jpeg[pos + 2 : pos + 4])[0]
        body = jpeg[pos + 4 : pos + 2 + length]
        if marker == 0xE1 and body.startswith(XMP_HEADER):
            return body[len(XMP_HEADER) :]
        pos += 2 + length
    return None


# -- videos: spherical video metadata v1 and v2 ------------------------------------------------
def spherical_v1_xml() -> bytes:
    """RDF/XML of Spherical Video V1 (as spatial-media's ``spherical_metadata`` writes it)."""
    return (
        '<?xml version="1.0"?>'
        "<rdf:SphericalVideo\n"
        'xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#"\n'
        'xmlns:GSpherical="http://ns.google.com/videos/1.0/spherical/">'
        "<GSpherical:Spherical>true</GSpherical:Spherical>"
        "<GSpherical:Stitched>true</GSpherical:Stitched>"
        f"<GSpherical:StitchingSoftware>{SOFTWARE}</GSpherical:StitchingSoftware>"
        "<GSpherical:ProjectionType>equirectangular</GSpherical:ProjectionType>"
        "</rdf:SphericalVideo>"
    ).encode()


def _box(kind, payload):
    return struct.pack(">I", 8 + len(payload)) + kind + payload


def _full_box(kind, version, flags, payload):
    return _box(kind, struct.pack(">I", (version << 24) | flags) + payload)


def _sv3d_box():
    svhd = _full_box(b"svhd", 0, 0, SOFTWARE.encode() + b"\x00")
    prhd = _full_box(b"prhd", 0, 0, struct.pack(">iii", 0, 0, 0))  # yaw, pitch, roll 16.16
    equi = _full_box(b"equi", 0, 0, struct.pack(">IIII", 0, 0, 0, 0))  # no crop: bounds 0
    return _box(b"sv3d", svhd + _box(b"proj", prhd + equi))


def _st3d_box():
    return _full_box(b"st3d", 0, 0, b"\x00")  # monoscopic


# containers whose payload is a list of boxes; stsd has 8 bytes first, sample entries 78
_CONTAINERS = {
    b"moov": 0,
    b"trak": 0,
    b"mdia": 0,
    b"minf": 0,
    b"stbl": 0,
    b"edts": 0,
    b"udta": 0,
    b"stsd": 8,
    b"sv3d": 0,
    b"proj": 0,
}


_VISUAL_ENTRIES = {
    b"avc1",
    b"avc3",
    b"hvc1",
    b"hev1",
    b"mp4v",
    b"mjpg",
    b"jpeg",
    b"vp09",
    b"av01",
    b"encv",
    b"s263",
    b"h263",
}


class Box:
    """An ISO-BMFF box: ``kind``, a ``head`` (bytes before children) and ``children`` or raw
    ``payload``."""

    __slots__ = ("children", "head", "kind", "payload")

    def __init__(
        self,
        kind: bytes,
        head: bytes = b"",
        children: list[Box] | None = None,
        payload: bytes = b"",
    ) -> None:
        self.kind, self.head, self.children, self.payload = kind, head, children, payload

    def to_bytes(self) -> bytes:
        body = self.head + (
            b"".join(c.to_bytes() for c in self.children)
            if self.children is not None
            else self.payload
        )
        if 8 + len(body) > 0xFFFFFFFF:
            return struct.pack(">I", 1) + self.kind + struct.pack(">Q", 16 + len(body)) + body
        return _box(self.kind, body)

    def __repr__(self) -> str:
        return f"Box({self.kind!r}, {len(self.children or [])} children)"


def parse_boxes(data, start=0, end=None, parent=None) -> list[Box]:
    """Boxes of ``data[start:end]`` as :class:`Box` trees (containers parsed, others raw)."""
    end = len(data) if end is None else end
    out = []
    pos = start
    while pos + 8 <= end:
        size, kind = struct.unpack(">I4s", data[pos : pos + 8])
        hdr = 8
        if size == 1:
            size = struct.unpack(">Q", data[pos + 8 : pos + 16])[0]
            hdr = 16
        elif size == 0:
            size = end - pos
        if size < hdr or pos + size > end:
            raise ValueError(f"malformed box {kind!r} at byte {pos}")
        body_start, body_end = pos + hdr, pos + size
        skip = _CONTAINERS.get(kind)
        if skip is None and parent == b"stsd" and kind in _VISUAL_ENTRIES:
            skip = 78
        if skip is not None:
            out.append(
                Box(
                    kind,
                    data[body_start : body_start + skip],
                    parse_boxes(data, body_start + skip, body_end, kind),
                )
            )
        else:
            out.append(Box(kind, payload=data[body_start:body_end]))
        pos = body_end
    return out


def find_boxes(boxes, path) -> list[Box]:
    """All boxes reached by the type path ``[b"moov", b"trak", ...]``."""
    found = [b for b in boxes if b.kind == path[0]]
    if len(path) == 1:
        return found
    return [x for b in found if b.children is not None for x in find_boxes(b.children, path[1:])]


def _is_video_trak(trak):
    for hdlr in find_boxes(trak.children, [b"mdia", b"hdlr"]):
        if hdlr.payload[8:12] == b"vide":
            return True
    return False


def _shift_chunk_offsets(boxes, delta):
    for stco in find_boxes(boxes, [b"moov", b"trak", b"mdia", b"minf", b"stbl", b"stco"]):
        p = stco.payload
        n = struct.unpack(">I", p[4:8])[0]
        offs = np.frombuffer(p[8 : 8 + 4 * n], ">u4").astype(np.int64) + delta
        stco.payload = p[:8] + offs.astype(">u4").tobytes() + p[8 + 4 * n :]
    for co64 in find_boxes(boxes, [b"moov", b"trak", b"mdia", b"minf", b"stbl", b"co64"]):
        p = co64.payload
        n = struct.unpack(">I", p[4:8])[0]
        offs = np.frombuffer(p[8 : 8 + 8 * n], ">u8").astype(np.int64) + delta
        co64.payload = p[:8] + offs.astype(">u8").tobytes() + p[8 + 8 * n :]


def _mark_spherical(trak) -> None:
    """Put V1's ``uuid`` box in a video ``trak`` and V2's ``st3d``/``sv3d`` in its visual
    sample entries, replacing any already there."""
    assert trak.children is not None  # trak is a container (_CONTAINERS), parsed
    trak.children = [
        c for c in trak.children if not (c.kind == b"uuid" and c.payload[:16] == SPHERICAL_UUID)
    ]
    trak.children.append(Box(b"uuid", payload=SPHERICAL_UUID + spherical_v1_xml()))
    for stsd in find_boxes(trak.children, [b"mdia", b"minf", b"stbl", b"stsd"]):
        assert stsd.children is not None  # so is stsd
        for entry in stsd.children:
            if entry.kind in _VISUAL_ENTRIES and entry.children is not None:
                entry.children = [c for c in entry.children if c.kind not in (b"sv3d", b"st3d")]
                entry.children += parse_boxes(_st3d_box() + _sv3d_box())


def inject_spherical_mp4(data) -> bytes:
    """An MP4/MOV (bytes) with Spherical Video V1 and V2 metadata in its video track.

    Raises
    ------
    ValueError
        Not an MP4 with a ``moov`` box and a video track.
    """
    boxes = parse_boxes(bytes(data))
    kinds = [b.kind for b in boxes]
    if b"moov" not in kinds:
        raise ValueError("not an MP4/MOV file: no moov box")
    traks = [t for t in find_boxes(boxes, [b"moov", b"trak"]) if _is_video_trak(t)]
    if not traks:
        raise ValueError("the MP4 has no video track")
    old_moov = len(next(b for b in boxes if b.kind == b"moov").to_bytes())
    for trak in traks:
        _mark_spherical(trak)
    moov = next(b for b in boxes if b.kind == b"moov")
    delta = len(moov.to_bytes()) - old_moov
    mdat_at = kinds.index(b"mdat") if b"mdat" in kinds else len(kinds)
    if kinds.index(b"moov") < mdat_at and delta:
        _shift_chunk_offsets(boxes, delta)
    return b"".join(b.to_bytes() for b in boxes)
