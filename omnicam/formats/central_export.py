"""Files for the tools that only know central models: cv2.omnidir, Kalibr, camodocal, OCamCalib.

Each file holds the central model of :mod:`.central_fit` that best matches the exact rig, and
says what it costs (RMS and maximum pixel error) in a comment.

**When the cost is large.** :func:`export` warns (``RuntimeWarning``) when the file it writes is
off by more than :data:`WARN_RMS_PX` (0.5 px) RMS or :data:`WARN_MAX_PX` (1 px) at its worst
pixel: more than a pixel somewhere in the image, an error a user sees. The warning names the
central format that fits this camera best (each format's fit measured the same way) and the
exports that are exact, the remap tables of :mod:`omnicam.formats.maps` (``omnicam maps``), which
use the exact non-central model. OCamCalib's model has no tangential term, so it costs more
than the unified one on a tilted rig (about 0.9 px RMS against 0.03 px at 3 degrees and 3 mm).
"""

from __future__ import annotations

import math
import warnings

import cv2
import numpy as np

from .._atomic import OutputError, atomic_output, write_bytes
from .central_fit import OcamFit, OmnidirFit, fit_ocamcalib, fit_omnidir

__all__ = [
    "FORMATS",
    "WARN_MAX_PX",
    "WARN_RMS_PX",
    "camodocal_text",
    "export",
    "kalibr_text",
    "ocamcalib_text",
    "write_camodocal",
    "write_kalibr",
    "write_ocamcalib",
    "write_omnidir",
]

FORMATS = ("omnidir", "kalibr", "camodocal", "ocamcalib")
#: :func:`export` warns when its file's RMS error exceeds this (px) ...
WARN_RMS_PX = 0.5
#: ... or its largest error exceeds this (px).
WARN_MAX_PX = 1.0


# -- writers -------------------------------------------------------------------------------------
def _fmt(x):
    """``x`` as a YAML float that reads back exactly: Python's shortest round-trip ``repr``,
    always with a point before any exponent (``500.0``, ``1.5e-05`` -> ``1.5e-05``, ``1e-05`` ->
    ``1.0e-05``), since a YAML 1.1 reader (PyYAML, Kalibr's) takes ``500`` for an integer and
    ``1e-05`` for a string, and Kalibr's ConfigReader refuses anything but floats."""
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"cannot write the non-finite value {x!r}")
    text = repr(x)
    mantissa, e, exponent = text.partition("e")
    if "." not in mantissa:
        mantissa += ".0"
    return mantissa + e + exponent


def _error_comment(fit, prefix="# "):
    return (
        f"{prefix}central approximation of a non-central omnicam rig, {fit.summary()}\n"
        f"{prefix}frame: X_cam = M (X_mirror - origin), M = "
        f"{np.round(fit.M, 12).tolist()}, origin = {np.round(fit.origin, 9).tolist()} "
        f"(det M = {np.linalg.det(fit.M):+.0f})\n"
    )


def write_omnidir(path, fit, image_size=None, overwrite=True) -> None:
    """``cv2.FileStorage`` file (yaml, yml, xml or json) with ``K``, ``xi``, ``D``, ``M``,
    ``origin``, ``rms_px``, ``max_px``, ``image_size``: what ``cv2.omnidir.*`` takes."""

    def verify(tmp):
        fs = cv2.FileStorage(tmp, cv2.FILE_STORAGE_READ)
        try:
            return (
                np.allclose(fs.getNode("K").mat(), fit.K)
                and abs(fs.getNode("xi").real() - fit.xi) < 1e-12
            )
        finally:
            fs.release()

    with atomic_output(path, what="omnidir file", overwrite=overwrite, verify=verify) as tmp:
        fs = cv2.FileStorage(tmp, cv2.FILE_STORAGE_WRITE)
        if not fs.isOpened():
            raise OutputError(
                f"cannot write omnidir file {path}: unknown extension "
                f"(use .yaml, .yml, .xml or .json)"
            )
        fs.write("model", "omnidir_mei")
        fs.writeComment(
            "X_omni = M (X_mirror - origin); cv2.omnidir.projectPoints(X_omni, 0, 0, K, xi, D)"
        )
        fs.write("K", fit.K)
        fs.write("xi", float(fit.xi))
        fs.write("D", np.asarray(fit.D, dtype=np.float64).reshape(1, 4))
        fs.write("M", fit.M)
        fs.write("origin", np.asarray(fit.origin).reshape(3, 1))
        fs.write("rms_px", float(fit.rms_px))
        fs.write("max_px", float(fit.max_px) if math.isfinite(fit.max_px) else -1.0)
        fs.write("depth", -1.0 if fit.depth is None else float(fit.depth))
        if image_size is not None:
            fs.write("image_size", np.array(image_size, dtype=np.int32).reshape(1, 2))
        fs.release()


