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

A camera whose mirror is an :class:`~omnicam.asphere.AsphericMirror` is written in format 2,
the same layout with another model tag and the mirror as a map of its kind::

    format_version: 2
    model: misaligned_catadioptric
    mirror: {kind: even_asphere, R: 25., k: -1.5, alpha: [0.01, ...], rho_n: 30.,
             vertex_z: 0., rim_radius: 30.}   (alpha absent when it has no terms)

A reader that ignored the new fields would read another camera, so the version changes: an
omnicam that reads format 1 only refuses these files ("field 'format_version' is 2; this
omnicam reads 1"), and this one reads both. A hyperboloid is written in format 1 whichever
class holds it, so its files stay what they were, byte for byte.

The ``verdict`` map (``format_version`` 1 all the same: every field of it is optional and
readers ignore fields they do not know, so older omnicams read these files and files without it
read as before) records what the calibration's report said when the file was written: where
``K`` came from, the confidence of the posture's choice, ``--force``, the stated uncertainty,
the warnings, and for chessboard calibrations the RMS, the held-out check and the viewing
directions' uncertainty. Its flags are written as 0 and 1 (the pre-scan refuses YAML's
``true``). :func:`read_verdict` reads it.

Reading and writing are :mod:`.filestorage`'s: pre-scanned, parsed without letting OpenCV crash,
every field validated (a ``ValueError`` naming the file and the field), written atomically and
verified by reading the temporary file back.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from .._typing import PathLike
from ..asphere import AsphericMirror
from ..camera import MisalignedCatadioptricCamera
from ..mirror import HyperbolicMirror, Mirror
from .filestorage import atomic_filestorage, is_number, reading, same_values, write_int_seq
from .verdict import TEXTS, Verdict

__all__ = [
    "FORMAT_VERSION",
    "FORMAT_VERSION_ASPHERE",
    "MODEL_NAME",
    "MODEL_NAME_ASPHERE",
    "load_camera",
    "read_mirror",
    "read_verdict",
    "save_camera",
]

FORMAT_VERSION = 1  # a hyperboloid's file
MODEL_NAME = "misaligned_hyperbolic"  # the model tag of a calibration file
FORMAT_VERSION_ASPHERE = 2  # an even asphere's file
MODEL_NAME_ASPHERE = "misaligned_catadioptric"
ASPHERE_KIND = "even_asphere"  # mirror.kind of a format 2 file
_MODELS = {FORMAT_VERSION: MODEL_NAME, FORMAT_VERSION_ASPHERE: MODEL_NAME_ASPHERE}


def _read_mirror(r, version) -> Mirror:
    """The ``mirror`` map of a file of format ``version`` (1: a, b, rim_radius; 2: a kind)."""
    mnode = r.node("mirror")
    if version == FORMAT_VERSION:
        return _hyperboloid_of(r, mnode)
    if not isinstance(mnode, dict):
        raise r.fail("mirror", "must be a map with kind, R, k, rim_radius (and alpha, rho_n)")
    kind = r.node("mirror.kind", mnode)
    if kind != ASPHERE_KIND:
        raise r.fail("mirror.kind", f"must be {ASPHERE_KIND!r}, got {kind!r}")
    return _asphere_of(r, mnode)


def _hyperboloid_of(r, mnode) -> HyperbolicMirror:
    if not isinstance(mnode, dict):
        raise r.fail("mirror", "must be a map with a, b, rim_radius")
    ab = [r.number(f"mirror.{k}", mnode) for k in ("a", "b", "rim_radius")]
    return r.check("mirror", lambda v: HyperbolicMirror(*v), ab)


def _asphere_of(r, mnode) -> AsphericMirror:
    R, k, rim = (r.number(f"mirror.{n}", mnode) for n in ("R", "k", "rim_radius"))
    alpha = mnode.get("alpha")
    alpha = [alpha] if is_number(alpha) else alpha  # XML: one item, a scalar
    alpha = [] if alpha is None else alpha
    if not isinstance(alpha, list) or not all(map(is_number, alpha)):
        raise r.fail("mirror.alpha", "must be a sequence of numbers")
    rho_n = r.number("mirror.rho_n", mnode) if "rho_n" in mnode else None
    vertex_z = r.number("mirror.vertex_z", mnode) if "vertex_z" in mnode else 0.0
    return r.check(
        "mirror",
        lambda v: AsphericMirror(R, k, rim, tuple(map(float, v)), rho_n, vertex_z),
        alpha,
    )


def read_mirror(path: PathLike) -> Mirror:
    """The mirror alone, from a file's ``mirror`` map: a data sheet's mirror for the command
    line (``omnicam calibrate --mirror-file``), or a calibration file's.

    ``mirror: {kind: hyperboloid, a, b, rim_radius}`` (``kind`` may be left out, as format 1
    writes it) or ``mirror: {kind: even_asphere, R, k, alpha, rho_n, vertex_z, rim_radius}``
    (``alpha``, ``rho_n`` and ``vertex_z`` optional: none, the rim radius, 0), in a
    ``cv2.FileStorage`` file (``.yaml``, ``.yml``, ``.xml``, ``.json``); other fields are
    ignored.

    Raises
    ------
    FileNotFoundError
        No file at ``path``.
    ValueError
        A missing or malformed field, or a mirror the model refuses, naming the file and the
        field.
    """
    r = reading(path, "mirror file")
    mnode = r.node("mirror")
    if not isinstance(mnode, dict):
        raise r.fail("mirror", f"must be a map with kind {MIRROR_KINDS} and its parameters")
    kind = mnode.get("kind", "hyperboloid")
    if kind == "hyperboloid":
        return _hyperboloid_of(r, mnode)
    if kind == ASPHERE_KIND:
        return _asphere_of(r, mnode)
    raise r.fail("mirror.kind", f"must be one of {MIRROR_KINDS}, got {kind!r}")


