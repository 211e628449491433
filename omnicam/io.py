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

import contextlib
import json
import os

import cv2
import numpy as np

from ._atomic import OutputError, atomic_output, write_bytes
from ._validate import validate_D, validate_image_size, validate_K
from .mirror import HyperbolicMirror

__all__ = ["save_camera", "load_camera", "read_intrinsics", "write_intrinsics", "read_far_lines",
           "write_far_lines", "FORMAT_VERSION", "MODEL_NAME", "SUFFIXES"]

FORMAT_VERSION = 1
MODEL_NAME = "misaligned_hyperbolic"  # the model tag of a calibration file
SUFFIXES = (".yaml", ".yml", ".xml", ".json")
# field names of an intrinsics file, first match wins: omnicam's, then OpenCV's calibration sample
K_FIELDS = ("K", "camera_matrix", "cameraMatrix")
D_FIELDS = ("D", "dist_coeffs", "distortion_coefficients", "distCoeffs")


def _suffix(path, what="calibration file"):
    ext = os.path.splitext(str(path))[1].lower()
    if ext not in SUFFIXES:
        raise ValueError(f"{what} {path!s}: extension must be one of {', '.join(SUFFIXES)}"
                         f" (the format follows it), got {ext or 'none'!r}")
    return ext


def _atomic_filestorage(path, what, write):
    """Write a ``cv2.FileStorage`` file through :func:`omnicam._atomic.atomic_output`.

    ``write(fs)`` fills the open storage. The temporary file has the target's extension (the
    format follows it); after the write it must open again and hold the ``format_version`` or
    ``K`` written first, since ``cv2.FileStorage`` does not report a failed write (a full disk
    leaves an empty or truncated file).
    """
    path = os.fspath(path)
    _suffix(path, what)

    def verify(tmp):
        fs = cv2.FileStorage(tmp, cv2.FILE_STORAGE_READ)
        try:
            return fs.isOpened() and not fs.root().empty()
        finally:
            fs.release()

    with atomic_output(path, what=what, verify=verify) as tmp:
        fs = cv2.FileStorage(tmp, cv2.FILE_STORAGE_WRITE)
        try:
            if not fs.isOpened():
                raise OutputError(f"cannot write {what} {path}: OpenCV cannot open it for writing")
            write(fs)
        finally:
            fs.release()


def _write_seq(fs, name, values):
    fs.startWriteStruct(name, cv2.FileNode_SEQ)
    for v in values:
        fs.write("", int(v))
    fs.endWriteStruct()


def save_camera(camera, path):
    """Write ``camera`` to ``path``; a temporary file in the same folder is renamed into place.

    Raises
    ------
    ValueError
        Unknown extension, or the folder cannot be written.
    """
    def write(fs):
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
            _write_seq(fs, "image_size", camera.image_size)

    _atomic_filestorage(path, "calibration file", write)


def write_intrinsics(path, K, D=None, image_size=None):
    """Write a pinhole's ``K``, ``D`` and ``image_size`` (what :func:`read_intrinsics` reads)."""
    K, D, image_size = validate_K(K), validate_D(D), validate_image_size(image_size)

    def write(fs):
        fs.write("K", K)
        if D is not None:
            fs.write("D", D.reshape(1, -1))
        if image_size is not None:
            _write_seq(fs, "image_size", image_size)

    _atomic_filestorage(path, "intrinsics file", write)


