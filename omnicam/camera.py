"""The misaligned catadioptric camera: the model alone, a thin, validated, immutable value object.

This module sits at the bottom of the house: ray tracing, the mirror, the gauge and validation
are under it; the views, the calibration routes and the file formats import it and return it.
Its entry points for users (``calibrate``, ``load``, ``save``, ...) are on the design's class,
:class:`omnicam.MisalignedHyperbolicCamera` (:mod:`omnicam.hyperbolic_camera`), as thin calls of
the module-level functions ``omnicam.calibrate``, ``omnicam.calibrate_pattern``, ...

Model contract (the binding text is ``docs/conventions.md``):

* **Parameters**: pinhole ``K`` (3x3, skew allowed) and optional OpenCV distortion ``D``; a
  :class:`~omnicam.mirror.HyperbolicMirror` ``(a, b, rim_radius)``; the mirror posture
  ``rvec, tvec`` with ``X_cam = R(rvec) X_mirror + tvec`` (5 DOF: the rotation about the mirror
  axis is fixed by the gauge below); ``image_size = (width, height)`` as metadata.
* **Gauge**: ``rvec`` is always the smallest rotation taking the camera's +z axis to the mirror
  axis, so an aligned rig (``rvec = 0``, ``tvec = (0, 0, c)``) keeps ``rvec = 0``.
* **The camera's own reflection** (optional): ``camera_reflection``, the circle coaxial with the
  optical axis (radius ``r`` at axial distance ``z``, camera frame) whose reflection a
  calibration detected; default panoramas start above it.
* **The verdict** (optional): ``verdict``, how far to trust the calibration that made the camera
  (:class:`omnicam.Verdict`): set by the calibration routes, saved and loaded with the file;
  carried by ``replace`` and ``scaled``, not part of equality (the same rig is the same rig,
  however far one trusts it).
* **Methods**: ``unproject`` (pixel -> reflected ray, eqs. 6-19), ``project`` (scene point ->
  pixel, the exact non-central inverse), ``project_directions`` (points at infinity).
* **Pixels**: centres at integer coordinates; no clipping to ``image_size``.
* **Failure**: a pixel that does not see the mirror, a point the rig cannot see and NaN input all
  give NaN rows, never an exception.
* **Shapes**: ``(N, 2)``/``(N, 1, 2)`` pixels and ``(N, 3)``/``(N, 1, 3)`` points, float32 or
  float64; results are float64 in the matching layout.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, NamedTuple

import cv2
import numpy as np

from . import raytrace
from ._typing import ArrayLike, FloatArray, Size
from ._validate import (
    finite_array,
    float_array,
    validate_D,
    validate_image_size,
    validate_K,
    validate_posture,
)
from .asphere import AsphericMirror
from .gauge import canonical_rvec
from .mirror import HyperbolicMirror, Mirror

__all__ = [
    "MisalignedCatadioptricCamera",
    "CameraReflection",
    "canonical_rvec",
    "scale_K",
    "validate_D",
    "validate_K",
    "validate_image_size",
]  # the last five re-exported for callers


def scale_K(K: ArrayLike, from_size: Size, to_size: Size) -> FloatArray:
    """``K`` of the same sensor imaged at another resolution.

    Pixel centres sit at integer coordinates, so ``x' = sx (x + 0.5) - 0.5`` with
    ``sx = w'/w`` (and likewise in y): ``K' = S K``.
    """
    sx = to_size[0] / from_size[0]
    sy = to_size[1] / from_size[1]
    S = np.array([[sx, 0.0, 0.5 * (sx - 1.0)], [0.0, sy, 0.5 * (sy - 1.0)], [0.0, 0.0, 1.0]])
    return S @ float_array(K, "K", "a 3x3 camera matrix")


class CameraReflection(NamedTuple):
    """The circle of the camera's body whose reflection outlines the camera in the image.

    docs/conventions.md, "The camera's own reflection": the camera and its lens are bodies of
    revolution about the optical axis, and the outline of their reflection is that of one
    circle of radius ``r`` at the axial distance ``z`` from the camera centre along the
    camera's +z axis (towards the mirror), both in the mirror's length unit. A calibration
    from one image fits it to the outline it detects
    (:func:`omnicam.calibration.reflection.fit_circle`); only ``r / (2 c - z)`` is well
    determined for a nearly central rig, which is all its outline depends on.
    """

    r: float
    z: float


def _camera_reflection(value: Any) -> CameraReflection | None:
    """``value`` as a :class:`CameraReflection` (None stays None); ValueError naming it."""
    if value is None:
        return None
    try:
        r, z = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(
            f"camera_reflection must be None or (r, z), the circle's radius and axial "
            f"distance, got {value!r}"
        ) from None
    if not (math.isfinite(r) and math.isfinite(z) and r > 0):
        raise ValueError(
            f"camera_reflection must be (r, z) with r > 0 and both finite, got ({r!r}, {z!r})"
        )
    return CameraReflection(r, z)


def _readonly(arr: ArrayLike) -> FloatArray:
    arr = np.array(arr, dtype=np.float64)
    arr.flags.writeable = False
    return arr


class MisalignedCatadioptricCamera:
    """A perspective camera looking at a mirror of revolution in any 5-DOF posture.

    Functional model (paper section 2.2): a pixel ``x`` gives the camera ray
    ``V_C = K^-1 x~`` (eq. 6, after undoing ``D``), in the mirror frame ``V_M = R^T V_C`` from
    ``F_M = -R^T tvec`` (eqs. 16-17); it meets the mirror at ``P_M`` (eqs. 8-12) and leaves as
    ``V_Mout = V_M - 2 n (n, V_M)`` (eqs. 14-15). The rig has no single viewpoint.

    Parameters
    ----------
    K : (3, 3) array_like
        Camera matrix, skew allowed, last row ``(0, 0, 1)``.
    mirror : HyperbolicMirror or AsphericMirror
        The hyperboloid of eq. 1, or any convex mirror of revolution as an even asphere
        (:class:`~omnicam.AsphericMirror`); the kernels reach either through one seam
        (:mod:`omnicam._kernels.mirror`).
    rvec, tvec : (3,) array_like
        Mirror posture in the camera frame, as ``cv2.solvePnP`` returns it with the mirror as
        the object. ``rvec`` is stored in the gauge of docs/conventions.md (see
        :func:`canonical_rvec`).
    D : array_like or None
        OpenCV distortion coefficients (4, 5, 8, 12 or 14 values).
    image_size : (int, int) or None
        ``(width, height)`` of the images, metadata only (needed by :meth:`scaled`).
    camera_reflection : (float, float) or None
        ``(r, z)`` of the circle whose reflection outlines the camera in the image
        (:class:`CameraReflection`), as a calibration detected it; None when unknown. Default
        panoramas start just above its reflection (:func:`omnicam.views.default_elevation_range`).
    verdict : Verdict or None
        How far to trust the calibration that made this camera (:class:`omnicam.Verdict`, what
        its report said): the calibration routes set it, :func:`omnicam.save_camera` records
        it, :func:`omnicam.load_camera` gives it back; None when unknown (a camera built by
        hand, a file without one). Carried by :meth:`replace` and :meth:`scaled` (the same
        calibration); not part of ``==`` nor of ``repr``: two cameras that map every pixel alike
        are equal, whatever their verdicts.

    Raises
    ------
    ValueError
        Naming the parameter, for anything that is not a physical rig of sane magnitudes
        (:mod:`omnicam._validate`): non-real or non-finite values; ``fx, fy`` outside
        [1e-2, 1e7] px; an image size above 100000 px per side or 2**31 pixels; a rotation
        that is not finite; the camera centre not below the mirror sheet or a rim point not in
        front of the camera; a rim image wider than 20000 px.
    """

    __slots__ = (
        "_K",
        "_D",
        "_mirror",
        "_rvec",
        "_tvec",
        "_R",
        "_C",
        "_image_size",
        "_viewpoint",
        "_camera_reflection",
        "_verdict",
    )

    def __init__(
        self,
        K: ArrayLike,
        mirror: Mirror,
        rvec: ArrayLike,
        tvec: ArrayLike,
        D: ArrayLike | None = None,
        image_size: Size | None = None,
        camera_reflection: tuple[float, float] | None = None,
        verdict: Any = None,
    ) -> None:
        if not isinstance(mirror, HyperbolicMirror | AsphericMirror):
            raise ValueError(
                f"mirror must be a HyperbolicMirror or an AsphericMirror, got "
                f"{type(mirror).__name__}"
            )
        # an omnicam.Verdict (formats/, a layer above the model: known by what it does)
        if verdict is not None and not callable(getattr(verdict, "doubts", None)):
            raise ValueError(
                f"verdict must be an omnicam.Verdict or None, got {type(verdict).__name__} "
                f"(a report's is report.verdict())"
            )
        self._verdict = verdict
        self._K = _readonly(validate_K(K))
        D = validate_D(D)
        self._D = None if D is None else _readonly(D)
        self._mirror = mirror
        rvec = finite_array(rvec, "rvec", (3,), "a rotation vector of 3 numbers")
        tvec = finite_array(tvec, "tvec", (3,), "a translation vector of 3 numbers")
        with np.errstate(all="ignore"):  # a huge rvec gives NaN, refused just below
            rvec = canonical_rvec(rvec)
            R = cv2.Rodrigues(rvec.reshape(3, 1))[0]
        if not np.isfinite(rvec).all():
            raise ValueError("rvec must give a finite rotation, got a non-finite gauge")
        self._rvec = _readonly(rvec)
        self._tvec = _readonly(tvec)
        self._R = _readonly(R)
        self._C = _readonly(-self._R.T @ self._tvec)  # F_M of eq. 17
        self._image_size = validate_image_size(image_size)
        self._camera_reflection = _camera_reflection(camera_reflection)
        self._viewpoint: tuple[FloatArray, float] | None = None
        # a physical rig: camera below the mirror sheet, rim in front, rim image enumerable
        validate_posture(self._R, self._tvec, mirror, lambda: self.rim_image_points(36))

    # -- constructors -------------------------------------------------------------------
    @classmethod
    def aligned(
        cls,
        mirror: HyperbolicMirror,
        f_C: float,
        x_c: float,
        y_c: float,
        image_size: Size | None = None,
    ) -> MisalignedCatadioptricCamera:
        """The paper's aligned HyperOmni rig (eqs. 2-5), the "uncalibrated" baseline.

        Camera at the lower focus with axes parallel to the mirror's: ``rvec = 0``,
        ``tvec = (0, 0, c)``, ``K = [[f_C, 0, x_c], [0, f_C, y_c], [0, 0, 1]]``.
        """
        K = np.array([[f_C, 0.0, x_c], [0.0, f_C, y_c], [0.0, 0.0, 1.0]], dtype=np.float64)
        return cls(K, mirror, np.zeros(3), np.array([0.0, 0.0, mirror.c]), image_size=image_size)

    def scaled(self, image_size: Size) -> MisalignedCatadioptricCamera:
        """The same rig imaged at another resolution of the same sensor.

        ``K`` is scaled by ``sx = w'/w``, ``sy = h'/h`` about pixel centres at integer
        coordinates: ``x' = sx (x + 0.5) - 0.5``. Needs ``image_size`` on this camera.
        """
        if self._image_size is None:
            raise ValueError("scaled() needs the camera's image_size; construct it with image_size")
        new = validate_image_size(image_size)
        if new is None:
            raise ValueError("image_size must be (width, height)")
        return type(self)(
            scale_K(self._K, self._image_size, new),
            self._mirror,
            self._rvec,
            self._tvec,
            self._D,
            new,
            self._camera_reflection,  # a circle of the body: the same at any resolution
            self._verdict,  # the same calibration
        )

    def replace(self, **changes: Any) -> MisalignedCatadioptricCamera:
        """A copy with some of ``K, mirror, rvec, tvec, D, image_size, camera_reflection,
        verdict`` changed (the verdict is kept unless given: ``replace(verdict=None)`` drops
        it)."""
        args: dict[str, Any] = dict(
            K=self._K,
            mirror=self._mirror,
            rvec=self._rvec,
            tvec=self._tvec,
            D=self._D,
            image_size=self._image_size,
            camera_reflection=self._camera_reflection,
            verdict=self._verdict,
        )
        unknown = set(changes) - set(args)
        if unknown:
            raise ValueError(f"unknown parameter(s) {sorted(unknown)}")
        args.update(changes)
        return type(self)(**args)

    # -- properties ---------------------------------------------------------------------
    @property
    def K(self) -> FloatArray:
        """(3, 3) camera matrix."""
        return self._K

    @property
    def D(self) -> FloatArray | None:
        """Distortion coefficients, or None."""
        return self._D

    @property
    def mirror(self) -> Mirror:
        """The mirror: a HyperbolicMirror or an AsphericMirror."""
        return self._mirror

    @property
    def rvec(self) -> FloatArray:
        """(3,) mirror rotation (mirror -> camera), gauge-fixed."""
        return self._rvec

    @property
    def tvec(self) -> FloatArray:
        """(3,) mirror origin in the camera frame."""
        return self._tvec

    @property
    def R(self) -> FloatArray:
        """(3, 3) ``cv2.Rodrigues(rvec)``: R of eq. 29."""
        return self._R

    @property
    def image_size(self) -> Size | None:
        """(width, height) or None."""
        return self._image_size

    @property
    def camera_center(self) -> FloatArray:
        """(3,) camera centre in the mirror frame, ``-R^T tvec`` (``F_M`` of eq. 17)."""
        return self._C

    @property
    def camera_reflection(self) -> CameraReflection | None:
        """``(r, z)`` of the circle whose reflection outlines the camera (camera frame, the
        mirror's length unit; :class:`CameraReflection`), as detected when calibrated; None
        when unknown."""
        return self._camera_reflection

    @property
    def verdict(self) -> Any:
        """How far to trust the calibration that made this camera (:class:`omnicam.Verdict`),
        or None when unknown; not part of ``==``."""
        return self._verdict

    def __repr__(self) -> str:
        body = self._camera_reflection
        extra = "" if body is None else f", camera_reflection=({body.r!r}, {body.z!r})"
        return (
            f"MisalignedCatadioptricCamera(K={self._K.tolist()}, mirror={self._mirror!r}, "
            f"rvec={self._rvec.tolist()}, tvec={self._tvec.tolist()}, "
            f"D={None if self._D is None else self._D.tolist()}, image_size={self._image_size}"
            f"{extra})"
        )

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, MisalignedCatadioptricCamera):
            return NotImplemented
        same_D = (self._D is None and other._D is None) or (
            self._D is not None and other._D is not None and np.array_equal(self._D, other._D)
        )
        return (
            same_D
            and self._mirror == other._mirror
            and self._image_size == other._image_size
            and self._camera_reflection == other._camera_reflection
            and all(
                np.array_equal(getattr(self, n), getattr(other, n))
                for n in ("_K", "_rvec", "_tvec")
            )
        )

    # unhashable (the arrays): Python's way, which mypy types as a method of object's
    __hash__: ClassVar[None] = None  # type: ignore[assignment]

    # -- the model ----------------------------------------------------------------------
    def unproject(self, image_points: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Reflected rays of pixels by ray tracing (eqs. 6-19).

        Parameters
        ----------
        image_points : (N, 2) or (N, 1, 2) array_like, float32 or float64
            Pixel coordinates (centres at integers), distorted as the camera sees them.

        Returns
        -------
        origins : (N, 3) or (N, 1, 3) float64 ndarray
            Reflection points on the mirror, mirror frame.
        directions : same shape
            Unit reflected directions pointing into the scene, mirror frame.
            Rows are NaN for pixels whose ray misses the mirror (outside the rim) and NaN input.
        """
        pts, restore = raytrace.as_points(image_points, "image_points", 2)
        origins, directions = raytrace.trace(pts, self._K, self._D, self._R, self._C, self._mirror)
        return restore(origins), restore(directions)

    def project(
        self, object_points: ArrayLike, rvec: ArrayLike | None = None, tvec: ArrayLike | None = None
    ) -> FloatArray:
        """Exact non-central projection of 3-D points to pixels.

        For each point the pixel whose traced ray (:meth:`unproject`) passes through it, to
        better than 1e-6 px: the reflection point is found by Newton's method on Fermat's path
        length, started from the aligned model (eqs. 2-5).

        Parameters
        ----------
        object_points : (N, 3) or (N, 1, 3) array_like
            Points, in the mirror frame unless ``rvec, tvec`` are given.
        rvec, tvec : (3,) array_like, optional
            Move the points into the mirror frame first, ``X_M = R(rvec) X + tvec``, as in
            ``cv2.projectPoints``.

        Returns
        -------
        image_points : (N, 2) or (N, 1, 2) float64 ndarray
            NaN for points the rig cannot see: behind or inside the mirror, outside the field
            of view the rim allows, and NaN input.
        """
        pts, restore = raytrace.as_points(object_points, "object_points", 3)
        if (rvec is None) != (tvec is None):
            raise ValueError("give both rvec and tvec, or neither")
        if rvec is not None:
            Rm = cv2.Rodrigues(finite_array(rvec, "rvec", (3,), "3 numbers").reshape(3, 1))[0]
            pts = np.ascontiguousarray(pts @ Rm.T + finite_array(tvec, "tvec", (3,), "3 numbers"))
        return restore(
            raytrace.project(
                pts, False, self._K, self._D, self._R, self._tvec, self._C, self._mirror
            )
        )

    def project_directions(self, directions: ArrayLike) -> FloatArray:
        """Project points at infinity: the pixel whose reflected ray has the given direction.

        Parameters
        ----------
        directions : (N, 3) or (N, 1, 3) array_like
            Directions in the mirror frame (need not be unit).

        Returns
        -------
        image_points : (N, 2) or (N, 1, 2) float64 ndarray
            NaN for directions the mirror does not show (above its horizon, zero vectors, NaN).
        """
        pts, restore = raytrace.as_points(directions, "directions", 3)
        return restore(
            raytrace.project(
                pts, True, self._K, self._D, self._R, self._tvec, self._C, self._mirror
            )
        )

    # -- the rim and the viewpoint ------------------------------------------------------
    def rim_image_points(self, n: int = 360) -> FloatArray:
        """Pixels of ``n`` points of the rim circle, ``(n, 2)``: the ellipse of section 3.1."""
        rim = self._mirror.rim_points(n)
        xc = rim @ self._R.T + self._tvec
        xn = xc[:, :2] / xc[:, 2:3]
        return raytrace.to_pixels(xn, self._K, self._D)

    def mirror_pixels(self) -> FloatArray:
        """All integer pixels that see the mirror (inside the rim ellipse, in the frame or not).

        Returns
        -------
        pixels : (M, 2) float64 ndarray
        """
        rim = self.rim_image_points(720)
        lo = np.floor(rim.min(axis=0)) - 2
        hi = np.ceil(rim.max(axis=0)) + 2
        xs = np.arange(lo[0], hi[0] + 1)
        out = []
        for y0 in np.arange(lo[1], hi[1] + 1, 256):
            ys = np.arange(y0, min(y0 + 256, hi[1] + 1))
            gx, gy = np.meshgrid(xs, ys)
            pix = np.stack([gx.ravel(), gy.ravel()], axis=1)
            _, d = raytrace.trace(pix, self._K, self._D, self._R, self._C, self._mirror)
            out.append(pix[np.isfinite(d[:, 0])])
        return np.concatenate(out)

    def best_fit_viewpoint(self) -> tuple[FloatArray, float]:
        """The point closest, in mean squared distance, to the rays of all mirror pixels.

        Closed-form least squares (section 4.1): with ``M_i = I - d_i d_i^T``,
        ``(sum M_i) p = sum M_i P_i``. The rays are those of every integer pixel inside the rim
        ellipse (:meth:`mirror_pixels`). For the aligned rig ``p`` is the outer focus
        ``(0, 0, c)`` and ``rms`` is 0.

        Returns
        -------
        point : (3,) float64 ndarray
            Viewpoint, mirror frame.
        rms : float
            Root mean squared distance from ``point`` to the rays.
        """
        if self._viewpoint is None:
            pix = self.mirror_pixels()
            P, d = raytrace.trace(pix, self._K, self._D, self._R, self._C, self._mirror)
            # sum of (I - d d^T) and of (I - d d^T) P
            A = len(d) * np.eye(3) - d.T @ d
            rhs = P.sum(axis=0) - d.T @ np.einsum("ij,ij->i", d, P)
            p = np.linalg.solve(A, rhs)
            w = p - P
            perp = w - d * np.einsum("ij,ij->i", w, d)[:, None]
            rms = float(np.sqrt(np.mean(np.einsum("ij,ij->i", perp, perp))))
            p.flags.writeable = False
            self._viewpoint = (p, rms)
        return self._viewpoint
