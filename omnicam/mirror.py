"""The hyperboloidal mirror: surface, normal, ray intersection and reflection.

Mirror frame (``docs/conventions.md``): origin at the centre of the hyperboloid

    (X^2 + Y^2) / a^2 - Z^2 / b^2 = -1                         (eq. 1)

mirror sheet ``Z > 0``, foci ``(0, 0, +c)`` and ``(0, 0, -c)`` with ``c = sqrt(a^2 + b^2)``.
The physical mirror is the cap of that sheet inside the rim, the circle of radius
``rim_radius`` at height ``z_rim = b * sqrt(1 + rim_radius^2 / a^2)``.

These are vectorised numpy functions: the readable reference of the model. The per-pixel
hot loops use the same formulas in the seam of the kernels, :mod:`omnicam._kernels.mirror`,
which takes the mirror as :meth:`HyperbolicMirror.kernel_params`.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

from ._typing import ArrayLike, FloatArray
from ._validate import LENGTH_RANGE, float_array, real_number
from .asphere import AsphericMirror

__all__ = ["HyperbolicMirror", "Mirror", "describe_mirror", "nominal_camera_z"]


def _positive_finite(name: str, value: float) -> float:
    lo, hi = LENGTH_RANGE
    return real_number(
        value, name, lo, hi, expected=f"a positive finite number in [{lo:g}, {hi:g}] (mirror units)"
    )


class HyperbolicMirror:
    """Hyperboloidal mirror ``(X^2+Y^2)/a^2 - Z^2/b^2 = -1``, sheet ``Z > 0`` (eq. 1).

    Parameters
    ----------
    a, b : float
        Hyperboloid parameters (the paper's ``a_h, b_h``), in the length unit of the rig
        (millimetres by convention).
    rim_radius : float
        Radius of the circular mirror boundary (the rim), same unit.

    All three must be real numbers in [1e-3, 1e6] (``_validate.LENGTH_RANGE``); anything else
    raises ``ValueError`` naming the parameter.

    Attributes
    ----------
    c : float
        Focal distance ``sqrt(a^2 + b^2)``: the foci are ``(0, 0, +-c)``.
    z_rim : float
        Height of the rim plane, ``b * sqrt(1 + rim_radius^2 / a^2)``.

    Notes
    -----
    Immutable: the parameters are read-only properties, and equal mirrors compare equal.
    """

    __slots__ = ("_a", "_b", "_rim_radius")

    def __init__(self, a: float, b: float, rim_radius: float) -> None:
        self._a = _positive_finite("a", a)
        self._b = _positive_finite("b", b)
        self._rim_radius = _positive_finite("rim_radius", rim_radius)

    # -- parameters -------------------------------------------------------------------
    @property
    def a(self) -> float:
        """Hyperboloid parameter a."""
        return self._a

    @property
    def b(self) -> float:
        """Hyperboloid parameter b."""
        return self._b

    @property
    def rim_radius(self) -> float:
        """Radius of the rim circle."""
        return self._rim_radius

    @property
    def c(self) -> float:
        """Focal distance ``sqrt(a^2 + b^2)``."""
        return math.hypot(self._a, self._b)

    @property
    def z_rim(self) -> float:
        """Height of the rim, ``b * sqrt(1 + rim_radius^2 / a^2)``."""
        return self._b * math.sqrt(1.0 + (self._rim_radius / self._a) ** 2)

    @property
    def vertex_z(self) -> float:
        """Height of the apex, the sheet's lowest point ``(0, 0, b)``."""
        return self._b

    @property
    def length_scale(self) -> float:
        """``a + b``: the length the kernels' Newton tolerances are relative to."""
        return self._a + self._b

    def kernel_params(self) -> tuple[float, ...]:
        """The mirror as the kernels take it (:mod:`omnicam._kernels.mirror`):
        ``(KIND_HYPERBOLOID, rim_radius, a + b, a, b)`` padded with zeros to 15 floats (the
        length tells the kernels the kind)."""
        head = (0.0, self._rim_radius, self.length_scale, self._a, self._b)
        return head + (0.0,) * (15 - len(head))

    def as_asphere(self) -> AsphericMirror:
        """The same surface as an even asphere (:mod:`omnicam.asphere`): ``R = a^2 / b``,
        ``k = -1 - a^2 / b^2``, ``vertex_z = b``, no polynomial terms; the mirror frames are
        the same (origin at the hyperboloid's centre)."""
        a, b = self._a, self._b
        return AsphericMirror(a * a / b, -1.0 - (a / b) ** 2, self._rim_radius, vertex_z=b)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, HyperbolicMirror):
            return NotImplemented
        return (self._a, self._b, self._rim_radius) == (other._a, other._b, other._rim_radius)

    def __hash__(self) -> int:
        return hash((self._a, self._b, self._rim_radius))

    def __repr__(self) -> str:
        return f"HyperbolicMirror(a={self._a!r}, b={self._b!r}, rim_radius={self._rim_radius!r})"

    # -- geometry ---------------------------------------------------------------------
    def surface_z(self, X: ArrayLike, Y: ArrayLike) -> FloatArray:
        """Height of the mirror sheet, ``Z = b * sqrt((X^2 + Y^2) / a^2 + 1)`` (eq. 13).

        Parameters
        ----------
        X, Y : array_like
            Coordinates in the mirror frame (broadcast together).

        Returns
        -------
        Z : ndarray
            Height of the sheet ``Z > 0`` above ``(X, Y)``; defined beyond the rim too.
        """
        X = float_array(X, "X", "mirror-frame coordinates", copy=False)
        Y = float_array(Y, "Y", "mirror-frame coordinates", copy=False)
        Z: FloatArray = self._b * np.sqrt((X * X + Y * Y) / self._a**2 + 1.0)
        return Z

    def normal(self, points: ArrayLike) -> FloatArray:
        """Unnormalised surface normal ``N = (f_X, f_Y, -1)`` at points of the sheet (eq. 14).

        ``N`` points down and out of the mirror, towards the camera. Eq. 15 needs it normalised
        (paper erratum in ``docs/conventions.md``); use :meth:`unit_normal` for that.

        Parameters
        ----------
        points : (..., 3) array_like
            Points on the sheet, mirror frame.

        Returns
        -------
        N : (..., 3) ndarray
        """
        P = float_array(points, "points", "(..., 3) mirror-frame points", copy=False)
        # f = b sqrt(1 + (X^2+Y^2)/a^2)  =>  f_X = b^2 X / (a^2 f)   (eqs. 13-14)
        k = self._b**2 / (self._a**2 * P[..., 2])
        return np.stack([k * P[..., 0], k * P[..., 1], -np.ones_like(P[..., 2])], axis=-1)

    def unit_normal(self, points: ArrayLike) -> FloatArray:
        """Unit normal of eq. 14, pointing out of the mirror (towards the camera)."""
        N = self.normal(points)
        length: FloatArray = np.linalg.norm(N, axis=-1, keepdims=True)
        return N / length

    def intersect(self, origins: ArrayLike, directions: ArrayLike) -> FloatArray:
        """First hit of rays ``F + k V`` with the mirror cap (eqs. 8-12).

        The root of ``alpha k^2 + 2 beta k + gamma = 0`` (eqs. 8-11) kept is the smallest ``k > 0``
        on the sheet ``Z > 0``; it is a hit only if the ray enters the mirror there
        (``(N, V) < 0``, eq. 12) and the point lies inside the rim (``X^2 + Y^2 <= rim_radius^2``).

        Parameters
        ----------
        origins : (..., 3) array_like
            Ray origins ``F_M`` (mirror frame).
        directions : (..., 3) array_like
            Ray directions ``V_M`` (need not be unit).

        Returns
        -------
        points : (..., 3) ndarray
            The hit ``P_M``; NaN where the ray misses the mirror cap.
        """
        F = float_array(origins, "origins", "(..., 3) mirror-frame points", copy=False)
        V = float_array(directions, "directions", "(..., 3) directions", copy=False)
        F, V = np.broadcast_arrays(F, V)
        ia2, ib2 = 1.0 / self._a**2, 1.0 / self._b**2
        # eqs. 9-11
        alpha = (V[..., 0] ** 2 + V[..., 1] ** 2) * ia2 - V[..., 2] ** 2 * ib2
        beta = (V[..., 0] * F[..., 0] + V[..., 1] * F[..., 1]) * ia2 - V[..., 2] * F[..., 2] * ib2
        gamma = (F[..., 0] ** 2 + F[..., 1] ** 2) * ia2 - F[..., 2] ** 2 * ib2 + 1.0
        disc = beta * beta - alpha * gamma
        with np.errstate(invalid="ignore", divide="ignore"):
            sq = np.sqrt(disc)
            # eq. 8, both roots, written without cancellation
            q = -(beta + np.copysign(sq, beta))
            k1 = q / alpha
            k2 = gamma / q
            big = np.full_like(k1, np.inf)
            z1 = F[..., 2] + k1 * V[..., 2]
            z2 = F[..., 2] + k2 * V[..., 2]
            k1 = np.where((k1 > 0) & (z1 > 0), k1, big)
            k2 = np.where((k2 > 0) & (z2 > 0), k2, big)
            k = np.minimum(k1, k2)
            k = np.where(np.isfinite(k) & (disc >= 0), k, np.nan)
        P = F + k[..., None] * V
        N = self.normal(P)
        ok = (np.einsum("...i,...i->...", N, V) < 0) & (
            P[..., 0] ** 2 + P[..., 1] ** 2 <= self._rim_radius**2
        )
        return np.where(ok[..., None], P, np.nan)

    @staticmethod
    def reflect(directions: ArrayLike, unit_normals: ArrayLike) -> FloatArray:
        """Reflection law ``V_out = V - 2 n (n, V)`` with a unit normal (eq. 15).

        Parameters
        ----------
        directions : (..., 3) array_like
            Incoming directions ``V_M``.
        unit_normals : (..., 3) array_like
            Unit surface normals at the reflection points.

        Returns
        -------
        V_out : (..., 3) ndarray
            Reflected directions, with the length of ``directions``.
        """
        V = float_array(directions, "directions", "(..., 3) directions", copy=False)
        n = float_array(unit_normals, "unit_normals", "(..., 3) unit normals", copy=False)
        nV: FloatArray = np.einsum("...i,...i->...", n, V)
        return V - 2.0 * n * nV[..., None]

    def rim_points(self, n: int | float = 360) -> FloatArray:
        """``n`` points evenly spaced on the rim circle, ``(n, 3)``, mirror frame.

        ``n`` must be an integer in [1, 10**7] (``ValueError`` naming ``n`` otherwise).
        """
        if isinstance(n, bool) or not isinstance(n, numbers.Integral) or not 1 <= n <= 10**7:
            if not (isinstance(n, float) and n.is_integer() and 1 <= n <= 10**7):
                raise ValueError(f"n must be an integer number of points in [1, 10**7], got {n!r}")
        t = np.linspace(0.0, 2.0 * np.pi, int(n), endpoint=False)
        r = self._rim_radius
        return np.stack([r * np.cos(t), r * np.sin(t), np.full_like(t, self.z_rim)], axis=1)