class _Reader:
    """Typed access to the nodes of an open FileStorage, every failure a ValueError."""

    def __init__(self, fs, path, what):
        self.fs, self.path, self.what = fs, path, what

    def fail(self, field, what):
        return ValueError(f"{self.what} {self.path}: field {field!r} {what}")

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

    def first(self, fields, required=False):
        """The first of ``fields`` present (aliases), or None."""
        for field in fields:
            if self.node(field, required=False) is not None:
                return field
        if required:
            raise self.fail(fields[0], f"is missing (also looked for {', '.join(fields[1:])})")
        return None

    def number(self, field, parent=None):
        node = self.node(field, parent)
        if not (node.isReal() or node.isInt()):
            raise self.fail(field, "must be a number")
        value = node.real()
        if not np.isfinite(value):
            raise self.fail(field, f"must be finite, got {value}")
        return value

    def matrix(self, field, shape=None, required=True, allow_list=False):
        """An ``!!opencv-matrix`` (or, with ``allow_list``, a plain list of numbers)."""
        node = self.node(field, required=required)
        if node is None:
            return None
        mat = None
        try:
            if node.isMap():
                mat = node.mat()
            elif allow_list and node.isSeq():
                mat = np.array([node.at(i).real() for i in range(node.size())])
        except cv2.error:
            mat = None
        if mat is None:
            raise self.fail(field, "must be an OpenCV matrix (!!opencv-matrix)"
                            + (" or a list of numbers" if allow_list else ""))
        mat = np.asarray(mat, dtype=np.float64)
        if shape is not None and len(shape) == 2 and mat.shape != shape and not (
                allow_list and mat.size == shape[0] * shape[1] and mat.ndim == 1):
            raise self.fail(field, f"must be a {shape[0]}x{shape[1]} matrix, got {mat.shape}")
        if shape is not None and mat.size != int(np.prod(shape)):
            raise self.fail(field, f"must have {int(np.prod(shape))} values, got shape {mat.shape}")
        if not np.isfinite(mat).all():
            raise self.fail(field, "must be finite")
        return mat if shape is None else mat.reshape(shape)

    def image_size(self):
        """``image_size: [w, h]`` (or OpenCV sample's ``image_width``/``image_height``), or None."""
        node = self.node("image_size", required=False)
        if node is not None:
            if not node.isSeq() or node.size() != 2 or not all(
                    node.at(i).isInt() for i in range(2)):
                raise self.fail("image_size", "must be a sequence [width, height] of integers")
            return (int(node.at(0).real()), int(node.at(1).real()))
        if self.node("image_width", required=False) is not None:
            return (self.number("image_width"), self.number("image_height"))
        return None

    def check(self, field, validate, value):
        """``validate(value)``, its ValueError re-raised naming the file and ``field``."""
        try:
            return validate(value)
        except ValueError as e:
            raise self.fail(field, str(e)) from None


@contextlib.contextmanager
def _reading(path, what):
    """Open ``path`` for reading as a :class:`_Reader`; OpenCV's errors become ValueError."""
    path = os.fspath(path)
    _suffix(path, what)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{what} {path} does not exist")
    try:
        fs = cv2.FileStorage(path, cv2.FILE_STORAGE_READ)
        opened = fs.isOpened()
    except (cv2.error, SystemError):  # cv2 5 raises SystemError on an empty file
        opened = False
    if not opened:
        raise ValueError(f"{what} {path}: not a readable OpenCV FileStorage file "
                         f"(yaml, yml, xml or json)")
    try:
        yield _Reader(fs, path, what)
    except cv2.error as e:
        raise ValueError(f"{what} {path}: malformed ({str(e).splitlines()[-1]})") from None
    finally:
        fs.release()


def load_camera(path, cls):
    """Read and validate a calibration file; return ``cls(K, mirror, rvec, tvec, D, image_size)``.

    ``cls`` is the camera class (:meth:`MisalignedHyperbolicCamera.load` passes itself), so this
    module stays below the camera in the layers and never imports it.

    Raises
    ------
    FileNotFoundError
        No file at ``path``.
    ValueError
        Anything malformed, missing, non-finite or inconsistent, naming the file and the field.
    """
    with _reading(path, "calibration file") as r:
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
        mirror = r.check("mirror", lambda v: HyperbolicMirror(*v), ab)
        K = r.matrix("K", (3, 3))
        D = r.matrix("D", required=False)
        rvec = r.matrix("rvec", (3,))
        tvec = r.matrix("tvec", (3,))
        size = r.image_size()
        try:
            return cls(K, mirror, rvec, tvec, D=None if D is None else D.ravel(), image_size=size)
        except ValueError as e:
            raise r.fail(str(e).split(" ", 1)[0], str(e)) from None


