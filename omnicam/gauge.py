"""The gauge of the 5-DOF mirror posture (``docs/conventions.md``, "Gauge").

Rotation about the mirror axis is not observable. omnicam always represents a posture by the
smallest rotation taking the camera's +z axis to the mirror axis, so an aligned rig has
``rvec = 0`` and a panorama's azimuth 0 is stable from run to run. Also here: the one posture
error metric that tests, benchmarks and examples use.
"""

from __future__ import annotations

import math
from typing import Protocol

import cv2
import numpy as np
import numpy.typing as npt

# the aliases of omnicam._typing, which shares this module's layer (README, Layout)
ArrayLike = npt.ArrayLike
FloatArray = npt.NDArray[np.float64]

__all__ = [
    "canonical_rvec",
    "gauge_rotation",
    "posture_error",
    "rotate_vector",
    "perpendicular_basis",
]


def canonical_rvec(rvec: ArrayLike) -> FloatArray:
    """The gauge (docs/conventions.md): the smallest rotation taking +z to the mirror axis.

    Rotations about the mirror axis are unobservable (5 DOF); this picks the representative.
    """
    rvec = np.asarray(rvec, np.float64).reshape(3)
    if rvec[2] == 0.0 and np.linalg.norm(rvec) < math.pi:
        # already a rotation about an axis in the x-y plane: the representative itself (and
        # returned unchanged, so the gauge is idempotent to the last bit)
        return np.copy(rvec)
    R, _ = cv2.Rodrigues(rvec.reshape(3, 1))
    m = R[:, 2]
    axis: FloatArray = np.array([-m[1], m[0], 0.0])  # e_z x m
    s = float(np.linalg.norm(axis))
    angle = math.atan2(s, m[2])
    if s < 1e-300:
        return np.zeros(3) if m[2] > 0 else np.array([math.pi, 0.0, 0.0])
    return axis / s * angle


def gauge_rotation(axis: ArrayLike) -> FloatArray:
    """The smallest rotation taking ``e_z`` to the unit ``axis``: ``R`` of :func:`canonical_rvec`.

    Parameters
    ----------
    axis : (3,) array_like
        The mirror axis in the camera frame (any non-zero length).

    Returns
    -------
    (3, 3) float64 ndarray
    """
    a = np.asarray(axis, np.float64)
    a = a / np.linalg.norm(a)
    v = np.array([-a[1], a[0], 0.0])  # e_z x a
    s = float(np.linalg.norm(v))
    ang = math.atan2(s, a[2])
    if s < 1e-300:
        return np.eye(3) if a[2] > 0 else np.diag([1.0, -1.0, -1.0])
    return np.asarray(cv2.Rodrigues((v / s * ang).reshape(3, 1))[0], np.float64)


class _Posture(Protocol):
    """What :func:`posture_error` reads of a camera."""

    @property
    def R(self) -> ArrayLike: ...

    @property
    def camera_center(self) -> ArrayLike: ...


def posture_error(camera: _Posture, truth: _Posture) -> tuple[float, float]:
    """How far ``camera``'s mirror posture is from ``truth``'s: the one metric of omnicam.

    Parameters
    ----------
    camera, truth : MisalignedHyperbolicCamera (or anything with ``R`` and ``camera_center``)

    Returns
    -------
    axis_deg : float
        Angle between the two mirror axes ``R e_z`` (camera frame), degrees.
    origin : float
        Distance between the two camera centres in the mirror frame (``-R^T tvec``, eq. 17),
        in the mirror's length unit: where the camera sits relative to the mirror.
    """
    m1 = np.asarray(camera.R, np.float64)[:, 2]
    m2 = np.asarray(truth.R, np.float64)[:, 2]
    axis = math.degrees(math.atan2(float(np.linalg.norm(np.cross(m1, m2))), float(m1 @ m2)))
    origin = float(
        np.linalg.norm(
            np.asarray(camera.camera_center, np.float64)
            - np.asarray(truth.camera_center, np.float64)
        )
    )
    return axis, origin


def rotate_vector(v: FloatArray, w: FloatArray) -> FloatArray:
    """``v`` rotated by the rotation vector ``w`` (Rodrigues' formula), without a matrix.

    Parameters
    ----------
    v, w : (3,) ndarray

    Returns
    -------
    (3,) ndarray
    """
    th = float(np.linalg.norm(w))
    if th == 0.0:
        return np.copy(v)
    k = w / th
    return v * math.cos(th) + np.cross(k, v) * math.sin(th) + k * (k @ v) * (1 - math.cos(th))


def perpendicular_basis(v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Two unit vectors perpendicular to ``v`` and to each other, ``(b1, b2)`` with
    ``(v / |v|, b1, b2)`` right-handed: the axes of the two small rotations of a direction.

    Parameters
    ----------
    v : (3,) ndarray

    Returns
    -------
    b1, b2 : (3,) ndarray
    """
    v = v / np.linalg.norm(v)
    h = np.array([1.0, 0.0, 0.0]) if abs(v[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    b1 = np.cross(v, h)
    b1 /= np.linalg.norm(b1)
    return b1, np.cross(v, b1)