#: The mirrors the ray tracer and the view tables take (through ``kernel_params()``, the seam
#: of :mod:`omnicam._kernels.mirror`)
Mirror = HyperbolicMirror | AsphericMirror


def nominal_camera_z(mirror: Mirror) -> float | None:
    """Where a rig built as designed puts the camera's centre: its height on the mirror axis
    (mirror frame), or None when the mirror does not say.

    - A :class:`HyperbolicMirror`: its lower focus, ``-c`` (the aligned HyperOmni rig of the
      paper's eqs. 2-5, the one central placement).
    - An :class:`~omnicam.asphere.AsphericMirror` that is a hyperboloid (``k < -1``, no
      ``alpha``): its lower focus too, ``vertex_z - b - c`` with ``b = R / (-1 - k)``,
      ``a^2 = R b`` (for ``HyperbolicMirror.as_asphere()`` the same ``-c``).
    - Any other asphere with ``vertex_z > 0``: the mirror frame's origin, 0. The convention for
      a mirror placed by its data sheet: the camera's centre of projection at the origin, the
      vertex ``vertex_z`` above it (as :meth:`AsphericMirror.equiangular` places it).
    - Otherwise (``vertex_z <= 0``: the frame says nothing of the camera) None; the checks that
      need it (the rim's expected size, ``guess_K``, the camera's offset) say so and are left
      out rather than guessed.
    """
    if isinstance(mirror, HyperbolicMirror):
        return -mirror.c
    if mirror.k < -1.0 and not mirror.alpha:
        b = mirror.R / (-1.0 - mirror.k)
        return mirror.vertex_z - b - math.sqrt(mirror.R * b + b * b)
    if mirror.vertex_z > 0.0:
        return 0.0
    return None


def describe_mirror(mirror: Mirror) -> str:
    """The mirror's parameters for a message: ``a = 23.4, b = 28.1, rim radius 30`` for a
    hyperboloid, ``even asphere R = 30, k = 0, vertex at Z = 40, rim radius 18`` (and its
    polynomial terms) otherwise."""
    if isinstance(mirror, HyperbolicMirror):
        return f"a = {mirror.a:g}, b = {mirror.b:g}, rim radius {mirror.rim_radius:g}"
    terms = f", {len(mirror.alpha)} polynomial terms" if mirror.alpha else ""
    return (
        f"even asphere R = {mirror.R:g}, k = {mirror.k:g}{terms}, vertex at Z = "
        f"{mirror.vertex_z:g}, rim radius {mirror.rim_radius:g}"
    )