def read_intrinsics(path):
    """Read a pinhole's ``K``, ``D`` and ``image_size`` from a ``cv2.FileStorage`` file.

    Fields (first match wins): the camera matrix ``K`` (or ``camera_matrix``, ``cameraMatrix``),
    optional distortion ``D`` (or ``dist_coeffs``, ``distortion_coefficients``, ``distCoeffs``;
    all zeros means none), optional ``image_size: [w, h]`` (or ``image_width``, ``image_height``):
    omnicam's names (also an omnicam calibration file) and those of OpenCV's calibration sample.

    Returns
    -------
    K : (3, 3) float64 ndarray
    D : (n,) float64 ndarray or None
    image_size : (int, int) or None

    Raises
    ------
    FileNotFoundError, ValueError
        As :func:`load_camera`, naming the file and the field.
    """
    from .intrinsics_formats import read_other_intrinsics  # ROS, Kalibr, image_size matrix

    other = read_other_intrinsics(path)
    if other is not None and not isinstance(other[0], str):
        try:
            K, D, size = validate_K(other[0]), validate_D(other[1]), \
                validate_image_size(other[2])
        except ValueError as e:
            raise ValueError(f"intrinsics file {os.fspath(path)}: {e}") from None
        return K, (D if D is not None and np.any(D) else None), size
    with _reading(path, "intrinsics file") as r:
        name = r.first(K_FIELDS, required=True)
        K = r.check(name, validate_K, r.matrix(name, (3, 3), allow_list=True))
        name = r.first(D_FIELDS)
        D = None
        if name is not None:
            D = r.check(name, validate_D, r.matrix(name, allow_list=True))
            if not np.any(D):
                D = None
        size = r.check("image_size", validate_image_size,
                       other[1] if other is not None else r.image_size())
    return K, D, size


def read_far_lines(path):
    """Far-line pixels from JSON: a list of lines, each a list of ``[x, y]`` pixels.

    The ``far_lines`` of section 3.2, as a user clicked them along the images of far straight
    lines. Returns a list of ``(N_i, 2)`` float64 arrays (each line at least 3 points).

    Raises
    ------
    FileNotFoundError
        No file at ``path``.
    ValueError
        Not JSON of that shape, or non-finite coordinates, naming the file and the line.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"far-lines file {path} does not exist")
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except json.JSONDecodeError as e:
        raise ValueError(f"far-lines file {path}: not valid JSON ({e})") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"far-lines file {path}: cannot read ({e})") from None
    expected = "a list of lines, each a list of [x, y] pixels"
    if not isinstance(data, list) or not data:
        raise ValueError(f"far-lines file {path}: expected {expected}")
    lines = []
    for i, line in enumerate(data):
        ok = isinstance(line, list) and len(line) >= 3 and all(
            isinstance(p, list) and len(p) == 2
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in p)
            for p in line)
        if not ok:
            raise ValueError(f"far-lines file {path}: line {i} must be a list of at least 3 "
                             f"[x, y] pixels ({expected})")
        arr = np.array(line, dtype=np.float64)
        if not np.isfinite(arr).all():
            raise ValueError(f"far-lines file {path}: line {i} has non-finite coordinates")
        lines.append(arr)
    return lines



def write_far_lines(path, far_lines):
    """Write far-line pixels as JSON (what :func:`read_far_lines` reads), atomically."""
    data = [np.asarray(line, dtype=np.float64).reshape(-1, 2).tolist() for line in far_lines]

    def verify(tmp):
        with open(tmp, encoding="utf-8") as f:
            return json.load(f) == data

    write_bytes(path, json.dumps(data), what="far-lines file", verify=verify)
