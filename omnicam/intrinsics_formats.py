"""Pinhole intrinsics in the formats users already have: ROS, Kalibr, OpenCV files.

:func:`omnicam.io.read_intrinsics` asks :func:`read_other_intrinsics` first; it recognises

* ROS ``camera_info`` YAML (``camera_matrix: {rows, cols, data}``, ``distortion_model``
  ``plumb_bob`` or ``rational_polynomial``, ``distortion_coefficients``, ``image_width``,
  ``image_height``), as ``camera_calibration`` writes it;
* a Kalibr camchain with a ``pinhole`` camera and ``radtan`` distortion (``intrinsics: [fu, fv,
  pu, pv]``, ``distortion_coeffs: [k1, k2, r1, r2]``, ``resolution: [w, h]``; the first camera,
  ``cam0``, of a chain);
* an OpenCV ``FileStorage`` file whose ``image_size`` is a matrix (``fs.write("image_size",
  np.array([w, h]))``) rather than a list;

and returns ``None`` for anything else, which ``read_intrinsics`` reads as before (omnicam's own
names and those of OpenCV's calibration sample, ``out_camera_data.yml``). The YAML of ROS and
Kalibr is not OpenCV's (no ``%YAML:1.0`` header, no ``!!opencv-matrix``), so it is read by
:func:`parse_yaml`, a small reader of the block/flow subset those tools write (mappings,
sequences, flow lists, numbers, strings, comments) -- not a general YAML parser.
"""

from __future__ import annotations

import math
import os
import re

import numpy as np

__all__ = ["MAX_BYTES", "parse_yaml", "read_other_intrinsics"]

#: Intrinsics files are small; anything larger is not one of these formats.
MAX_BYTES = 1 << 20


# -- a small YAML reader --------------------------------------------------------------------------
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


def _scalar(text):
    t = text.strip()
    t = re.sub(r"^!!?[\w.:-]+\s*", "", t)  # tags such as !!opencv-matrix, !!float
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


def _flow(text):
    """``[a, b, [c, d]]`` or ``{k: v}`` -> python values."""
    pos = 0

    def value():
        nonlocal pos
        while pos < len(text) and text[pos] in " \t":
            pos += 1
        if pos < len(text) and text[pos] == "[":
            pos += 1
            items = []
            while True:
                while pos < len(text) and text[pos] in " \t,":
                    pos += 1
                if pos >= len(text):
                    raise ValueError("unclosed [")
                if text[pos] == "]":
                    pos += 1
                    return items
                items.append(value())
        if pos < len(text) and text[pos] == "{":
            pos += 1
            items = {}
            while True:
                while pos < len(text) and text[pos] in " \t,":
                    pos += 1
                if pos >= len(text):
                    raise ValueError("unclosed {")
                if text[pos] == "}":
                    pos += 1
                    return items
                m = re.match(r"\s*([^:,{}\[\]]+?)\s*:\s*", text[pos:])
                if not m:
                    raise ValueError("malformed {...}")
                pos += m.end()
                items[m.group(1)] = value()
        m = re.match(r"[^,\]}]*", text[pos:])
        pos += m.end()
        return _scalar(m.group(0))

    out = value()
    if text[pos:].strip():
        raise ValueError(f"unexpected text after a flow value: {text[pos:].strip()[:20]!r}")
    return out


def _logical_lines(text):
    """``(indent, content)`` lines, comments and directives dropped, flow values joined."""
    out = []
    pending = None
    for raw in text.splitlines():
        line = _strip_comment(raw.replace("\t", "    "))
        if pending is not None:
            pending[1] += " " + line.strip()
            if pending[1].count("[") + pending[1].count("{") <= pending[1].count("]") + pending[
                1
            ].count("}"):
                out.append(tuple(pending))
                pending = None
            continue
        if not line.strip() or line.startswith("%") or line.strip() in ("---", "..."):
            continue
        indent = len(line) - len(line.lstrip(" "))
        content = line.strip()
        if content.count("[") + content.count("{") > content.count("]") + content.count("}"):
            pending = [indent, content]
            continue
        out.append((indent, content))
    if pending is not None:
        raise ValueError("unclosed [ or {")
    return out


_KEY = re.compile(r"((?:\"[^\"]*\")|(?:'[^']*')|[^:#{}\[\],][^:]*?)\s*:(?:\s+|$)(.*)$")


def _value_text(text):
    text = text.strip()
    tagless = re.sub(r"^!!?[\w.:-]+\s*", "", text)
    if tagless.startswith(("[", "{")):
        return _flow(tagless)
    return _scalar(text)


