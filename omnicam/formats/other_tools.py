"""Other tools' camera files: pinhole intrinsics to read, and central models that are not.

:func:`omnicam.read_intrinsics` asks :func:`read_other_intrinsics` first; it reads

* ROS ``camera_info`` YAML (``camera_matrix: {rows, cols, data}``, ``distortion_model``
  ``plumb_bob`` or ``rational_polynomial``, ``distortion_coefficients``, ``image_width``,
  ``image_height``), as ``camera_calibration`` writes it;
* a Kalibr camchain with a ``pinhole`` camera and ``radtan`` distortion (``intrinsics: [fu, fv,
  pu, pv]``, ``distortion_coeffs: [k1, k2, r1, r2]``, ``resolution: [w, h]``; the first camera,
  ``cam0``, of a chain);

and returns ``None`` for anything else, which ``read_intrinsics`` reads with ``cv2.FileStorage``
(omnicam's own names, those of OpenCV's calibration sample, an ``image_size`` matrix).

**Central models are not pinhole intrinsics.** A ``cv2.omnidir`` calibration (a FileStorage
file with an ``xi``), a Kalibr ``omni`` camera and an OCamCalib ``calib_results.txt`` describe
the whole catadioptric camera as one central model. Their ``K`` is the unified model's, whose
focal length for a hyperbolic mirror is ``f sqrt(1 - xi^2)``, not the lens's ``f``, and their
``D`` distorts the unified projection, not the lens (:mod:`omnicam.chessboard.central`);
OCamCalib's polynomial has no ``K`` at all. Taken as the lens's ``K`` and ``D`` they would give a
wrong camera without a word, so they are refused with that reason (:func:`not_pinhole`; the
``cv2.omnidir`` files by ``read_intrinsics``, which parses FileStorage files), and the unified
ones are read by :func:`omnicam.read_central_model` as a central model, where a chessboard
calibration can start (:func:`read_other_central` reads Kalibr's).

The YAML of ROS and Kalibr is PyYAML's, not OpenCV's: ``cv2.FileStorage`` refuses Kalibr's block
sequences written at their key's own indentation (``T_cn_cnm1:`` then ``- [...]`` lines, in
every chain of two cameras or with an IMU), so :func:`parse_yaml` reads the subset those tools
write: block mappings and sequences, flow lists and maps (over several lines too), plain and
quoted scalars, tags, comments. Not anchors, aliases, multi-line plain scalars or block scalars.
"""

from __future__ import annotations

import math
import os
import re

import numpy as np

__all__ = [
    "MAX_BYTES",
    "MAX_NESTING",
    "OCAMCALIB_HEADER",
    "not_pinhole",
    "parse_yaml",
    "read_other_central",
    "read_other_intrinsics",
]

#: Intrinsics files are small; anything larger is not one of these formats.
MAX_BYTES = 1 << 20
#: Deepest nesting :func:`parse_yaml` reads (blocks and flow collections).
MAX_NESTING = 64
#: The first line of OCamCalib's ``calib_results.txt``, as its toolbox writes it.
OCAMCALIB_HEADER = "#polynomial coefficients for the DIRECT mapping function"


# -- the YAML subset of ROS and Kalibr ------------------------------------------------------------
_TAG = re.compile(r"^!!?[\w.:-]+\s*")  # tags such as !!opencv-matrix, !!float
_KEY = re.compile(r"((?:\"[^\"]*\")|(?:'[^']*')|[^:#{}\[\],'\"][^:]*?)\s*:(?:\s+|$)(.*)$")
_FLOW_KEY = re.compile(r"\s*([^:,{}\[\]]+?)\s*:\s*")
_FLOW_SCALAR = re.compile(r"[^,\]}]*")


def _strip_comment(line):
    out, quote = [], None
    for i, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "'\"":
            quote = ch
        elif ch == "#" and (i == 0 or line[i - 1] in " \t"):
            break
        out.append(ch)
    return "".join(out).rstrip()


def _open_brackets(text):
    return text.count("[") + text.count("{") - text.count("]") - text.count("}")


def _logical_lines(text):
    """``(indent, content)`` lines, comments and directives dropped, flow values joined."""
    out = []
    pending = None
    for raw in text.splitlines():
        line = _strip_comment(raw.replace("\t", "    "))
        if pending is not None:
            pending[1] += " " + line.strip()
            if _open_brackets(pending[1]) <= 0:
                out.append(tuple(pending))
                pending = None
            continue
        if not line.strip() or line.startswith("%") or line.strip() in ("---", "..."):
            continue
        indent = len(line) - len(line.lstrip(" "))
        content = line.strip()
        if _open_brackets(content) > 0:
            pending = [indent, content]
            continue
        out.append((indent, content))
    if pending is not None:
        raise ValueError("unclosed [ or {")
    return out


