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
    camera_reflection: {r: 9., z: 12.}  (optional: the circle of the camera's reflection)
    verdict: {...}                  (optional: how far to trust it, see :class:`Verdict`)

The ``verdict`` map (new after omnicam 0.3.0; still ``format_version`` 1: every field of it is
optional and readers ignore fields they do not know, so older omnicams read these files and
files without it read as before) records what the calibration's report said when the file was
written: where ``K`` came from, the confidence of the posture's choice, ``--force``, the stated
uncertainty, the warnings, and for chessboard calibrations the RMS, the held-out check and the
viewing directions' uncertainty. Its flags are written as 0 and 1 (YAML's ``true`` is refused
on reading, below). :func:`read_verdict` reads it.

Reading is defensive, because ``cv2.FileStorage`` (OpenCV 4.x and 5.0) crashes the whole process
on some inputs. Found by ``tests/fuzz/run.py`` and an outside fuzz run:

* SIGSEGV on a file name that is not valid UTF-8;
* SIGSEGV on JSON with 100,000 nested brackets and on XML with 30,000 nested elements (its
  parsers recurse without a limit);
* heap corruption ("double free or corruption") after loading a few corrupt ``.json`` files
  (a non-UTF-8 ``model`` tag, byte flips);
* a raw ``UnicodeDecodeError`` from ``FileNode.string()`` on non-UTF-8 text;
* ``FileNode.mat()`` saturating silently: ``dt: u`` with the value 583 reads as 255;
* integers beyond 32 bits wrapped around silently: ``format_version: 4294967297`` reads as 1,
  and so does ``format_version: true`` (YAML booleans become the integers 1 and 0);
* its own ``[ERROR:0@...] persistence.cpp`` lines on stderr for every parse error;
* ``FileNode.getNode`` and ``FileNode.at`` cost time linear in the position: walking a 1 MiB
  file of 60,000 keys took 40 s (so maps over 256 keys and sequences over 4096 items are
  refused, and only the fields omnicam needs are read).

So before OpenCV sees anything, :func:`_prescan` refuses (``ValueError`` naming the file) a name
that is not UTF-8, anything but a regular file (a folder, FIFO or device: "is not a regular
file"), files over ``MAX_FILE_BYTES`` (1 MiB), empty or binary files (a NUL byte), text that is
not UTF-8, nesting deeper than ``MAX_DEPTH`` (brackets, XML elements, YAML indentation) and
base64 blocks (omnicam never writes them), and in YAML and XML integers beyond 32 bits and
the booleans ``true``/``false``. JSON is then parsed by the standard library alone and
never reaches OpenCV; YAML and XML are parsed by ``cv2.FileStorage`` from the checked text in
memory (so what OpenCV parses is what was checked), with its log silenced, and its node tree is
copied into Python values. Matrices are rebuilt from ``rows``, ``cols``, ``dt`` and ``data``
here, every value checked against the range of its ``dt``.

Writing goes through :func:`omnicam._atomic.atomic_output` and is verified by reading the
temporary file back with the same reader: a failure (full disk, read-only folder, ...) raises
``ValueError`` naming the file and keeps the old file.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re

import cv2
import numpy as np

from .._atomic import OutputError, atomic_output, sigint_deferred, write_bytes
from .._quiet import opencv_silenced
from .._typing import ArrayLike, FloatArray, PathLike, Size
from .._validate import (
    file_path,
    finite_array,
    real_number,
    regular_file,
    shown,
    validate_D,
    validate_image_size,
    validate_K,
)
from ..camera import MisalignedCatadioptricCamera
from ..mirror import HyperbolicMirror
from .other_tools import not_pinhole, read_other_central, read_other_intrinsics

__all__ = [
    "save_camera",
    "load_camera",
    "Verdict",
    "read_verdict",
    "read_intrinsics",
    "read_central_model",
    "write_intrinsics",
    "read_far_lines",
    "write_far_lines",
    "FORMAT_VERSION",
    "MODEL_NAME",
    "SUFFIXES",
    "MAX_FILE_BYTES",
    "MAX_DEPTH",
    "Reader",
    "file_path",
    "reading",
]

FORMAT_VERSION = 1
MODEL_NAME = "misaligned_hyperbolic"  # the model tag of a calibration file
SUFFIXES = (".yaml", ".yml", ".xml", ".json")
MAX_FILE_BYTES = 1 << 20  # calibration, intrinsics and far-line files are a few kB
MAX_DEPTH = 32  # nesting of brackets / elements / YAML blocks (ours: 3)
MAX_INDENT = 128  # columns of YAML indentation
MAX_FIELDS = 256  # keys of a map
MAX_VALUES = 4096  # items of a sequence (our matrices hold at most 14)
# field names of an intrinsics file, first match wins: omnicam's, then OpenCV's calibration sample
K_FIELDS = ("K", "camera_matrix", "cameraMatrix")
D_FIELDS = ("D", "dist_coeffs", "distortion_coefficients", "distCoeffs")
# OpenCV matrix element types (dt) and the values they hold
_DT_RANGES = {
    "u": (0, 255),
    "c": (-128, 127),
    "w": (0, 65535),
    "s": (-32768, 32767),
    "i": (-(2**31), 2**31 - 1),
    "f": (-3.4028234663852886e38, 3.4028234663852886e38),
    "d": (-math.inf, math.inf),
}
_MAX_MATRIX_VALUES = MAX_VALUES
_BOOLEAN = re.compile(r"(?m)(?:^|[:\[,>-])[ \t]*(true|false)[ \t]*(?=$|[,\]#<])")
_LONG_INT = re.compile(r"(?<![\w.+-])[-+]?\d{10,}(?![\w.])")  # 10+ digits, not part of a real


def _nesting(text):
    """``(depth, indent, where)``: the deepest nesting of ``[``/``{`` outside strings and of XML
    elements, the widest YAML indentation, and the offsets in ``text`` where the nesting first
    goes beyond ``MAX_DEPTH`` and the indentation beyond ``MAX_INDENT`` (None if never)."""
    depth = deepest = 0
    quote = None
    escaped = False
    beyond = []  # offsets where the nesting passes MAX_DEPTH
    for i, ch in enumerate(text):  # brackets outside double- or single-quoted strings
        if quote:
            if escaped:
                escaped = False
            elif ch == "\\" and quote == '"':
                escaped = True
            elif ch == quote:
                quote = None
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
            if depth > deepest:
                deepest = depth
                if depth == MAX_DEPTH + 1:
                    beyond.append(i)
        elif ch in "]}":
            depth -= 1
    elements = 0
    if "<" in text:
        depth = 0
        for m in re.finditer(r"<(/?)[A-Za-z_:][^<>]*?(/?)>|<!--.*?-->", text, flags=re.DOTALL):
            if m.group().startswith("<!--"):
                continue
            if m.group(1):
                depth -= 1
            elif not m.group(2):
                depth += 1
                elements = max(elements, depth)
                if depth == MAX_DEPTH + 1:
                    beyond.append(m.start())
    indent = offset = 0
    indent_at = None
    for line in text.splitlines(keepends=True):
        width = re.match(r"[ \t]*(?:-[ \t]+)*", line).end()
        if width > MAX_INDENT >= indent:
            indent_at = offset + width
        indent = max(indent, width)
        offset += len(line)
    return max(deepest, elements), indent, (min(beyond, default=None), indent_at)


_JSON_TOKEN = re.compile(r'"(?:[^"\\]|\\.)*"|[\[\]{}:]')
_TOP_KEY = {  # a top-level field's line, as cv2.FileStorage writes them (at column 0)
    "yaml": re.compile(r"(?m)^([A-Za-z_][\w.-]*)[ \t]*:"),
    "xml": re.compile(r"(?m)^<([A-Za-z_][\w.-]*)(?=[\s/>])"),
}


def _field_at(text, pos):
    """The top-level field of the document ``text`` that holds offset ``pos``, or None.

    JSON: the last key at depth 1 before ``pos``; YAML and XML: the last field that starts a
    line before it (``cv2.FileStorage`` writes nested ones indented).
    """
    head = text[:pos]
    if head.lstrip().startswith("{"):
        depth, key, last = 0, None, None
        for m in _JSON_TOKEN.finditer(head):
            tok = m.group()
            if tok in "[{":
                depth += 1
            elif tok in "]}":
                depth -= 1
            elif tok == ":":
                key = last if depth == 1 and last is not None else key
            else:
                last = tok[1:-1] if depth == 1 else None
        return key
    fmt = "xml" if head.lstrip().startswith("<") else "yaml"
    names = [n for n in _TOP_KEY[fmt].findall(head) if n not in ("opencv_storage", "xml")]
    return names[-1] if names else None


def _where(text, pos):
    """``"line 14, field 'K'"``: where offset ``pos`` of ``text`` lies, for a message."""
    field = _field_at(text, pos)
    line = text.count("\n", 0, pos) + 1
    return f"line {line}" + (f", field {field!r}" if field else "")


def _prescan(path, what, json_only=False):
    """The text of ``path`` if it is safe to parse, else ``ValueError`` naming the file.

    Raises ``FileNotFoundError`` if nothing is at ``path``; see the module docstring for what
    is refused and why.
    """
    name = shown(path)
    text = _read_text(path, f"{what} {name}")
    _check_text(text, f"{what} {name}", json_only)
    return text


def _read_text(path, label):
    """The UTF-8 text of the regular file ``path`` of at most ``MAX_FILE_BYTES``, not empty and
    without a NUL byte (``label``: the file as messages name it, "calibration file x.yaml")."""
    st = regular_file(path, label)
    if st.st_size > MAX_FILE_BYTES:
        raise ValueError(
            f"{label}: too large ({st.st_size} bytes; at most {MAX_FILE_BYTES} are read)"
        )
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_FILE_BYTES + 1)
    except OSError as e:
        raise ValueError(f"{label}: cannot read it ({e.strerror or e})") from None
    if len(data) > MAX_FILE_BYTES:
        raise ValueError(f"{label}: too large (more than {MAX_FILE_BYTES} bytes)")
    if not data.strip():
        raise ValueError(f"{label} is empty, not a readable yaml, xml or json file")
    if b"\0" in data:
        raise ValueError(f"{label}: a binary file, not yaml, xml or json text")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        head = data[: e.start].decode("utf-8")  # the text before the first bad byte
        raise ValueError(
            f"{label}: not UTF-8 text at {_where(head, len(head))} (byte {e.start}); a "
            f"corrupt or binary file, or text in another encoding: save it as UTF-8"
        ) from None


