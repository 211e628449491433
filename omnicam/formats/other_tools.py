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
every chain of two cameras or with an IMU), so :func:`parse_yaml` reads them with PyYAML's safe
loader (the files are pre-scanned for size first, :data:`MAX_BYTES`).
"""

from __future__ import annotations

import math
import os
import re

import numpy as np
import yaml

__all__ = [
    "MAX_BYTES",
    "MAX_NESTING",
    "OCAMCALIB_HEADER",
    "not_pinhole",
    "other_tool_file",
    "parse_yaml",
    "read_other_central",
    "read_other_intrinsics",
]

#: Intrinsics files are small; anything larger is not one of these formats.
MAX_BYTES = 1 << 20
#: Deepest nesting :func:`parse_yaml` reads (maps and lists).
MAX_NESTING = 64
#: The first line of OCamCalib's ``calib_results.txt``, as its toolbox writes it.
OCAMCALIB_HEADER = "#polynomial coefficients for the DIRECT mapping function"


# -- the YAML of ROS and Kalibr -------------------------------------------------------------------
class _Loader(yaml.SafeLoader):
    """PyYAML's safe loader, with two differences for these files: a tag it does not know
    (``!!opencv-matrix``) reads as the plain map, list or scalar it tags, and a number written
    without a dot (``1e-05``, as C++ writers give it) is a float, as in YAML 1.2."""


def _untagged(loader, suffix, node):
    if isinstance(node, yaml.MappingNode):
        return loader.construct_mapping(node, deep=True)
    if isinstance(node, yaml.SequenceNode):
        return loader.construct_sequence(node, deep=True)
    return loader.construct_scalar(node)


_Loader.add_multi_constructor("", _untagged)
_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."),
)


def _depth(node) -> int:
    """How deeply ``node`` nests (a scalar: 0), walked without recursion; ``ValueError`` for a
    node met twice (an alias: ROS and Kalibr write none, and a few nested aliases would make
    this walk, and any reader that copies them, exponentially long)."""
    deepest, stack, seen = 0, [(node, 0)], set()
    while stack:
        n, d = stack.pop()
        if id(n) in seen:
            raise ValueError("anchors and aliases (&name, *name) are not read")
        seen.add(id(n))
        deepest = max(deepest, d)
        if isinstance(n, yaml.SequenceNode):
            stack.extend((c, d + 1) for c in n.value)
        elif isinstance(n, yaml.MappingNode):
            stack.extend((v, d + 1) for _, v in n.value)
    return deepest


def parse_yaml(text):
    """The document of YAML ``text`` as Python values (PyYAML's safe loader, :class:`_Loader`).

    Raises
    ------
    ValueError
        Text that is not YAML (naming the line and column), or nested deeper than
        :data:`MAX_NESTING`.
    """
    try:
        node = yaml.compose(text, Loader=_Loader)
    except yaml.MarkedYAMLError as e:
        mark = e.problem_mark or e.context_mark
        where = "" if mark is None else f" at line {mark.line + 1}, column {mark.column + 1}"
        raise ValueError(f"{e.problem or e.context}{where}") from None
    except yaml.YAMLError as e:
        raise ValueError(str(e).splitlines()[0]) from None
    except RecursionError:
        raise ValueError(f"nested too deeply (more than {MAX_NESTING} levels)") from None
    if node is None:
        return {}
    if _depth(node) > MAX_NESTING:
        raise ValueError(f"nested too deeply (more than {MAX_NESTING} levels)")
    return _Loader(text).construct_document(node)


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
    :mod:`.filestorage`'s pre-scan. ``image_size`` written as an OpenCV matrix is read by
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


# -- recognised where omnicam's own calibration file is expected ---------------------------------
_OMNIDIR_XI = re.compile(r'^\s*(?:"xi"\s*:|xi\s*:|<xi>)', re.MULTILINE)


def other_tool_file(path) -> tuple[str, str] | None:
    """``(what the file is, how omnicam takes it)`` when ``path`` is another tool's camera file
    (a Kalibr camchain, a ROS ``camera_info``, an OCamCalib ``calib_results.txt``, a
    ``cv2.omnidir`` calibration), else ``None``: what to say when such a file is given where
    omnicam's own calibration file is expected. The second part names the command-line option
    that reads it, or says that none does and what to do instead.
    """
    text = _text(os.fspath(path))
    if text is None:
        return None
    central = (
        "a central model of the whole catadioptric camera, which no option of omnicam reads "
        "(omnicam's model is not central); calibrate the rig with omnicam calibrate (one image "
        "of the mirror with the lens's K, or --chessboard, which needs no K)"
    )
    if text.lstrip().startswith(OCAMCALIB_HEADER):
        return "an OCamCalib calib_results.txt", central
    if "!!opencv-matrix" in text or text.lstrip().startswith(("%YAML", "<?xml", "{")):
        if _OMNIDIR_XI.search(text):
            return "a cv2.omnidir calibration (it has an xi)", central
        return None
    try:
        doc = parse_yaml(text)
    except ValueError:
        return None
    if not isinstance(doc, dict):
        return None
    pinhole = (
        "it holds the lens's K and D: give it to --intrinsics of omnicam calibrate, which "
        "calibrates the mirror's posture (omnicam's calibration file) from one image with it"
    )
    if "camera_matrix" in doc and ("distortion_model" in doc or "image_width" in doc):
        return "a ROS camera_info", pinhole
    cam = doc.get("cam0") if isinstance(doc.get("cam0"), dict) else doc
    model = cam.get("camera_model") if isinstance(cam, dict) else None
    if model is None:
        return None
    if model == "pinhole":
        return "a Kalibr camchain (a pinhole camera)", pinhole
    return f"a Kalibr camchain (camera_model {model})", central