def _scalar(text):
    t = _TAG.sub("", text.strip())
    if len(t) >= 2 and t[0] == t[-1] and t[0] in "'\"":
        return t[1:-1]
    low = t.lower()
    if low in ("", "~", "null"):
        return None
    if low in ("true", "false"):
        return low == "true"
    if re.fullmatch(r"[-+]?\d+", t):
        return int(t)
    try:
        return float(t)
    except ValueError:
        return t


def _skip(text, pos, chars):
    while pos < len(text) and text[pos] in chars:
        pos += 1
    return pos


def _flow_items(text, pos, close, depth):
    """The items of ``[...]`` (``close="]"``) or ``{...}`` after the opening bracket."""
    items = [] if close == "]" else {}
    while True:
        pos = _skip(text, pos, " \t,")
        if pos >= len(text):
            raise ValueError(f"unclosed {'[' if close == ']' else '{'}")
        if text[pos] == close:
            return items, pos + 1
        if text[pos] in "]}":  # the other closing bracket: no value there, so no progress
            raise ValueError(f"{text[pos]!r} where {close!r} closes")
        if close == "]":
            value, pos = _flow_value(text, pos, depth + 1)
            items.append(value)
            continue
        m = _FLOW_KEY.match(text, pos)
        if not m:
            raise ValueError("malformed {...}")
        items[m.group(1)], pos = _flow_value(text, m.end(), depth + 1)


def _flow_value(text, pos, depth=0):
    """The flow value at ``text[pos:]`` (a list, a map or a scalar) and the position after it."""
    if depth > MAX_NESTING:
        raise ValueError("nested too deeply")
    pos = _skip(text, pos, " \t")
    if pos < len(text) and text[pos] in "[{":
        return _flow_items(text, pos + 1, "]" if text[pos] == "[" else "}", depth)
    end = _FLOW_SCALAR.match(text, pos).end()
    return _scalar(text[pos:end]), end


def _value_text(text):
    """An inline value: a flow collection or a scalar."""
    text = _TAG.sub("", text.strip())
    if not text.startswith(("[", "{")):
        return _scalar(text)
    value, pos = _flow_value(text, 0)
    if text[pos:].strip():
        raise ValueError(f"unexpected text after a flow value: {text[pos:].strip()[:20]!r}")
    return value


def _is_item(content):
    return content == "-" or content.startswith("- ")


def _node(lines, i, depth):
    """The block node starting at ``lines[i]``, at that line's indentation: a sequence, a
    mapping or one inline value; returns ``(value, index of the next line)``."""
    if depth > MAX_NESTING:
        raise ValueError("nested too deeply")
    content = lines[i][1]
    if _is_item(content):
        return _sequence(lines, i, depth)
    if _KEY.match(content) and not content.startswith(("[", "{")):
        return _mapping(lines, i, depth)
    return _value_text(content), i + 1


def _check_end(lines, i, indent):
    if i < len(lines) and lines[i][0] > indent:
        raise ValueError(f"unexpected indentation at {lines[i][1][:40]!r}")


def _sequence(lines, i, depth):
    indent, out = lines[i][0], []
    while i < len(lines) and lines[i][0] == indent and _is_item(lines[i][1]):
        rest = lines[i][1][1:].lstrip()
        if rest:  # the item starts on the dash's line, at the column where its text does
            lines[i] = (indent + len(lines[i][1]) - len(rest), rest)
            value, i = _node(lines, i, depth + 1)
        elif i + 1 < len(lines) and lines[i + 1][0] > indent:
            value, i = _node(lines, i + 1, depth + 1)
        else:
            value, i = None, i + 1
        out.append(value)
    _check_end(lines, i, indent)
    return out, i


def _mapping(lines, i, depth):
    indent, out = lines[i][0], {}
    while i < len(lines) and lines[i][0] == indent and not _is_item(lines[i][1]):
        m = _KEY.match(lines[i][1])
        if not m:
            raise ValueError(f"expected 'key: value', got {lines[i][1][:40]!r}")
        key, rest = m.group(1).strip("'\""), _TAG.sub("", m.group(2).strip())
        i += 1
        below = i < len(lines) and (
            lines[i][0] > indent or (lines[i][0] == indent and _is_item(lines[i][1]))
        )  # a nested block, or a sequence at the key's own indentation (PyYAML's style)
        if rest:
            out[key] = _value_text(rest)
        elif below:
            out[key], i = _node(lines, i, depth + 1)
        else:
            out[key] = None
    _check_end(lines, i, indent)
    return out, i