def _check_text(text, label, json_only):
    """``ValueError`` (naming ``label``) for text nested too deeply, and in YAML and XML for
    base64 blocks, booleans and integers beyond 32 bits, which OpenCV misreads."""
    depth, indent, (depth_at, indent_at) = _nesting(text)
    if depth > MAX_DEPTH or (not json_only and indent > MAX_INDENT):
        at = depth_at if depth > MAX_DEPTH else indent_at
        raise ValueError(
            f"{label}: nested too deeply at {_where(text, at)} ({max(depth, indent)} levels or "
            f"columns; at most {MAX_DEPTH} levels, {MAX_INDENT} columns); not a file omnicam "
            f"writes"
        )
    if json_only:
        return
    if "$base64$" in text:
        raise ValueError(f"{label}: base64-encoded data is not supported")
    if text.lstrip().startswith("{"):
        return
    m = _BOOLEAN.search(text)
    if m:
        raise ValueError(
            f"{label}: {m.group(1)!r} where a value is expected ({_where(text, m.start(1))}); "
            f"OpenCV would read it as the number {int(m.group(1) == 'true')}"
        )
    for m in _LONG_INT.finditer(text):
        digits = m.group().lstrip("+-")
        if len(digits) > 10 or abs(int(m.group())) > 2**31 - 1:
            number = m.group() if len(digits) <= 20 else f"of {len(digits)} digits"
            raise ValueError(
                f"{label}: the integer {number} ({_where(text, m.start())}) does not fit in 32 "
                f"bits (OpenCV would read it wrapped around); write it as a real number"
                + (f" such as {m.group()}." if len(digits) <= 20 else "")
            )


def _suffix(path, what="calibration file"):
    ext = os.path.splitext(str(path))[1].lower()
    if ext not in SUFFIXES:
        raise ValueError(
            f"{what} {shown(path)}: extension must be one of {', '.join(SUFFIXES)}"
            f" (the format follows it), got {ext or 'none'!r}"
        )
    return ext