MIRROR_KINDS = "hyperboloid, even_asphere"


def _write_mirror(fs, mirror: Mirror) -> None:
    """The ``format_version``, ``model`` and ``mirror`` of :func:`save_camera`: format 1 for a
    hyperboloid (the same bytes as before asphere files existed), 2 for an even asphere."""
    if isinstance(mirror, HyperbolicMirror):
        fs.write("format_version", FORMAT_VERSION)
        fs.write("model", MODEL_NAME)
        fs.startWriteStruct("mirror", cv2.FileNode_MAP)
        fs.write("a", mirror.a)
        fs.write("b", mirror.b)
        fs.write("rim_radius", mirror.rim_radius)
        fs.endWriteStruct()
        return
    fs.write("format_version", FORMAT_VERSION_ASPHERE)
    fs.write("model", MODEL_NAME_ASPHERE)
    fs.startWriteStruct("mirror", cv2.FileNode_MAP)
    fs.write("kind", ASPHERE_KIND)
    fs.write("R", mirror.R)
    fs.write("k", mirror.k)
    if mirror.alpha:
        fs.startWriteStruct("alpha", cv2.FileNode_SEQ)
        for a in mirror.alpha:
            fs.write("", float(a))
        fs.endWriteStruct()
    fs.write("rho_n", mirror.rho_n)
    fs.write("vertex_z", mirror.vertex_z)
    fs.write("rim_radius", mirror.rim_radius)
    fs.endWriteStruct()


def load_camera(path: PathLike) -> MisalignedCatadioptricCamera:
    """Read and validate a calibration file written by :func:`save_camera`.

    Reads format 1 (a hyperboloid) and format 2 (an even asphere, :class:`AsphericMirror`).
    The camera carries the file's verdict (``camera.verdict``, as :func:`read_verdict` reads
    it; None when the file has none, or one that cannot be read: :func:`read_verdict` says
    why). :meth:`omnicam.MisalignedHyperbolicCamera.load` is this, as the design's class, for a
    hyperboloid's file.

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
    try:  # the camera of every file alike: a verdict that cannot be read is left out
        verdict = _verdict_of(r)
    except ValueError:
        verdict = None
    version = r.number("format_version")
    if version not in _MODELS:
        raise r.fail(
            "format_version",
            f"is {version:g}; this omnicam reads {FORMAT_VERSION} and {FORMAT_VERSION_ASPHERE}",
        )
    model = r.node("model")
    if model != _MODELS[version]:
        raise r.fail("model", f"must be {_MODELS[version]!r} in format {version:g}")
    mirror = _read_mirror(r, version)
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
            verdict=verdict,
        )
    except ValueError as e:
        raise r.fail(str(e).split(" ", 1)[0].rstrip(":,"), str(e)) from None


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
        if field.name in TEXTS:
            value = [value] if isinstance(value, str) else value  # XML: one item, a scalar
            if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                raise r.fail(name, "must be a sequence of strings")
        elif field.name == "ray_std_deg":
            if not (isinstance(value, list) and len(value) == 2 and all(map(is_number, value))):
                raise r.fail(name, "must be a sequence of two numbers (median, worst)")
            value = tuple(value)
        elif field.name in ("method", "K_source", "K_file", "K_note"):
            if not isinstance(value, str):
                raise r.fail(name, "must be a string")
        elif not is_number(value) and not isinstance(value, bool):
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
        if field.name in TEXTS:
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


def save_camera(
    camera: MisalignedCatadioptricCamera, path: PathLike, verdict: object = None
) -> None:
    """Write ``camera`` to ``path`` atomically and verified, with its verdict.

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
        ``PatternReport`` is taken as :meth:`Verdict.from_report` of it. None (the default):
        the verdict the camera carries (``camera.verdict``, set by the calibration routes and
        by :func:`load_camera`), none if it carries none; ``camera.replace(verdict=None)``
        writes a file without one.

    Raises
    ------
    ValueError
        Unknown extension, a name that is not UTF-8, a ``verdict`` that is neither, or the file
        cannot be written (missing or read-only folder, full disk, a folder in the way, ...):
        the message names the file, the old file at ``path`` is unchanged and no temporary file
        is left.
    """
    if verdict is None:
        verdict = getattr(camera, "verdict", None)
    elif not isinstance(verdict, Verdict):
        verdict = Verdict.from_report(verdict)

    def write(fs):
        _write_mirror(fs, camera.mirror)
        fs.write("K", np.asarray(camera.K))
        if camera.D is not None:
            fs.write("D", np.asarray(camera.D).reshape(1, -1))
        fs.write("rvec", np.asarray(camera.rvec).reshape(3, 1))
        fs.write("tvec", np.asarray(camera.tvec).reshape(3, 1))
        if camera.image_size is not None:
            write_int_seq(fs, "image_size", camera.image_size)
        if camera.camera_reflection is not None:
            fs.startWriteStruct("camera_reflection", cv2.FileNode_MAP)
            fs.write("r", float(camera.camera_reflection[0]))
            fs.write("z", float(camera.camera_reflection[1]))
            fs.endWriteStruct()
        if verdict is not None:
            _write_verdict(fs, verdict)

    def read_back(tmp):
        return _same_camera(load_camera(tmp), camera) and read_verdict(tmp) == verdict

    atomic_filestorage(path, "calibration file", write, read_back)


def _same_camera(a, b):
    return (
        a.mirror == b.mirror
        and a.image_size == b.image_size
        and all(
            same_values(getattr(a, n), getattr(b, n))
            for n in ("K", "D", "rvec", "tvec", "camera_reflection")
        )
    )