def parse_yaml(text):
    """The mappings, sequences and scalars of a block-style YAML document (see module notes).

    Integers, reals, ``true``/``false`` and ``null``/``~`` are read as Python values, anything
    else as a string; duplicate keys keep the last value.

    Raises
    ------
    ValueError
        Text outside the subset this reads, or nested deeper than :data:`MAX_NESTING`.
    """
    lines = _logical_lines(text)
    if not lines:
        return {}
    value, i = _node(lines, 0, 0)
    if i != len(lines):
        raise ValueError(f"unexpected text at {lines[i][1][:40]!r}")
    return value


# -- central models -------------------------------------------------------------------------------
def not_pinhole(what, xi=None):
    """Why the file, ``what`` (e.g. "a cv2.omnidir calibration"), gives no pinhole ``K`` and
    ``D``: one sentence to follow the file's name in a ``ValueError``."""
    if what.startswith("an OCamCalib"):
        return (
            f"{what} (Scaramuzza's polynomial model of the whole catadioptric camera), not "
            f"pinhole intrinsics: it holds no K or D of the lens under the mirror, and omnicam "
            f"cannot import it; give the lens's own K (and D), or calibrate from chessboards "
            f"(omnicam calibrate --chessboard), which needs no K"
        )
    xi_text = f", xi = {xi:.6g}" if isinstance(xi, (int, float)) else ""
    return (
        f"{what} (the unified central model{xi_text}), not pinhole intrinsics: its K is the "
        f"unified model's, whose focal length is f sqrt(1 - xi^2) for a hyperbolic mirror, not "
        f"the lens's f, and its D distorts the unified projection, not the lens; give the "
        f"lens's own K (and D), or read it with omnicam.read_central_model as the start of "
        f"a chessboard calibration"
    )


# -- the formats ----------------------------------------------------------------------------------
def _numbers(value, what, count=None):
    try:
        arr = np.array(value, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be a list of numbers") from None
    if count is not None and arr.size != count:
        raise ValueError(f"{what} must have {count} numbers, got {arr.size}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{what} must be finite")
    return arr


def _int(value, what):
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or not math.isfinite(value)
        or value != int(value)
        or value <= 0
    ):
        raise ValueError(f"{what} must be a positive integer, got {value!r}")
    return int(value)


def _from_ros(doc):
    cm = doc["camera_matrix"]
    data = cm.get("data") if isinstance(cm, dict) else cm
    K = _numbers(data, "field 'camera_matrix.data'", 9).reshape(3, 3)
    D = None
    dist = doc.get("distortion_coefficients", doc.get("D"))
    model = str(doc.get("distortion_model", "plumb_bob"))
    if model not in ("plumb_bob", "rational_polynomial"):
        raise ValueError(
            f"field 'distortion_model' is {model!r}; omnicam reads OpenCV's "
            f"plumb_bob and rational_polynomial (equidistant is a fisheye model)"
        )
    if dist is not None:
        data = dist.get("data") if isinstance(dist, dict) else dist
        if data:
            D = _numbers(data, "field 'distortion_coefficients.data'")
    size = None
    if "image_width" in doc or "image_height" in doc:
        size = (
            _int(doc.get("image_width"), "field 'image_width'"),
            _int(doc.get("image_height"), "field 'image_height'"),
        )
    return K, D, size


def _kalibr_camera(doc):
    """The first camera of a camchain (``cam0``, else the lowest ``camN``, else the document)."""
    cams = [k for k in doc if re.fullmatch(r"cam\d+", str(k)) and isinstance(doc[k], dict)]
    return doc["cam0"] if "cam0" in doc else doc[min(cams)] if cams else doc


def _kalibr_distortion(cam, names):
    dm = cam.get("distortion_model", "none")
    if dm == "radtan":
        return _numbers(cam.get("distortion_coeffs"), "field 'distortion_coeffs'", 4)
    if dm not in ("none", None):
        raise ValueError(
            f"field 'distortion_model' is {dm!r}; omnicam reads Kalibr's radtan ({names})"
        )
    return None


def _kalibr_size(cam):
    if cam.get("resolution") is None:
        return None
    w, h = _numbers(cam.get("resolution"), "field 'resolution'", 2)
    return (_int(w, "field 'resolution'"), _int(h, "field 'resolution'"))