# -- reading ------------------------------------------------------------------------------------
def _from_node(node, depth=0):
    """A ``cv2.FileNode`` subtree as Python values (dict, list, int, float, str, None).

    ``FileNode.getNode`` and ``FileNode.at`` take time linear in the position, so maps are
    limited to ``MAX_FIELDS`` keys and sequences to ``MAX_VALUES`` items (a 1 MiB file of
    60,000 keys would otherwise take minutes).
    """
    if depth > MAX_DEPTH:
        raise ValueError("is nested too deeply")
    if node.isMap():
        if node.size() > MAX_FIELDS:
            raise ValueError(f"has more than {MAX_FIELDS} fields")
        return {k: _from_node(node.getNode(k), depth + 1) for k in node.keys()}
    if node.isSeq():
        if node.size() > MAX_VALUES:
            raise ValueError(f"has more than {MAX_VALUES} values")
        return [_from_node(node.at(i), depth + 1) for i in range(node.size())]
    if node.isInt():
        return int(node.real())
    if node.isReal():
        return float(node.real())
    if node.isString():
        try:
            return node.string()
        except UnicodeDecodeError:
            raise ValueError("holds a string that is not UTF-8") from None
    return None


class _Fields:
    """The top-level map of an open ``cv2.FileStorage``, each field converted when read."""

    def __init__(self, fs):
        self.fs = fs  # kept open while fields are read
        self.names = set(fs.root().keys())

    def get(self, name):
        if name not in self.names:
            return None
        with opencv_silenced():
            try:
                return _from_node(self.fs.root().getNode(name))
            except cv2.error as e:
                raise ValueError(f"is malformed ({str(e).splitlines()[-1]})") from None


# what cv2.FileStorage writes for NaN and the infinities in JSON (.Nan, .Inf, -.Inf) and reads
# back in any case and sign; and strings, left as they are
_OPENCV_NONFINITE = re.compile(
    r'"(?:[^"\\]|\\.)*"|(?<![\w.])([+-]?)\.(nan|inf)(?!\w)', re.IGNORECASE
)


def _json_loads(text, label, invalid="not valid JSON"):
    """The JSON document ``text`` as ``json.loads`` reads it, also with the non-finite numbers
    ``cv2.FileStorage`` writes (``.Nan``, ``.Inf``, ``-.Inf``: a NaN is refused later, naming
    its field); a ``ValueError`` naming ``label``, the line and the field otherwise (``invalid``
    says what a syntax error makes of the file)."""

    def standard(m):
        if m.group(2) is None:
            return m.group()
        if m.group(2).lower() == "nan":
            return "NaN"
        return "-Infinity" if m.group(1) == "-" else "Infinity"

    text = _OPENCV_NONFINITE.sub(standard, text)  # no line changes: the lines stay right
    try:
        return json.loads(text)
    except RecursionError:
        raise ValueError(f"{label}: nested too deeply") from None
    except json.JSONDecodeError as e:
        raise ValueError(
            f"{label}: {invalid} at {_where(text, e.pos)} (column {e.colno}): {e.msg}"
        ) from None
    except ValueError as e:  # an integer beyond Python's limit of digits (4300)
        runs = re.findall(r"\d+", text)
        huge = max(runs, key=len) if runs else ""
        if "digits" not in str(e) or not huge:
            raise ValueError(f"{label}: {invalid} ({e})") from None
        raise ValueError(
            f"{label}: an integer of {len(huge)} digits at {_where(text, text.index(huge))}, "
            f"larger than any value omnicam reads"
        ) from None


def _parse(text, path, what, ext):
    """The fields of the document ``text``: a dict (JSON) or :class:`_Fields` (YAML, XML)."""
    name = shown(path)
    if ext == ".json" or text.lstrip().startswith("{"):
        data = _json_loads(
            text, f"{what} {name}", "not a readable OpenCV FileStorage file, not valid JSON"
        )
        if not isinstance(data, dict):
            raise ValueError(f"{what} {name}: expected a map of named fields at the top level")
        return data
    with opencv_silenced():
        try:
            fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
            opened = fs.isOpened()
            root_is_map = opened and fs.root().isMap()
        except (cv2.error, SystemError):
            opened = root_is_map = False
    if not opened:
        raise ValueError(
            f"{what} {name}: not a readable OpenCV FileStorage file (yaml, yml, xml or json)"
        )
    if not root_is_map:
        raise ValueError(f"{what} {name}: expected a map of named fields at the top level")
    if fs.root().size() > MAX_FIELDS:
        raise ValueError(
            f"{what} {name}: more than {MAX_FIELDS} top-level fields; not a "
            f"calibration or intrinsics file"
        )
    return _Fields(fs)


def _is_number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


