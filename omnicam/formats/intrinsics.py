"""A pinhole's intrinsics (``K``, ``D``, ``image_size``) in files, and the central models of
``cv2.omnidir`` and Kalibr read back.

Read as every omnicam file is (:mod:`.filestorage`: pre-scanned, validated, naming the file and
the field); other tools' layouts are recognised by :mod:`.other_tools`.
"""

from __future__ import annotations

import numpy as np

from .._typing import ArrayLike, FloatArray, PathLike, Size
from .._validate import (
    file_path,
    finite_array,
    real_number,
    shown,
    validate_D,
    validate_image_size,
    validate_K,
)
from .filestorage import atomic_filestorage, prescan, reading, same_values, write_int_seq
from .other_tools import not_pinhole, read_other_central, read_other_intrinsics

__all__ = ["D_FIELDS", "K_FIELDS", "read_central_model", "read_intrinsics", "write_intrinsics"]

# field names of an intrinsics file, first match wins: omnicam's, then OpenCV's calibration sample
K_FIELDS = ("K", "camera_matrix", "cameraMatrix")
D_FIELDS = ("D", "dist_coeffs", "distortion_coefficients", "distCoeffs")


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
    prescan(path, what)  # nothing that could crash a parser reaches one
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
    prescan(path, what)
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
            write_int_seq(fs, "image_size", image_size)

    def read_back(tmp):
        K2, D2, size2 = read_intrinsics(tmp)
        return (
            same_values(K2, K)
            and size2 == image_size
            and (same_values(D2, D) if D2 is not None or D is None or np.any(D) else True)
        )

    atomic_filestorage(path, "intrinsics file", write, read_back)