def _from_kalibr(doc):
    cam = _kalibr_camera(doc)
    model = cam.get("camera_model")
    if model == "omni":
        xi = cam.get("intrinsics", [None])[0] if isinstance(cam.get("intrinsics"), list) else None
        raise ValueError(not_pinhole("a Kalibr camchain with camera_model 'omni'", xi))
    if model != "pinhole":
        raise ValueError(
            f"field 'camera_model' is {model!r}; omnicam reads Kalibr's pinhole "
            f"cameras (its lens under the mirror)"
        )
    fu, fv, pu, pv = _numbers(cam.get("intrinsics"), "field 'intrinsics'", 4)
    K = np.array([[fu, 0.0, pu], [0.0, fv, pv], [0.0, 0.0, 1.0]])
    D = _kalibr_distortion(cam, "OpenCV's k1 k2 p1 p2")
    return K, D, _kalibr_size(cam)


def _kalibr_omni(doc):
    cam = _kalibr_camera(doc)
    if cam.get("camera_model") != "omni":
        raise ValueError(
            f"field 'camera_model' is {cam.get('camera_model')!r}, not a central model: "
            f"omnicam reads Kalibr's omni cameras as one (a pinhole camchain is read by "
            f"omnicam.read_intrinsics)"
        )
    xi, fu, fv, pu, pv = _numbers(cam.get("intrinsics"), "field 'intrinsics'", 5)
    K = np.array([[fu, 0.0, pu], [0.0, fv, pv], [0.0, 0.0, 1.0]])
    D = _kalibr_distortion(cam, "k1 k2 p1 p2 on the unified projection")
    return K, float(xi), D, _kalibr_size(cam)


def _text(path):
    """The file's text if it may be one of these formats (small, UTF-8), else ``None``."""
    if not os.path.isfile(path) or os.path.getsize(path) > MAX_BYTES:
        return None
    try:
        with open(path, "rb") as f:
            return f.read().decode("utf-8")
    except (OSError, UnicodeDecodeError):
        return None


def _read_other(path, what, read_ros, read_kalibr):
    """Dispatch on the text of ``path``: OCamCalib refused, ROS and Kalibr YAML read, else
    ``None``; every failure a ``ValueError`` naming the file (``what`` it was read as)."""
    path = os.fspath(path)
    name = f"{what} {path}"
    text = _text(path)
    if text is None:
        return None
    if text.lstrip().startswith(OCAMCALIB_HEADER):
        raise ValueError(f"{name}: {not_pinhole('an OCamCalib calib_results.txt')}")
    if (
        os.path.splitext(path)[1].lower() not in (".yaml", ".yml")
        or "!!opencv-matrix" in text
        or not re.search(r"^\s*(camera_matrix|camera_model)\s*:", text, re.MULTILINE)
    ):
        return None
    try:
        doc = parse_yaml(text)
    except ValueError as e:
        raise ValueError(f"{name}: not YAML omnicam can read ({e})") from None
    if not isinstance(doc, dict):
        return None
    try:
        return read_ros(doc) if "camera_matrix" in doc else read_kalibr(doc)
    except ValueError as e:
        raise ValueError(f"{name}: {e}") from None
    except (KeyError, TypeError, AttributeError):
        raise ValueError(
            f"{name}: a ROS camera_info or Kalibr camchain without its camera fields"
        ) from None


def read_other_intrinsics(path):
    """``(K, D, image_size)`` from a ROS or Kalibr YAML file; ``None`` when it is neither.

    Only :func:`parse_yaml` reads the file (never ``cv2.FileStorage``); call it after
    :mod:`.omnicam_files`' pre-scan. ``image_size`` written as an OpenCV matrix is read by
    :func:`omnicam.read_intrinsics` itself.

    Returns
    -------
    None, or a tuple ``(K, D, image_size)`` (unvalidated).

    Raises
    ------
    ValueError
        The file is one of these formats but a field is missing or malformed, or it is a
        central model (a Kalibr omni camera, an OCamCalib file: module notes); the message
        names the file and the field or the reason.
    """
    return _read_other(path, "intrinsics file", _from_ros, _from_kalibr)


def read_other_central(path):
    """``(K, xi, D, image_size)`` of a Kalibr ``omni`` camchain (unvalidated; ``D`` ``None``
    without distortion); ``None`` when the file is not a ROS or Kalibr YAML file.

    Raises
    ------
    ValueError
        A Kalibr camchain of another camera model, a ROS ``camera_info`` (pinhole intrinsics),
        an OCamCalib file, or a missing or malformed field; the message names the file.
    """

    def ros(doc):
        raise ValueError(
            "a ROS camera_info: pinhole intrinsics, not a central model (read it with "
            "omnicam.read_intrinsics)"
        )

    return _read_other(path, "central model file", ros, _kalibr_omni)