class Reader:
    """Typed access to the fields of a parsed file, every failure a ValueError naming both."""

    def __init__(self, data, path, what):
        self.data, self.path, self.what = data, shown(path), what

    def fail(self, field, what):
        """Raise the ``ValueError`` that names the file and ``field``."""
        return ValueError(f"{self.what} {self.path}: field {field!r} {what}")

    def node(self, field, parent=None, required=True):
        """The FileStorage node of ``field`` (in ``parent``); missing: None, or an error if
        ``required``."""
        try:
            value = (parent if parent is not None else self.data).get(field.split(".")[-1])
        except ValueError as e:
            raise self.fail(field, str(e)) from None
        if value is None and required:
            raise self.fail(field, "is missing")
        return value

    def first(self, fields, required=False):
        """The first of ``fields`` present (aliases), or None."""
        for field in fields:
            if self.node(field, required=False) is not None:
                return field
        if required:
            raise self.fail(fields[0], f"is missing (also looked for {', '.join(fields[1:])})")
        return None

    def number(self, field, parent=None):
        """The finite number in ``field``."""
        value = self.node(field, parent)
        if not _is_number(value):
            raise self.fail(field, "must be a number")
        try:
            value = float(value)
        except OverflowError:
            value = math.inf
        if not math.isfinite(value):
            raise self.fail(field, f"must be finite, got {value}")
        return value

    def _numbers(self, field, values, lo=-math.inf, hi=math.inf, integer=False):
        if not isinstance(values, list) or not values or len(values) > _MAX_MATRIX_VALUES:
            raise self.fail(field, "must hold a non-empty list of numbers")
        out = np.empty(len(values))
        for i, v in enumerate(values):
            if not _is_number(v) or (integer and not isinstance(v, int)):
                kind = "an integer" if integer else "a number"
                raise self.fail(field, f"value {i} must be {kind}, got {v!r}")
            try:
                out[i] = float(v)
            except OverflowError:
                out[i] = math.inf
            if not math.isfinite(out[i]):
                raise self.fail(field, "must be finite")
            if not lo <= v <= hi:
                raise self.fail(field, f"value {v!r} does not fit its type (range {lo:g}..{hi:g})")
        return out

    def _opencv_matrix(self, field, m):
        """Rebuild an ``opencv-matrix`` map, every value checked against its ``dt``."""
        rows, cols, dt, data = (m.get(k) for k in ("rows", "cols", "dt", "data"))
        if not all(
            isinstance(v, int) and not isinstance(v, bool) and 0 < v <= _MAX_MATRIX_VALUES
            for v in (rows, cols)
        ):
            raise self.fail(field, "must have positive integer rows and cols")
        if dt not in _DT_RANGES:
            raise self.fail(
                field, f"must have a one-channel dt ({', '.join(_DT_RANGES)}), got {dt!r}"
            )
        lo, hi = _DT_RANGES[dt]
        values = self._numbers(field, data, lo, hi, integer=dt not in "fd")
        if values.size != rows * cols:
            raise self.fail(field, f"has {values.size} values for {rows}x{cols}")
        return values.reshape(rows, cols)

    def _opencv_nd_matrix(self, field, m):
        """An ``opencv-nd-matrix`` (``fs.write`` of a 1-D array) with one size, as a column."""
        sizes = m.get("sizes")
        sizes = [sizes] if isinstance(sizes, int) else sizes  # XML gives one size as a scalar
        if not (
            isinstance(sizes, list)
            and len(sizes) == 1
            and isinstance(sizes[0], int)
            and not isinstance(sizes[0], bool)
        ):
            raise self.fail(field, "must be a one-dimensional opencv-nd-matrix")
        return self._opencv_matrix(
            field, {"rows": sizes[0], "cols": 1, "dt": m.get("dt"), "data": m.get("data")}
        )

    def matrix(self, field, shape=None, required=True, allow_list=False):
        """An ``!!opencv-matrix`` (or, with ``allow_list``, a plain list of numbers)."""
        value = self.node(field, required=required)
        if value is None:
            return None
        if isinstance(value, dict) and {"rows", "cols", "dt", "data"} <= set(value):
            mat = self._opencv_matrix(field, value)
        elif isinstance(value, dict) and {"sizes", "dt", "data"} <= set(value):
            mat = self._opencv_nd_matrix(field, value)
        elif allow_list and isinstance(value, list):
            mat = self._numbers(field, value)
        else:
            raise self.fail(
                field,
                "must be an OpenCV matrix (!!opencv-matrix)"
                + (" or a list of numbers" if allow_list else ""),
            )
        if (
            shape is not None
            and len(shape) == 2
            and mat.shape != shape
            and not (allow_list and mat.size == shape[0] * shape[1] and mat.ndim == 1)
        ):
            raise self.fail(field, f"must be a {shape[0]}x{shape[1]} matrix, got {mat.shape}")
        if shape is not None and mat.size != int(np.prod(shape)):
            raise self.fail(field, f"must have {int(np.prod(shape))} values, got shape {mat.shape}")
        return mat if shape is None else mat.reshape(shape)

    def image_size(self):
        """``image_size: [w, h]`` or a 2-value matrix (or ``image_width``/``image_height``)."""
        value = self.node("image_size", required=False)
        if isinstance(value, dict):  # fs.write("image_size", array): an (nd-)matrix
            m = self.matrix("image_size").ravel()
            if m.size != 2 or np.any(m != np.round(m)):
                raise self.fail("image_size", "must be (width, height), two integers")
            return (int(m[0]), int(m[1]))
        if value is not None:
            if not (
                isinstance(value, list)
                and len(value) == 2
                and all(isinstance(v, int) and not isinstance(v, bool) for v in value)
            ):
                raise self.fail("image_size", "must be a sequence [width, height] of integers")
            return tuple(value)
        if self.node("image_width", required=False) is not None:
            return (self.number("image_width"), self.number("image_height"))
        return None

    def check(self, field, validate, value):
        """``validate(value)``, its ValueError re-raised naming the file and ``field``."""
        try:
            return validate(value)
        except ValueError as e:
            raise self.fail(field, str(e)) from None


def reading(path, what):
    """A :class:`Reader` of the file at ``path``: pre-scanned, parsed, never crashing OpenCV."""
    path = file_path(path, what)
    ext = _suffix(path, what)
    return Reader(_parse(_prescan(path, what), path, what, ext), path, what)


def load_camera(path: PathLike) -> MisalignedCatadioptricCamera:
    """Read and validate a calibration file written by :func:`save_camera`.

    :meth:`omnicam.MisalignedHyperbolicCamera.load` is this, as the design's class.

    Raises
    ------
    FileNotFoundError
        No file at ``path``.
    ValueError
        Anything malformed, missing, non-finite, out of range (the camera's physical validation)
        or inconsistent, naming the file and the field; also a path that is not a regular file,
        a name that is not UTF-8, and files that are too large, binary or nested too deeply.
    """
    r = reading(path, "calibration file")
    version = r.number("format_version")
    if version != FORMAT_VERSION:
        raise r.fail("format_version", f"is {version:g}; this omnicam reads {FORMAT_VERSION}")
    model = r.node("model")
    if model != MODEL_NAME:
        raise r.fail("model", f"must be {MODEL_NAME!r}")
    mnode = r.node("mirror")
    if not isinstance(mnode, dict):
        raise r.fail("mirror", "must be a map with a, b, rim_radius")
    ab = [r.number(f"mirror.{k}", mnode) for k in ("a", "b", "rim_radius")]
    mirror = r.check("mirror", lambda v: HyperbolicMirror(*v), ab)
    K = r.matrix("K", (3, 3))
    D = r.matrix("D", required=False)
    rvec = r.matrix("rvec", (3,))
    tvec = r.matrix("tvec", (3,))
    size = r.image_size()
    body = r.node("camera_reflection", required=False)  # optional: absent in older files
    reflection = None
    if body is not None:
        if not isinstance(body, dict):
            raise r.fail("camera_reflection", "must be a map with r, z")
        reflection = (r.number("camera_reflection.r", body), r.number("camera_reflection.z", body))
    try:
        return MisalignedCatadioptricCamera(
            K,
            mirror,
            rvec,
            tvec,
            D=None if D is None else D.ravel(),
            image_size=size,
            camera_reflection=reflection,
        )
    except ValueError as e:
        raise r.fail(str(e).split(" ", 1)[0].rstrip(":,"), str(e)) from None


