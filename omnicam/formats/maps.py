"""Remap tables as files for other tools: ffmpeg's ``remap`` filter (PGM), ``.npy``, FileStorage.

ffmpeg's ``remap`` filter takes two extra inputs, ``xmap`` and ``ymap``: 16-bit single-channel
images of the *output's* size whose values are integer source coordinates; it copies the
source pixel ``(xmap, ymap)`` (nearest neighbour, no interpolation) and paints the ``fill``
colour (black by default) where a coordinate is outside the source. :func:`ffmpeg_maps` turns
omnicam's float tables into such integers -- ``np.rint`` (round half to even, which is what
``cv2.remap(..., INTER_NEAREST)`` does with float maps) -- and writes :data:`UNSEEN_PGM` (65535)
where the mirror sees nothing or the rounded source pixel lies outside the frame, so ffmpeg and
``cv2.remap(..., INTER_NEAREST, borderMode=BORDER_CONSTANT)`` give the same pixels
(``tests/test_ffmpeg_maps.py`` runs ffmpeg when it is installed and compares exactly).

The pipelines checked pixel for pixel against ``cv2.remap(src, map_x, map_y, INTER_NEAREST,
borderMode=BORDER_CONSTANT, borderValue=0)`` on the float tables (ffmpeg 5.1):
``ffmpeg -i src.png -i x.pgm -i y.pgm -lavfi "format=gray,remap" out.png`` (also ``rgb24``) for
lossless stills, and the video pipeline ``-lavfi "format=yuv444p,remap"``, whose every plane
equals ``cv2.remap`` of the same plane of the yuv444p source with ffmpeg's black
``(16, 128, 128)`` as the border value (a lossy codec afterwards is the only difference); the
printed command then converts to ``yuv420p``, which every player takes (:func:`ffmpeg_command`).

The PGM files are binary ``P5`` with ``maxval`` exactly 65535 (two bytes per sample, most
significant byte first, as the Netpbm format defines 16-bit PGM), which ffmpeg reads as
``gray16be``. Supersampling: build the tables at ``k`` times the output size, remap, then let
ffmpeg scale down (``scale=W:H:flags=area``): nearest-neighbour picks averaged over ``k x k``.
"""

from __future__ import annotations

import os
import shlex

import cv2
import numpy as np
import numpy.typing as npt

from .._atomic import OutputError, atomic_output, write_bytes
from .._typing import PathLike
from ..images import read_image

__all__ = [
    "UNSEEN_PGM",
    "ffmpeg_command",
    "ffmpeg_maps",
    "float_maps",
    "pgm_bytes",
    "write_ffmpeg_maps",
    "write_filestorage_maps",
    "write_npy_maps",
    "write_pgm",
]

#: Map value for output pixels with no source pixel: outside any frame ffmpeg can read.
UNSEEN_PGM = 65535


def float_maps(map1, map2) -> tuple[np.ndarray, np.ndarray]:
    """``(map_x, map_y)`` float32 from any ``m1type`` omnicam returns."""
    if map1.ndim == 3 and map1.dtype == np.int16:
        return cv2.convertMaps(map1, map2, cv2.CV_32FC1)
    if map1.ndim == 3:
        return np.ascontiguousarray(map1[..., 0]), np.ascontiguousarray(map1[..., 1])
    return map1, map2


def ffmpeg_maps(map_x, map_y, source_size) -> tuple[npt.NDArray[np.uint16], npt.NDArray[np.uint16]]:
    """Integer source coordinates for ffmpeg's ``remap``: ``(xmap, ymap)`` uint16.

    Parameters
    ----------
    map_x, map_y : (H, W) float ndarray
        Float tables (``cv2.CV_32FC1``).
    source_size : (int, int)
        ``(width, height)`` of the frames the tables are for.

    Returns
    -------
    xmap, ymap : (H, W) uint16 ndarray
        ``rint`` of the tables; 65535 in both where the table has no source pixel.
    """
    w, h = (int(v) for v in source_size)
    if not (0 < w < UNSEEN_PGM and 0 < h < UNSEEN_PGM):
        raise ValueError(f"source_size must be (width, height) below 65535, got {source_size!r}")
    with np.errstate(invalid="ignore"):
        x = np.rint(np.asarray(map_x, dtype=np.float64))
        y = np.rint(np.asarray(map_y, dtype=np.float64))
        inside = (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1)
    xmap = np.full(x.shape, UNSEEN_PGM, np.uint16)
    ymap = np.full(x.shape, UNSEEN_PGM, np.uint16)
    xmap[inside] = x[inside].astype(np.uint16)
    ymap[inside] = y[inside].astype(np.uint16)
    return xmap, ymap


