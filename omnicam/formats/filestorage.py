"""The ``cv2.FileStorage`` files under omnicam's own: a pre-scan, a reader that cannot crash, a
verified atomic writer.

``cv2.FileStorage`` (OpenCV 4.x and 5.0) cannot be handed any file: it crashes the process on a
file name that is not valid UTF-8 and on deeply nested JSON or XML (its parsers recurse without
a limit), corrupts its heap on some corrupt ``.json`` files, raises a raw
``UnicodeDecodeError`` on non-UTF-8 strings, saturates out-of-range values silently (``dt: u``
with the value 583 reads as 255), wraps integers beyond 32 bits and YAML's booleans into small
integers (``4294967297`` and ``true`` both read as 1), prints its own ``persistence.cpp`` error
lines on stderr, and takes time linear in the position for ``FileNode.getNode`` and
``FileNode.at`` (quadratic over a file of many keys).

So before OpenCV sees anything, :func:`prescan` refuses (``ValueError`` naming the file) a name
that is not UTF-8, anything but a regular file (a folder, FIFO or device: "is not a regular
file"), files over ``MAX_FILE_BYTES`` (1 MiB), empty or binary files (a NUL byte), text that is
not UTF-8, nesting deeper than ``MAX_DEPTH`` (brackets, XML elements, YAML indentation) and
base64 blocks (omnicam never writes them), and in YAML and XML integers beyond 32 bits and
the booleans ``true``/``false``. JSON is then parsed by the standard library alone and
never reaches OpenCV; YAML and XML are parsed by ``cv2.FileStorage`` from the checked text in
memory (so what OpenCV parses is what was checked), with its log silenced, and its node tree is
copied into Python values (maps over ``MAX_FIELDS`` keys and sequences over ``MAX_VALUES`` items
refused, and only the fields asked for read). Matrices are rebuilt from ``rows``, ``cols``,
``dt`` and ``data`` here, every value checked against the range of its ``dt``
(:class:`Reader`).

Writing goes through :func:`omnicam._atomic.atomic_output` and is verified by reading the
temporary file back (:func:`atomic_filestorage`): a failure (full disk, read-only folder, ...)
raises ``ValueError`` naming the file and keeps the old file.
"""

from __future__ import annotations

import json
import math
import os
import re

import cv2
import numpy as np

from .._atomic import OutputError, atomic_output, sigint_deferred
from .._quiet import opencv_silenced
from .._validate import file_path, regular_file, shown

__all__ = [
    "MAX_DEPTH",
    "MAX_FIELDS",
    "MAX_FILE_BYTES",
    "MAX_VALUES",
    "SUFFIXES",
    "Reader",
    "atomic_filestorage",
    "check_suffix",
    "is_number",
    "json_loads",
    "prescan",
    "reading",
    "same_values",
    "write_int_seq",
]

SUFFIXES = (".yaml", ".yml", ".xml", ".json")
MAX_FILE_BYTES = 1 << 20  # calibration, intrinsics and far-line files are a few kB
MAX_DEPTH = 32  # nesting of brackets / elements / YAML blocks (ours: 3)
MAX_INDENT = 128  # columns of YAML indentation
MAX_FIELDS = 256  # keys of a map
MAX_VALUES = 4096  # items of a sequence (our matrices hold at most 14)
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
LONG_INT = re.compile(r"(?<![\w.+-])[-+]?\d{10,}(?![\w.])")  # 10+ digits, not part of a real


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


def prescan(path, what, json_only=False):
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
    for m in LONG_INT.finditer(text):
        digits = m.group().lstrip("+-")
        if len(digits) > 10 or abs(int(m.group())) > 2**31 - 1:
            number = m.group() if len(digits) <= 20 else f"of {len(digits)} digits"
            raise ValueError(
                f"{label}: the integer {number} ({_where(text, m.start())}) does not fit in 32 "
                f"bits (OpenCV would read it wrapped around); write it as a real number"
                + (f" such as {m.group()}." if len(digits) <= 20 else "")
            )


def check_suffix(path, what="calibration file"):
    """The extension of ``path`` (lower case), one of ``SUFFIXES``, or ``ValueError``."""
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


def json_loads(text, label, invalid="not valid JSON"):
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
        data = json_loads(
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


def is_number(v):
    """A number of a parsed file: an int or a float, not a bool."""
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
        if not is_number(value):
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
            if not is_number(v) or (integer and not isinstance(v, int)):
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
    ext = check_suffix(path, what)
    return Reader(_parse(prescan(path, what), path, what, ext), path, what)


# -- writing ------------------------------------------------------------------------------------
def atomic_filestorage(path, what, write, read_back):
    """Write a ``cv2.FileStorage`` file through :func:`omnicam._atomic.atomic_output`.

    ``write(fs)`` fills the open storage; ``read_back(tmp)`` must then return True for the
    temporary file (it re-reads it with this module's reader), since ``cv2.FileStorage`` does
    not report a failed write (a full disk leaves an empty or truncated file).
    """
    path = file_path(path, what)
    check_suffix(path, what)

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


def write_int_seq(fs, name, values):
    """``values`` as the sequence of integers ``name`` (``image_size: [w, h]``)."""
    fs.startWriteStruct(name, cv2.FileNode_SEQ)
    for v in values:
        fs.write("", int(v))
    fs.endWriteStruct()


def same_values(a, b):
    """Both None, or arrays of one shape equal to 1e-12: what a read-back check compares."""
    if a is None or b is None:
        return a is None and b is None
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return a.shape == b.shape and np.allclose(a, b, rtol=1e-12, atol=1e-12)