# -- the verdict: how far to trust a calibration --------------------------------------------------
#: Where a calibration's ``K`` came from (:attr:`Verdict.K_source`).
K_SOURCES = ("given", "file", "guessed", "chessboard")
#: How the posture was found (:attr:`Verdict.method`).
METHODS = ("image", "chessboard")
_VERDICT_FLOATS = (
    "confidence",
    "axis_std_deg",
    "origin_std_mm",
    "rim_rms_px",
    "rms_px",
    "heldout_median_px",
    "heldout_max_px",
)
_MAX_TEXT = 2000  # characters of one warning or note


def _file_text(text, name):
    """``text`` on one line, as the reader takes it back from every format.

    The pre-scan refuses YAML and XML holding a bare ``true``/``false`` or an integer beyond 32
    bits, wherever they are (:func:`_check_text`); OpenCV writes the strings ``true`` and
    ``null`` unquoted, and a string that starts with a quote as if it were quoted already (a
    file it cannot read back). So such words get backticks, a leading quote one before it, and
    long integers are grouped (``4_294_967_297``).
    """
    if not isinstance(text, str):
        raise ValueError(f"{name} must be a string, got {type(text).__name__}")
    text = " ".join(text.split())[:_MAX_TEXT]
    text = re.sub(r"(^|[:\[,>-][ \t]*)(true|false|null)(?=[ \t]*(?:$|[,\]#<]))", r"\1`\2`", text)
    if text[:1] in ("'", '"'):
        text = "`" + text
    return _LONG_INT.sub(lambda m: f"{int(m.group()):_}", text)


@dataclasses.dataclass(frozen=True)
class Verdict:
    """How far to trust a calibration: what its report said when the file was written.

    The ``verdict`` map of a calibration file (:func:`save_camera`, :func:`read_verdict`).
    ``camera.save(path, report)`` records :meth:`from_report` of the report; the command line
    adds where ``K`` came from and ``--force``. Numbers that do not apply or are unknown are
    None (never NaN).

    Attributes
    ----------
    method : str
        ``"image"`` (one image of the mirror: the rim, Chen's method, the choice of posture) or
        ``"chessboard"`` (chessboards seen through the mirror).
    K_source : str
        Where ``K`` came from: ``"given"`` (typed or passed in), ``"file"`` (read from
        :attr:`K_file`), ``"guessed"`` (from the rim and the mirror, as if the rig were
        aligned) or ``"chessboard"`` (fitted to the boards).
    K_file : str or None
        The file ``K`` was read from (``--intrinsics``, ``--from``), as given.
    K_note : str
        How ``K`` was made, in words (the guess's recipe and numbers).
    confidence : float or None
        The choice among the physical postures, 0 to 1 (``CalibrationReport.confidence``;
        None for chessboards).
    ambiguous : bool
        The choice could not separate the physical postures.
    forced : bool
        Written although implausible (``--force``).
    axis_std_deg, origin_std_mm : float or None
        The stated RMS uncertainty of the mirror axis (deg) and of the camera centre (the
        mirror's length unit).
    rim_rms_px : float or None
        RMS distance of the rim points to the rim's image, px.
    rms_px : float or None
        Chessboards: RMS corner reprojection error, px.
    heldout_median_px, heldout_max_px : float or None
        Chessboards: the held-out corner RMS (median and worst view), px.
    heldout_folds : int or None
        Chessboards: the folds of the held-out check.
    ray_std_deg : (float, float) or None
        Chessboards: the viewing directions' standard deviation over the mirror's image, deg
        (median, worst).
    warnings : tuple of str
        The report's warnings, the implausible findings left out.
    implausible : tuple of str
        The implausible findings: what makes ``omnicam calibrate`` refuse without ``--force``.
    """

    method: str = "image"
    K_source: str = "given"
    K_file: str | None = None
    K_note: str = ""
    confidence: float | None = None
    ambiguous: bool = False
    forced: bool = False
    axis_std_deg: float | None = None
    origin_std_mm: float | None = None
    rim_rms_px: float | None = None
    rms_px: float | None = None
    heldout_median_px: float | None = None
    heldout_max_px: float | None = None
    heldout_folds: int | None = None
    ray_std_deg: tuple | None = None
    warnings: tuple = ()
    implausible: tuple = ()

    def __post_init__(self):
        def put(name, value):
            object.__setattr__(self, name, value)

        if self.method not in METHODS:
            raise ValueError(f"method must be one of {', '.join(METHODS)}, got {self.method!r}")
        if self.K_source not in K_SOURCES:
            raise ValueError(
                f"K_source must be one of {', '.join(K_SOURCES)}, got {self.K_source!r}"
            )
        if self.K_file is not None:
            put("K_file", _file_text(shown(file_path(self.K_file, "K_file")), "K_file"))
        put("K_note", _file_text(self.K_note, "K_note"))
        for name in ("ambiguous", "forced"):
            value = getattr(self, name)
            if value not in (0, 1):  # True, False, 0, 1 (the file's flags)
                raise ValueError(f"{name} must be 0 or 1 (False or True), got {value!r}")
            put(name, bool(value))
        for name in _VERDICT_FLOATS:
            put(name, _optional_number(getattr(self, name), name))
        if self.confidence is not None and not 0.0 <= self.confidence <= 1.0:
            raise ValueError(f"confidence must be within 0..1, got {self.confidence!r}")
        folds = self.heldout_folds
        if folds is not None and (
            not isinstance(folds, (int, np.integer)) or isinstance(folds, bool) or folds < 2
        ):
            raise ValueError(f"heldout_folds must be an integer of at least 2, got {folds!r}")
        put("heldout_folds", None if folds is None else int(folds))
        ray = self.ray_std_deg
        if ray is not None:
            if np.ndim(ray) != 1 or len(ray) != 2:
                raise ValueError(f"ray_std_deg must be (median, worst), got {ray!r}")
            ray = tuple(_optional_number(v, "ray_std_deg") for v in ray)
            put("ray_std_deg", None if None in ray else ray)
        for name in ("warnings", "implausible"):
            texts = getattr(self, name)
            if isinstance(texts, str) or not isinstance(texts, (list, tuple)):
                raise ValueError(f"{name} must be a sequence of strings")
            if len(texts) > MAX_VALUES:
                raise ValueError(f"{name} has more than {MAX_VALUES} entries")
            put(name, tuple(_file_text(w, name) for w in texts))

    @classmethod
    def from_report(
        cls,
        report,
        *,
        K_source: str | None = None,
        K_file: str | None = None,
        K_note: str = "",
        forced: bool = False,
        implausible=None,
    ) -> Verdict:
        """The verdict of a :class:`~omnicam.calibration.CalibrationReport` (one image) or a
        :class:`~omnicam.chessboard.PatternReport` (chessboards).

        Parameters
        ----------
        report : CalibrationReport or PatternReport
        K_source : str, optional
            Default ``"given"`` for one image (``calibrate`` takes ``K``), ``"chessboard"`` for
            chessboards (``K`` is fitted).
        K_file, K_note, forced
            As the attributes.
        implausible : sequence of str, optional
            The findings that made the result implausible; default the report's
            ``plausibility`` (one image), none for chessboards. They are left out of
            ``warnings``.

        Raises
        ------
        ValueError
            ``report`` is not a calibration report, or a bad argument (naming it).
        """
        if not hasattr(report, "warnings") or not hasattr(report, "camera"):
            raise ValueError(
                f"verdict must be a Verdict or a calibration report (CalibrationReport, "
                f"PatternReport), got {type(report).__name__}"
            )
        if implausible is None:
            implausible = getattr(report, "plausibility", ())
        implausible = tuple(str(w) for w in implausible)
        warnings = tuple(str(w) for w in report.warnings if str(w) not in implausible)
        common = dict(
            K_file=K_file,
            K_note=K_note,
            forced=forced,
            rim_rms_px=getattr(report, "rim_rms", None),
            warnings=warnings,
            implausible=implausible,
        )
        if hasattr(report, "view_rms"):  # chessboards
            std = getattr(report, "std", {}) or {}
            held = getattr(report, "heldout", None)
            return cls(
                method="chessboard",
                K_source=K_source or "chessboard",
                axis_std_deg=std.get("axis_deg"),
                origin_std_mm=std.get("origin"),
                rms_px=report.rms,
                heldout_median_px=None if held is None else held.median,
                heldout_max_px=None if held is None else held.max,
                heldout_folds=None if held is None else held.folds,
                ray_std_deg=tuple(getattr(report, "ray_std_deg", (None, None))),
                **common,
            )
        return cls(
            method="image",
            K_source=K_source or "given",
            confidence=report.confidence,
            ambiguous=getattr(report, "ambiguous", False),
            axis_std_deg=getattr(report, "axis_std_deg", None),
            origin_std_mm=getattr(report, "origin_std_mm", None),
            **common,
        )

    def doubts(self) -> tuple[str, ...]:
        """What makes the calibration doubtful, each a short phrase (empty: no doubt recorded).

        A guessed ``K``, an ambiguous choice of posture, implausible findings (written with
        ``--force`` or from the library), e.g. ``("with a guessed K", "ambiguous (confidence
        0.00)")``.
        """
        out = []
        if self.K_source == "guessed":
            out.append("with a guessed K")
        if self.ambiguous:
            c = "" if self.confidence is None else f" (confidence {self.confidence:.2f})"
            out.append(f"ambiguous{c}")
        n = len(self.implausible)
        found = f"{n} implausibility warning{'s' if n != 1 else ''}"
        if self.forced:
            out.append(f"forced past {found}" if n else "forced")
        elif n:
            out.append(f"with {found}")
        return tuple(out)


