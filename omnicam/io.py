"""Calibration files: ``cv2.FileStorage`` (yaml, yml, xml, json), versioned, validated, atomic.

Layout (format_version 1)::

    format_version: 1
    model: misaligned_hyperbolic
    mirror: {a: 28.1, b: 23.4, rim_radius: 30.}
    K: !!opencv-matrix 3x3
    D: !!opencv-matrix 1xN          (absent when there is no distortion)
    rvec: !!opencv-matrix 3x1
    tvec: !!opencv-matrix 3x1
    image_size: [width, height]     (absent when unknown)
"""
from __future__ import annotations

import os
import tempfile

import cv2
import numpy as np

from .mirror import HyperbolicMirror

__all__ = ["save_camera", "load_camera", "FORMAT_VERSION", "SUFFIXES"]

FORMAT_VERSION = 1
SUFFIXES = (".yaml", ".yml", ".xml", ".json")


def _suffix(path):
    ext = os.path.splitext(str(path))[1].lower()
    if ext not in SUFFIXES:
        raise ValueError(f"calibration file {path!s}: extension must be one of {', '.join(SUFFIXES)}"
                         f" (the format follows it), got {ext or 'none'!r}")
    return ext


def save_camera(camera, path):
    """Write ``camera`` to ``path``; a temporary file in the same folder is renamed into place.

    Raises
    ------
    ValueError
        Unknown extension, or the folder cannot be written.
    """
    from .camera import MODEL_NAME

    path = os.fspath(path)
    ext = _suffix(path)
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise ValueError(f"calibration file {path}: folder {folder} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=".omnicam-", suffix=ext, dir=folder)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; a saved file gets the usual mode
    try:
        fs = cv2.FileStorage(tmp, cv2.FILE_STORAGE_WRITE)
        if not fs.isOpened():
            raise ValueError(f"calibration file {path}: cannot write in {folder}")
        fs.write("format_version", FORMAT_VERSION)
        fs.write("model", MODEL_NAME)
        fs.startWriteStruct("mirror", cv2.FileNode_MAP)
        fs.write("a", camera.mirror.a)
        fs.write("b", camera.mirror.b)
        fs.write("rim_radius", camera.mirror.rim_radius)
        fs.endWriteStruct()
        fs.write("K", np.asarray(camera.K))
        if camera.D is not None:
            fs.write("D", np.asarray(camera.D).reshape(1, -1))
        fs.write("rvec", np.asarray(camera.rvec).reshape(3, 1))
        fs.write("tvec", np.asarray(camera.tvec).reshape(3, 1))
        if camera.image_size is not None:
            fs.startWriteStruct("image_size", cv2.FileNode_SEQ)
            for v in camera.image_size:
                fs.write("", int(v))
            fs.endWriteStruct()
        fs.release()
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


class _Reader:
    """Typed access to the nodes of an open FileStorage, every failure a ValueError."""

    def __init__(self, fs, path):
        self.fs, self.path = fs, path

    def fail(self, field, what):
        return ValueError(f"calibration file {self.path}: field {field!r} {what}")

    def node(self, field, parent=None, required=True):
        try:
            node = (parent if parent is not None else self.fs.root()).getNode(field.split(".")[-1])
        except cv2.error:
            raise self.fail(field, "is malformed") from None
        if node.empty() or node.isNone():
            if required:
                raise self.fail(field, "is missing")
            return None
        return node

    def number(self, field, parent=None):
        node = self.node(field, parent)
        if not (node.isReal() or node.isInt()):
            raise self.fail(field, "must be a number")
        value = node.real()
        if not np.isfinite(value):
            raise self.fail(field, f"must be finite, got {value}")
        return value

    def matrix(self, field, shape=None, required=True):
        node = self.node(field, required=required)
        if node is None:
            return None
        try:
            mat = node.mat() if node.isMap() else None
        except cv2.error:
            mat = None
        if mat is None:
            raise self.fail(field, "must be an OpenCV matrix (!!opencv-matrix)")
        mat = np.asarray(mat, dtype=np.float64)
        if shape is not None and len(shape) == 2 and mat.shape != shape:
            raise self.fail(field, f"must be a {shape[0]}x{shape[1]} matrix, got {mat.shape}")
        if shape is not None and mat.size != int(np.prod(shape)):
            raise self.fail(field, f"must have {int(np.prod(shape))} values, got shape {mat.shape}")
        if not np.isfinite(mat).all():
            raise self.fail(field, "must be finite")
        return mat if shape is None else mat.reshape(shape)


def load_camera(path, cls=None):
    """Read and validate a calibration file; return a :class:`MisalignedHyperbolicCamera`.

    Raises
    ------
    FileNotFoundError
        No file at ``path``.
    ValueError
        Anything malformed, missing, non-finite or inconsistent, naming the file and the field.
    """
    from .camera import MODEL_NAME, MisalignedHyperbolicCamera

    cls = cls or MisalignedHyperbolicCamera
    path = os.fspath(path)
    _suffix(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"calibration file {path} does not exist")
    try:
        fs = cv2.FileStorage(path, cv2.FILE_STORAGE_READ)
        opened = fs.isOpened()
    except (cv2.error, SystemError):
        opened = False
    if not opened:
        raise ValueError(f"calibration file {path}: not a readable OpenCV FileStorage file")
    try:
        r = _Reader(fs, path)
        version = r.number("format_version")
        if version != FORMAT_VERSION:
            raise r.fail("format_version", f"is {version:g}; this omnicam reads {FORMAT_VERSION}")
        model = r.node("model")
        if not model.isString() or model.string() != MODEL_NAME:
            raise r.fail("model", f"must be {MODEL_NAME!r}")
        mnode = r.node("mirror")
        if not mnode.isMap():
            raise r.fail("mirror", "must be a map with a, b, rim_radius")
        ab = [r.number(f"mirror.{k}", mnode) for k in ("a", "b", "rim_radius")]
        K = r.matrix("K", (3, 3))
        D = r.matrix("D", required=False)
        rvec = r.matrix("rvec", (3,))
        tvec = r.matrix("tvec", (3,))
        size = None
        snode = r.node("image_size", required=False)
        if snode is not None:
            if not snode.isSeq() or snode.size() != 2 or not all(
                    snode.at(i).isInt() for i in range(2)):
                raise r.fail("image_size", "must be a sequence [width, height] of integers")
            size = (int(snode.at(0).real()), int(snode.at(1).real()))
        try:
            mirror = HyperbolicMirror(*ab)
        except ValueError as e:
            raise r.fail("mirror", str(e)) from None
        try:
            return cls(K, mirror, rvec, tvec, D=None if D is None else D.ravel(), image_size=size)
        except ValueError as e:
            field = str(e).split(" ", 1)[0]
            raise r.fail(field, str(e)) from None
    except cv2.error as e:
        raise ValueError(f"calibration file {path}: malformed ({str(e).splitlines()[-1]})") from None
    finally:
        fs.release()