def kalibr_text(fit, image_size, rostopic="/cam0/image_raw") -> str:
    """Kalibr camchain YAML (``camera_model: omni``, ``distortion_model: radtan``)."""
    if abs(fit.K[0, 1]) > 1e-9:
        raise ValueError("fit: Kalibr's omni model has no skew; fit with skew=False")
    K, D = fit.K, np.ravel(fit.D)
    w, h = image_size
    return (
        "# Kalibr camchain written by omnicam\n" + _error_comment(fit) + "cam0:\n"
        "  camera_model: omni\n"
        f"  intrinsics: [{_fmt(fit.xi)}, {_fmt(K[0, 0])}, {_fmt(K[1, 1])}, {_fmt(K[0, 2])}, "
        f"{_fmt(K[1, 2])}]\n"
        "  distortion_model: radtan\n"
        f"  distortion_coeffs: [{', '.join(_fmt(v) for v in D)}]\n"
        f"  resolution: [{int(w)}, {int(h)}]\n"
        f"  rostopic: {rostopic}\n"
        "  cam_overlaps: []\n"
    )


def camodocal_text(fit, image_size, camera_name="omnicam") -> str:
    """Camodocal's ``MEI`` camera YAML (OpenCV FileStorage syntax, as camodocal reads it)."""
    if abs(fit.K[0, 1]) > 1e-9:
        raise ValueError("fit: camodocal's MEI model has no skew; fit with skew=False")
    K, D = fit.K, np.ravel(fit.D)
    w, h = image_size
    return (
        "%YAML:1.0\n---\n" + _error_comment(fit) + "model_type: MEI\n"
        f"camera_name: {camera_name}\n"
        f"image_width: {int(w)}\n"
        f"image_height: {int(h)}\n"
        "mirror_parameters:\n"
        f"   xi: {_fmt(fit.xi)}\n"
        "distortion_parameters:\n"
        f"   k1: {_fmt(D[0])}\n   k2: {_fmt(D[1])}\n   p1: {_fmt(D[2])}\n"
        f"   p2: {_fmt(D[3])}\n"
        "projection_parameters:\n"
        f"   gamma1: {_fmt(K[0, 0])}\n   gamma2: {_fmt(K[1, 1])}\n"
        f"   u0: {_fmt(K[0, 2])}\n   v0: {_fmt(K[1, 2])}\n"
    )


def ocamcalib_text(fit, image_size) -> str:
    """OCamCalib's ``calib_results.txt`` (read by ``get_ocam_model`` of ``ocam_functions.cpp``).

    Its comment lines are the ones OCamCalib writes (the reader skips them by position); the
    error figures are appended after the last field, where the reader stops.
    """
    w, h = image_size
    pol = " ".join(f"{v:.12e}" for v in fit.pol)
    inv = " ".join(f"{v:.12e}" for v in fit.invpol)
    return (
        "#polynomial coefficients for the DIRECT mapping function (ocam_model.ss in MATLAB). "
        "These are used by cam2world\n\n"
        f"{len(fit.pol)} {pol} \n\n"
        "#polynomial coefficients for the inverse mapping function (ocam_model.invpol in "
        "MATLAB). These are used by world2cam\n\n"
        f"{len(fit.invpol)} {inv} \n\n"
        '#center: "row" and "column", starting from 0 (C convention)\n\n'
        f"{fit.xc:.6f} {fit.yc:.6f}\n\n"
        '#affine parameters "c", "d", "e"\n\n'
        f"{fit.c:.6f} {fit.d:.6f} {fit.e:.6f}\n\n"
        '#image size: "height" and "width"\n\n'
        f"{int(h)} {int(w)}\n\n"
        "#written by omnicam: central approximation of a non-central rig (scene at infinity)"
        f"\n#{fit.summary()}\n"
        f"#frame: X_ocam = M X_mirror, M = {np.round(fit.M, 12).tolist()}\n"
    )


def _camodocal_verify(fit):
    def verify(tmp):
        fs = cv2.FileStorage(tmp, cv2.FILE_STORAGE_READ)
        try:
            return abs(fs.getNode("mirror_parameters").getNode("xi").real() - fit.xi) < 1e-9
        finally:
            fs.release()

    return verify


def _image_size(camera, image_size):
    size = image_size if image_size is not None else camera.image_size
    if size is None:
        raise ValueError("image_size: the camera has none; give (width, height)")
    return tuple(int(v) for v in size)


def write_kalibr(path, camera, fit=None, image_size=None, overwrite=True) -> OmnidirFit:
    """Kalibr camchain of the best skew-free unified model; returns the fit."""
    fit = fit or fit_omnidir(camera, skew=False)
    write_bytes(
        path,
        kalibr_text(fit, _image_size(camera, image_size)),
        what="Kalibr camchain",
        overwrite=overwrite,
    )
    return fit