def _optional_number(value, name):
    """``value`` as a finite float, None for None or NaN; ValueError naming ``name``."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    value = float(value)
    if math.isnan(value):
        return None
    if not math.isfinite(value) or value < 0:
        raise ValueError(f"{name} must be finite and not negative, got {value!r}")
    return value


def read_verdict(path: PathLike) -> Verdict | None:
    """The :class:`Verdict` recorded in a calibration file, or None when it has none.

    Files written by ``camera.save(path)`` without a verdict, and by omnicam 0.3.0 and
    before, have none; :meth:`MisalignedHyperbolicCamera.load` reads the camera of every
    file alike.

    Raises
    ------
    FileNotFoundError
        No file at ``path``.
    ValueError
        A malformed verdict (naming the file and the field), or a file refused as
        :func:`load_camera` refuses it.
    """
    return _verdict_of(reading(path, "calibration file"))


def _verdict_of(r):
    node = r.node("verdict", required=False)
    if node is None:
        return None
    if not isinstance(node, dict):
        raise r.fail("verdict", "must be a map of named fields")
    values = {}
    for field in dataclasses.fields(Verdict):
        value = node.get(field.name)
        if value is None:
            continue
        name = f"verdict.{field.name}"
        if field.name in ("warnings", "implausible"):
            value = [value] if isinstance(value, str) else value  # XML: one item, a scalar
            if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                raise r.fail(name, "must be a sequence of strings")
        elif field.name == "ray_std_deg":
            if not (isinstance(value, list) and len(value) == 2 and all(map(_is_number, value))):
                raise r.fail(name, "must be a sequence of two numbers (median, worst)")
            value = tuple(value)
        elif field.name in ("method", "K_source", "K_file", "K_note"):
            if not isinstance(value, str):
                raise r.fail(name, "must be a string")
        elif not _is_number(value) and not isinstance(value, bool):
            raise r.fail(name, "must be a number")
        values[field.name] = value
    try:
        return Verdict(**values)
    except ValueError as e:
        field = str(e).split(" ", 1)[0]
        raise r.fail(f"verdict.{field}", str(e).split(" ", 1)[1]) from None


def _write_verdict(fs, verdict):
    """The ``verdict`` map of :func:`save_camera` (fields that are None or empty left out)."""
    fs.startWriteStruct("verdict", cv2.FileNode_MAP)
    for field in dataclasses.fields(Verdict):
        value = getattr(verdict, field.name)
        if value is None or (isinstance(value, (str, tuple)) and not value):
            continue
        if field.name in ("warnings", "implausible"):
            fs.startWriteStruct(field.name, cv2.FileNode_SEQ)
            for text in value:
                fs.write("", text)
            fs.endWriteStruct()
        elif field.name == "ray_std_deg":
            fs.startWriteStruct(field.name, cv2.FileNode_SEQ)
            for v in value:
                fs.write("", float(v))
            fs.endWriteStruct()
        elif isinstance(value, bool) or field.name == "heldout_folds":
            fs.write(field.name, int(value))
        elif isinstance(value, float):
            fs.write(field.name, value)
        else:
            fs.write(field.name, str(value))
    fs.endWriteStruct()


def read_intrinsics(path: PathLike) -> tuple[FloatArray, FloatArray | None, Size | None]:
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
        As :func:`load_camera`, naming the file and the field; also for the files of central
        models (``cv2.omnidir``, Kalibr ``omni``, OCamCalib), whose ``K`` and ``D`` are not the
        lens's: the message says what the file is (:mod:`omnicam.formats.other_tools`).
    """
    what = "intrinsics file"
    path = file_path(path, what)
    _prescan(path, what)  # nothing that could crash a parser reaches one
    other = read_other_intrinsics(path)
    if other is not None:
        try:
            K, D, size = validate_K(other[0]), validate_D(other[1]), validate_image_size(other[2])
        except ValueError as e:
            raise ValueError(f"{what} {path}: {e}") from None
        return K, (D if D is not None and np.any(D) else None), size
    r = reading(path, what)
    xi = r.node("xi", required=False)
    if xi is not None:  # cv2.omnidir's: the unified model's K and D, not the lens's
        raise ValueError(f"{what} {r.path}: {not_pinhole('a cv2.omnidir calibration', xi)}")
    name = r.first(K_FIELDS, required=True)
    K = r.check(name, validate_K, r.matrix(name, (3, 3), allow_list=True))
    name = r.first(D_FIELDS)
    D = None
    if name is not None:
        D = r.check(name, validate_D, r.matrix(name, allow_list=True))
        if not np.any(D):
            D = None
    size = r.check("image_size", validate_image_size, r.image_size())
    return K, D, size