def _block(lines, i, indent):
    """Parse the block starting at ``lines[i]`` with this ``indent``; ``(value, next_i)``."""
    if lines[i][1].startswith("- ") or lines[i][1] == "-":
        seq = []
        while (
            i < len(lines)
            and lines[i][0] == indent
            and (lines[i][1].startswith("- ") or lines[i][1] == "-")
        ):
            rest = lines[i][1][1:].strip()
            if not rest:
                if i + 1 < len(lines) and lines[i + 1][0] > indent:
                    value, i = _block(lines, i + 1, lines[i + 1][0])
                else:
                    value, i = None, i + 1
            elif _KEY.match(rest) and not rest.startswith(("[", "{", "'", '"')):
                # "- key: value" starts a mapping nested in the sequence item
                sub = [(indent + 2, rest)]
                j = i + 1
                while j < len(lines) and lines[j][0] > indent:
                    sub.append(lines[j])
                    j += 1
                value, _ = _block(sub, 0, indent + 2)
                i = j
            else:
                value, i = _value_text(rest), i + 1
            seq.append(value)
        return seq, i
    mapping = {}
    while i < len(lines) and lines[i][0] == indent:
        m = _KEY.match(lines[i][1])
        if not m:
            raise ValueError(f"expected 'key: value', got {lines[i][1][:40]!r}")
        key = m.group(1).strip("'\"")
        rest = m.group(2)
        i += 1
        tag_only = re.fullmatch(r"!!?[\w.:-]+", rest.strip() or "x") is not None
        if (not rest.strip() or tag_only) and i < len(lines) and lines[i][0] > indent:
            mapping[key], i = _block(lines, i, lines[i][0])
        elif (
            (not rest.strip() or tag_only)
            and i < len(lines)
            and lines[i][0] == indent
            and lines[i][1].startswith("- ")
        ):
            mapping[key], i = _block(lines, i, indent)  # a sequence at the key's own indent
        else:
            mapping[key] = None if tag_only else _value_text(rest)
    if i < len(lines) and lines[i][0] > indent:
        raise ValueError(f"unexpected indentation at {lines[i][1][:40]!r}")
    return mapping, i


def parse_yaml(text):
    """The mappings, sequences and scalars of a block-style YAML document (see module notes).

    Raises
    ------
    ValueError
        Text outside the subset this reads.
    """
    if not _shallow(text):
        raise ValueError("nested too deeply")
    lines = _logical_lines(text)
    if not lines:
        return {}
    try:
        value, i = _block(lines, 0, lines[0][0])
    except RecursionError:
        raise ValueError("nested too deeply") from None
    if i != len(lines):
        raise ValueError(f"unexpected text at {lines[i][1][:40]!r}")
    return value


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


def _from_kalibr(doc):
    cams = [k for k in doc if re.fullmatch(r"cam\d+", str(k)) and isinstance(doc[k], dict)]
    cam = doc["cam0"] if "cam0" in doc else doc[min(cams)] if cams else doc
    model = cam.get("camera_model")
    if model != "pinhole":
        raise ValueError(
            f"field 'camera_model' is {model!r}; omnicam reads Kalibr's pinhole "
            f"cameras (its lens under the mirror)"
        )
    fu, fv, pu, pv = _numbers(cam.get("intrinsics"), "field 'intrinsics'", 4)
    K = np.array([[fu, 0.0, pu], [0.0, fv, pv], [0.0, 0.0, 1.0]])
    dm = cam.get("distortion_model", "none")
    D = None
    if dm == "radtan":
        D = _numbers(cam.get("distortion_coeffs"), "field 'distortion_coeffs'", 4)
    elif dm not in ("none", None):
        raise ValueError(
            f"field 'distortion_model' is {dm!r}; omnicam reads Kalibr's radtan "
            f"(OpenCV's k1 k2 p1 p2)"
        )
    size = None
    if cam.get("resolution") is not None:
        w, h = _numbers(cam.get("resolution"), "field 'resolution'", 2)
        size = (_int(w, "field 'resolution'"), _int(h, "field 'resolution'"))
    return K, D, size


def _shallow(text, limit=64):
    """No brackets or XML elements nested deeper than ``limit`` (cv2.FileStorage has crashed on
    deeply nested files): only such files are handed to it here."""
    depth = 0
    i, n = 0, len(text)
    while i < n:
        ch = text[i]
        if ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "<" and i + 1 < n:
            nxt = text[i + 1]
            if nxt == "/":
                depth -= 1
            elif nxt not in "?!":
                end = text.find(">", i)
                if end > 0 and text[end - 1] != "/":
                    depth += 1
        if depth > limit:
            return False
        i += 1
    return True


def read_other_intrinsics(path):
    """``(K, D, image_size)`` from a ROS or Kalibr YAML file; ``None`` when it is neither.

    Only omnicam's own small YAML parser reads the file (never ``cv2.FileStorage``); call it
    after :func:`omnicam.io`'s pre-scan. ``image_size`` written as an OpenCV matrix is read by
    :func:`omnicam.io.read_intrinsics` itself.

    Returns
    -------
    None, or a tuple ``(K, D, image_size)`` (unvalidated).

    Raises
    ------
    ValueError
        The file is one of these formats but a field is missing or malformed; the message
        names the file and the field.
    """
    path = os.fspath(path)
    if os.path.splitext(path)[1].lower() not in (
        ".yaml",
        ".yml",
        ".xml",
        ".json",
    ) or not os.path.isfile(path):
        return None
    if os.path.getsize(path) > MAX_BYTES:
        return None
    try:
        with open(path, "rb") as f:
            raw = f.read()
        text = raw.decode("utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    yaml = os.path.splitext(path)[1].lower() in (".yaml", ".yml")
    if (
        yaml
        and "!!opencv-matrix" not in text
        and re.search(r"^\s*(camera_matrix|camera_model)\s*:", text, re.MULTILINE)
    ):
        try:
            doc = parse_yaml(text)
        except ValueError as e:
            raise ValueError(f"intrinsics file {path}: not YAML omnicam can read ({e})") from None
        try:
            if isinstance(doc, dict) and "camera_matrix" in doc:
                return _from_ros(doc)
            if isinstance(doc, dict):
                return _from_kalibr(doc)
        except ValueError as e:
            raise ValueError(f"intrinsics file {path}: {e}") from None
        except (KeyError, TypeError, AttributeError):
            raise ValueError(
                f"intrinsics file {path}: a ROS camera_info or Kalibr camchain "
                f"without its camera fields"
            ) from None
        return None
    return None