def write_camodocal(path, camera, fit=None, image_size=None, overwrite=True) -> OmnidirFit:
    """Camodocal MEI yaml of the best skew-free unified model; returns the fit."""
    fit = fit or fit_omnidir(camera, skew=False)
    write_bytes(
        path,
        camodocal_text(fit, _image_size(camera, image_size)),
        what="camodocal file",
        overwrite=overwrite,
        verify=_camodocal_verify(fit),
    )
    return fit


def write_ocamcalib(path, camera, fit=None, image_size=None, overwrite=True) -> OcamFit:
    """OCamCalib ``calib_results.txt``; returns the :class:`OcamFit`."""
    fit = fit or fit_ocamcalib(camera)
    write_bytes(
        path,
        ocamcalib_text(fit, _image_size(camera, image_size)),
        what="OCamCalib file",
        overwrite=overwrite,
    )
    return fit


def _cost(fit):
    """``(rms_px, max_px)`` of a fit: for OCamCalib the worse of its two mappings."""
    if isinstance(fit, OcamFit):
        return (
            max(fit.world2cam_rms_px, fit.cam2world_rms_px),
            max(fit.world2cam_max_px, fit.cam2world_max_px),
        )
    return fit.rms_px, fit.max_px


_NAMES = {
    "omnidir": "omnidir (cv2.omnidir, with skew)",
    "kalibr": "kalibr or camodocal (the unified model without skew)",
    "ocamcalib": "ocamcalib (Scaramuzza's polynomial)",
}


def _cost_warning(camera, fmt, depth, fits):
    """The warning text when ``fmt``'s fit costs more than the thresholds, else ``None``.

    ``fits`` holds the fits already made, by model (``"omnidir"``, ``"kalibr"`` for the
    skew-free unified model of Kalibr and camodocal, ``"ocamcalib"``); the other models are
    fitted here, only when a warning is due, so that it names the best by the same measure."""
    model = "kalibr" if fmt == "camodocal" else fmt
    rms, mx = _cost(fits[model])
    if rms <= WARN_RMS_PX and mx <= WARN_MAX_PX:
        return None
    if "omnidir" not in fits:
        fits["omnidir"] = fit_omnidir(camera, depth=depth)
    if "kalibr" not in fits:
        fits["kalibr"] = fit_omnidir(camera, depth=depth, skew=False)
    if depth is None and "ocamcalib" not in fits:
        fits["ocamcalib"] = fit_ocamcalib(camera, omnidir=fits["kalibr"])
    costs = {name: _cost(fit) for name, fit in fits.items()}
    best = min(costs, key=lambda name: costs[name])
    b_rms, b_max = costs[best]
    if best == model:
        advice = "no central format fits this rig better"
    else:
        advice = (
            f"the central format that fits this camera best is {_NAMES[best]}: RMS "
            f"{b_rms:.3g} px, max {b_max:.3g} px"
        )
    return (
        f"the {fmt} export is off by RMS {rms:.3g} px, max {mx:.3g} px (omnicam warns above "
        f"{WARN_RMS_PX:g} px RMS or {WARN_MAX_PX:g} px max): this rig is not central enough "
        f"for that model; {advice}; exact: the remap tables (omnicam maps --npy, --filestorage "
        f"or --ffmpeg; omnicam.formats.maps), which use the non-central model itself"
    )


def export(camera, fmt, path, depth=None, overwrite=True) -> OmnidirFit | OcamFit:
    """Write ``camera``'s central approximation in format ``fmt`` (one of :data:`FORMATS`);
    returns the fit (:class:`OmnidirFit` or :class:`OcamFit`).

    Warns
    -----
    RuntimeWarning
        When the file's error exceeds :data:`WARN_RMS_PX` RMS or :data:`WARN_MAX_PX` at its
        worst pixel; the message gives it, names the central format that fits this camera
        best, and the exact exports (module notes). The file is written all the same.
    """
    if fmt not in FORMATS:
        raise ValueError(f"fmt must be one of {FORMATS}, got {fmt!r}")
    if depth is not None and fmt == "ocamcalib":
        raise ValueError("depth: the OCamCalib export is for a scene at infinity only")
    fit: OmnidirFit | OcamFit
    fits: dict[str, OmnidirFit | OcamFit]
    if fmt == "omnidir":
        fit = fit_omnidir(camera, depth=depth)
        write_omnidir(path, fit, camera.image_size, overwrite=overwrite)
        fits = {"omnidir": fit}
    else:
        unified = fit_omnidir(camera, depth=depth, skew=False)
        fits = {"kalibr": unified}
        if fmt == "kalibr":
            fit = write_kalibr(path, camera, unified, overwrite=overwrite)
        elif fmt == "camodocal":
            fit = write_camodocal(path, camera, unified, overwrite=overwrite)
        else:
            fit = fits["ocamcalib"] = write_ocamcalib(
                path, camera, fit_ocamcalib(camera, omnidir=unified), overwrite=overwrite
            )
    message = _cost_warning(camera, fmt, depth, fits)
    if message is not None:
        warnings.warn(message, RuntimeWarning, stacklevel=2)
    return fit