def read_central_model(path: PathLike) -> dict:
    """The unified (Mei) model of a ``cv2.omnidir`` calibration or a Kalibr ``omni`` camchain.

    ``cv2.omnidir`` files in any ``cv2.FileStorage`` format: its calibration sample's
    ``camera_matrix``, ``distortion_coefficients`` and ``xi``, or ``omnicam export --to
    omnidir``'s ``K``, ``D``, ``xi`` and ``image_size`` (the names of :func:`read_intrinsics`);
    Kalibr camchains whose first camera is ``omni`` (``intrinsics: [xi, fu, fv, pu, pv]``,
    ``radtan`` or no distortion, ``resolution``).

    Returns
    -------
    dict
        In the conventions of :mod:`omnicam.chessboard.central` (its ``CentralFit``):

        * ``"K"``: (3, 3) float64, the unified model's camera matrix ``[[gamma_x, s, c_x],
          [0, gamma_y, c_y], [0, 0, 1]]`` (not the lens's: module notes of
          :mod:`omnicam.formats.other_tools`);
        * ``"xi"``: float, ``>= 0``. A hyperbolic mirror's is in ``(0, 1)``, which
          :func:`~omnicam.chessboard.central.hyperbolic_start` needs; a fit with distortion
          can give ``xi >= 1`` on a rig that is not exactly central (``k1`` trades with ``xi``);
        * ``"D"``: (4,) float64, ``k1, k2, p1, p2`` on the unified model's normalised plane
          (zeros when the file has none);
        * ``"image_size"``: ``(width, height)`` or ``None``.

        ``hyperbolic_start(m["K"], m["xi"], rim_px_radius, rim_radius)`` starts from it.

    Raises
    ------
    FileNotFoundError, ValueError
        As :func:`load_camera`; also a file that holds no central model (pinhole
        intrinsics, an OCamCalib file), the message saying what it is.
    """
    what = "central model file"
    path = file_path(path, what)
    _prescan(path, what)
    model = read_other_central(path)  # Kalibr camchains
    if model is None:
        r = reading(path, what)
        if r.node("xi", required=False) is None:
            raise r.fail("xi", "is missing: not a cv2.omnidir calibration (nor a Kalibr camchain)")
        K = r.matrix(r.first(K_FIELDS, required=True), (3, 3), allow_list=True)
        name = r.first(D_FIELDS)
        D = None if name is None else r.matrix(name, allow_list=True)
        model = K, r.number("xi"), D, r.image_size()
    K, xi, D, size = model
    try:
        return {
            "K": validate_K(K),
            "xi": real_number(xi, "xi", lo=0.0, expected="a finite number >= 0"),
            "D": np.zeros(4)
            if D is None
            else finite_array(D, "D", (4,), "4 numbers (k1 k2 p1 p2)"),
            "image_size": validate_image_size(size),
        }
    except ValueError as e:
        raise ValueError(f"{what} {shown(path)}: {e}") from None


def read_far_lines(path: PathLike) -> list[FloatArray]:
    """Far-line pixels from JSON: a list of lines, each a list of ``[x, y]`` pixels.

    The ``far_lines`` of section 3.2, as a user clicked them along the images of far straight
    lines. Returns a list of ``(N_i, 2)`` float64 arrays (each line at least 3 points). The file
    is pre-scanned as calibration files are (regular file, size, UTF-8, nesting) and parsed by
    the standard library.

    Raises
    ------
    FileNotFoundError
        No file at ``path``.
    ValueError
        Not JSON of that shape, non-finite coordinates, or a file refused by the pre-scan,
        naming the file (and the line).
    """
    what = "far-lines file"
    path = file_path(path, what)
    text = _prescan(path, what, json_only=True)
    name = shown(path)
    data = _json_loads(text, f"{what} {name}")
    try:
        return _far_lines(data, "lines")
    except ValueError as e:
        raise ValueError(f"{what} {name}: {e}") from None