def pgm_bytes(image) -> bytes:
    """A 16-bit binary PGM (``P5``, maxval 65535, big-endian) of a uint16 image."""
    image = np.asarray(image)
    if image.ndim != 2 or image.dtype != np.uint16 or image.size == 0:
        raise ValueError(
            f"image must be a non-empty 2-D uint16 array, got {image.dtype} {image.shape}"
        )
    h, w = image.shape
    return f"P5\n{w} {h}\n65535\n".encode("ascii") + image.astype(">u2").tobytes()


def write_pgm(path, image, overwrite=True) -> None:
    """Write :func:`pgm_bytes` atomically, checked by reading it back (OpenCV reads a PGM of
    maxval 65535 as uint16, as ffmpeg reads it as ``gray16be``)."""
    data = pgm_bytes(image)

    def verify(tmp):
        back = read_image(tmp, cv2.IMREAD_UNCHANGED, "PGM map")
        return back.dtype == np.uint16 and np.array_equal(back, image)

    write_bytes(path, data, what="PGM map", overwrite=overwrite, verify=verify)


def write_ffmpeg_maps(prefix, map_x, map_y, source_size, overwrite=True) -> tuple[str, str]:
    """``PREFIX_x.pgm`` and ``PREFIX_y.pgm`` for ffmpeg's ``remap``; returns their paths."""
    xmap, ymap = ffmpeg_maps(map_x, map_y, source_size)
    px, py = f"{os.fspath(prefix)}_x.pgm", f"{os.fspath(prefix)}_y.pgm"
    write_pgm(px, xmap, overwrite)
    write_pgm(py, ymap, overwrite)
    return px, py


def write_npy_maps(prefix, map_x, map_y, overwrite=True) -> list[str]:
    """``PREFIX_x.npy`` and ``PREFIX_y.npy`` (float32, for ``cv2.remap``); returns the paths."""
    paths = []
    for suffix, arr in (("x", map_x), ("y", map_y)):
        path = f"{os.fspath(prefix)}_{suffix}.npy"
        arr = np.ascontiguousarray(arr, dtype=np.float32)

        def verify(tmp, arr=arr):
            return np.array_equal(np.load(tmp), arr)

        with (
            atomic_output(path, what="map", overwrite=overwrite, verify=verify) as tmp,
            open(tmp, "wb") as f,
        ):
            np.save(f, arr)
        paths.append(path)
    return paths


def write_filestorage_maps(path, map_x, map_y, overwrite=True) -> PathLike:
    """``map_x`` and ``map_y`` (float32) in one ``cv2.FileStorage`` file (yaml, xml, json)."""
    map_x = np.ascontiguousarray(map_x, dtype=np.float32)
    map_y = np.ascontiguousarray(map_y, dtype=np.float32)

    def verify(tmp):
        fs = cv2.FileStorage(tmp, cv2.FILE_STORAGE_READ)
        try:
            return np.array_equal(fs.getNode("map_x").mat(), map_x) and np.array_equal(
                fs.getNode("map_y").mat(), map_y
            )
        finally:
            fs.release()

    with atomic_output(path, what="map file", overwrite=overwrite, verify=verify) as tmp:
        fs = cv2.FileStorage(tmp, cv2.FILE_STORAGE_WRITE)
        if not fs.isOpened():
            raise OutputError(f"cannot write map file {path}: use .yaml, .yml, .xml or .json")
        fs.writeComment("cv2.remap(src, map_x, map_y, interpolation); unseen pixels map to -10")
        fs.write("map_x", map_x)
        fs.write("map_y", map_y)
        fs.release()
    return path


def ffmpeg_command(
    x_pgm, y_pgm, output_size=None, supersample=1, input_name="in.mp4", output_name="out.mp4"
) -> str:
    """The ffmpeg command line that applies the maps (``format=yuv444p,remap``), as a string.

    ``yuv444p`` keeps chroma at full resolution, so every output pixel is one source pixel.
    With ``supersample`` k the maps are k times ``output_size`` and ``scale`` brings it down.
    A video output (any ``output_name`` that is not an image OpenCV writes, such as ``.png`` or
    ``out_%04d.png``) ends in ``format=yuv420p``: H.264 in 4:4:4 is refused by browsers and
    many players. 4:2:0 needs an even width and height, so an odd last column or row is cropped
    (``crop``), as ``cv2.VideoWriter`` drops it.
    """
    chain = "format=yuv444p,remap"
    if supersample > 1 and output_size is not None:
        chain += f",scale={output_size[0]}:{output_size[1]}:flags=area"
    if not cv2.haveImageWriter(os.fspath(output_name)):
        if output_size is None:
            chain += ",crop=trunc(iw/2)*2:trunc(ih/2)*2"
        elif output_size[0] % 2 or output_size[1] % 2:
            chain += f",crop={output_size[0] // 2 * 2}:{output_size[1] // 2 * 2}:0:0"
        chain += ",format=yuv420p"
    q = shlex.quote
    return (
        f"ffmpeg -i {q(input_name)} -i {q(os.fspath(x_pgm))} -i {q(os.fspath(y_pgm))} "
        f'-lavfi "{chain}" {q(output_name)}'
    )