def _far_lines(data, name):
    """Validate far lines (a list of lines of ``[x, y]`` pixels): a list of (N, 2) arrays."""
    expected = "a list of lines, each a list of at least 3 [x, y] pixels"
    if isinstance(data, np.ndarray) and data.ndim == 3:
        data = list(data)
    if not isinstance(data, (list, tuple)) or not data:
        raise ValueError(f"{name} must be {expected}, got {type(data).__name__}")
    lines = []
    for i, line in enumerate(data):
        try:
            arr = np.asarray(line)
        except (TypeError, ValueError, OverflowError):
            arr = None
        if arr is not None and arr.dtype.kind == "O":
            arr = None
        if arr is not None and arr.ndim == 3 and arr.shape[1:] == (1, 2):
            arr = arr.reshape(-1, 2)  # OpenCV's (N, 1, 2)
        if (
            arr is None
            or arr.dtype.kind not in "iuf"
            or arr.ndim != 2
            or arr.shape[1] != 2
            or arr.shape[0] < 3
        ):
            raise ValueError(
                f"{name}: line {i} must be a list of at least 3 [x, y] pixels ({expected})"
            )
        arr = arr.astype(np.float64)
        if not np.isfinite(arr).all():
            raise ValueError(f"{name}: line {i} has non-finite coordinates")
        lines.append(arr)
    return lines


# -- writing ------------------------------------------------------------------------------------
def _atomic_filestorage(path, what, write, read_back):
    """Write a ``cv2.FileStorage`` file through :func:`omnicam._atomic.atomic_output`.

    ``write(fs)`` fills the open storage; ``read_back(tmp)`` must then return True for the
    temporary file (it re-reads it with this module's reader), since ``cv2.FileStorage`` does
    not report a failed write (a full disk leaves an empty or truncated file).
    """
    path = file_path(path, what)
    _suffix(path, what)

    with opencv_silenced(), atomic_output(path, what=what, verify=read_back) as tmp:
        fs = None
        try:
            # an unreleased FileStorage writes its file when it is collected, possibly after
            # the temporary was removed: no Ctrl-C between creating it and owning it
            with sigint_deferred():
                fs = cv2.FileStorage(tmp, cv2.FILE_STORAGE_WRITE)
            if not fs.isOpened():
                raise OutputError(
                    f"cannot write {what} {shown(path)}: OpenCV cannot open it for writing"
                )
            write(fs)
        finally:
            if fs is not None:
                fs.release()


def _write_seq(fs, name, values):
    fs.startWriteStruct(name, cv2.FileNode_SEQ)
    for v in values:
        fs.write("", int(v))
    fs.endWriteStruct()


def save_camera(
    camera: MisalignedCatadioptricCamera, path: PathLike, verdict: object = None
) -> None:
    """Write ``camera`` to ``path`` atomically and verified, with its verdict if given.

    A temporary file in the same folder is written, flushed, read back and compared with
    ``camera`` (and ``verdict``), and only then renamed into place
    (:func:`omnicam._atomic.atomic_output`).

    Parameters
    ----------
    camera : MisalignedCatadioptricCamera
    path : str or os.PathLike
        ``.yaml``, ``.yml``, ``.xml`` or ``.json`` (the format follows the extension).
    verdict : Verdict or a calibration report, optional
        Recorded as the file's ``verdict`` map (:class:`Verdict`); a ``CalibrationReport`` or
        ``PatternReport`` is taken as :meth:`Verdict.from_report` of it. None: no verdict.

    Raises
    ------
    ValueError
        Unknown extension, a name that is not UTF-8, a ``verdict`` that is neither, or the file
        cannot be written (missing or read-only folder, full disk, a folder in the way, ...):
        the message names the file, the old file at ``path`` is unchanged and no temporary file
        is left.
    """
    if verdict is not None and not isinstance(verdict, Verdict):
        verdict = Verdict.from_report(verdict)

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
        if camera.camera_reflection is not None:
            fs.startWriteStruct("camera_reflection", cv2.FileNode_MAP)
            fs.write("r", float(camera.camera_reflection[0]))
            fs.write("z", float(camera.camera_reflection[1]))
            fs.endWriteStruct()
        if verdict is not None:
            _write_verdict(fs, verdict)

    def read_back(tmp):
        return _same_camera(load_camera(tmp), camera) and read_verdict(tmp) == verdict

    _atomic_filestorage(path, "calibration file", write, read_back)


def _close(a, b):
    if a is None or b is None:
        return a is None and b is None
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return a.shape == b.shape and np.allclose(a, b, rtol=1e-12, atol=1e-12)


def _same_camera(a, b):
    return (
        a.mirror == b.mirror
        and a.image_size == b.image_size
        and all(
            _close(getattr(a, n), getattr(b, n))
            for n in ("K", "D", "rvec", "tvec", "camera_reflection")
        )
    )


def write_intrinsics(
    path: PathLike, K: ArrayLike, D: ArrayLike | None = None, image_size: Size | None = None
) -> None:
    """Write a pinhole's ``K``, ``D`` and ``image_size`` (what :func:`read_intrinsics` reads).

    Atomic and verified as :func:`save_camera`.

    Raises
    ------
    ValueError
        A bad ``K``, ``D`` or ``image_size`` (naming it), or the file cannot be written (as
        :func:`save_camera`; the old file is unchanged).
    """
    K, D, image_size = validate_K(K), validate_D(D), validate_image_size(image_size)

    def write(fs):
        fs.write("K", K)
        if D is not None:
            fs.write("D", D.reshape(1, -1))
        if image_size is not None:
            _write_seq(fs, "image_size", image_size)

    def read_back(tmp):
        K2, D2, size2 = read_intrinsics(tmp)
        return (
            _close(K2, K)
            and size2 == image_size
            and (_close(D2, D) if D2 is not None or D is None or np.any(D) else True)
        )

    _atomic_filestorage(path, "intrinsics file", write, read_back)


def write_far_lines(path: PathLike, far_lines: list) -> None:
    """Write far-line pixels as JSON (what :func:`read_far_lines` reads), atomically.

    Raises
    ------
    ValueError
        ``far_lines`` is not a list of lines of at least 3 finite ``[x, y]`` pixels (naming
        it), or the file cannot be written (the old file is unchanged, naming the file).
    """
    what = "far-lines file"
    path = file_path(path, what)
    data = [line.tolist() for line in _far_lines(far_lines, "far_lines")]

    def verify(tmp):
        with open(tmp, encoding="utf-8") as f:
            return json.load(f) == data

    write_bytes(path, json.dumps(data), what=what, verify=verify)
