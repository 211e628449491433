"""Any convex mirror of revolution, as optical designers write it: the even asphere.

Mirror frame as for the hyperboloid (``docs/conventions.md``): the mirror axis is Z, the
surface is seen from below, and the physical mirror is the cap inside the rim circle
``rho = rim_radius``. The surface is

    Z = vertex_z + sag(rho),   rho = sqrt(X^2 + Y^2)

    sag(rho) = rho^2 / (R (1 + sqrt(1 - (1 + k) rho^2 / R^2)))
               + sum_j alpha_j (rho / rho_n)^(2 j + 4),   j = 0, 1, ...

with vertex radius ``R > 0`` (the surface curves up, away from a camera below it), conic
constant ``k`` (0 sphere, -1 paraboloid, < -1 hyperboloid, (-1, 0) prolate and > 0 oblate
ellipsoid) and even polynomial terms in the normalised radius ``rho / rho_n`` (``rho_n`` the
rim radius by default: normalised, a few terms fit a profile to 1e-6 of the aperture where
raw powers of rho are ill-conditioned). The conic part is the branch through the vertex of
``rho^2 - 2 R w + (1 + k) w^2 = 0`` (``w = Z - vertex_z``). Eq. 1's hyperboloid is
``R = a^2 / b``, ``k = -1 - a^2 / b^2``, ``vertex_z = b``
(:meth:`omnicam.mirror.HyperbolicMirror.as_asphere`).

The model contract: the mirror is convex inside the rim (the principal curvatures ``f''(rho)``
and ``f'(rho) / rho`` positive), and the conic is defined up to the rim
(``(1 + k) rim_radius^2 < R^2``); a camera outside its body sees each point at most once.
The rim is the circle ``rho = rim_radius`` at ``z_rim = vertex_z + sag(rim_radius)``; the
mirror's body is the solid above the cap, inside the rim's cylinder.

These are vectorised numpy functions, the readable reference; the kernels take the mirror as
:meth:`AsphericMirror.kernel_params` through :mod:`omnicam._kernels.mirror`.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence

import numpy as np

from ._typing import ArrayLike, FloatArray
from ._validate import LENGTH_RANGE, float_array, real_number

__all__ = ["AsphericMirror", "equiangular_profile", "fit_equiangular"]

#: Largest magnitude of the conic constant and of a polynomial coefficient (mirror units)
K_RANGE = (-1e6, 1e6)
ALPHA_LIMIT = 1e6
#: Polynomial terms the kernels take (omnicam._kernels.mirror.MAX_ALPHA)
MAX_ALPHA = 8
#: Points per rim radius where convexity is checked
CONVEXITY_SAMPLES = 2001
#: Newton iterations of :meth:`AsphericMirror.intersect` (monotone: see there)
HIT_MAX_ITER = 100


def _length(name: str, value: float) -> float:
    lo, hi = LENGTH_RANGE
    return real_number(
        value, name, lo, hi, expected=f"a positive finite number in [{lo:g}, {hi:g}] (mirror units)"
    )


class AsphericMirror:
    """Convex even-asphere mirror of revolution (module docstring for the model).

    Parameters
    ----------
    R : float
        Vertex radius of curvature, > 0 (mirror units).
    k : float
        Conic constant.
    rim_radius : float
        Radius of the rim circle.
    alpha : sequence of float, optional
        Coefficients of ``(rho / rho_n)^4, ^6, ...`` (mirror units).
    rho_n : float, optional
        Normalisation radius of the polynomial terms; the rim radius by default.
    vertex_z : float, optional
        Height of the vertex (the surface's lowest point) in the mirror frame.

    Raises ``ValueError`` naming the parameter for anything not finite or out of range, a
    conic not defined up to the rim (``rim_radius``) or a surface not convex inside it
    (``alpha``).

    Notes
    -----
    Immutable: the parameters are read-only properties, and equal mirrors compare equal.
    """

    __slots__ = ("_R", "_k", "_rim_radius", "_alpha", "_rho_n", "_vertex_z")

    def __init__(
        self,
        R: float,
        k: float,
        rim_radius: float,
        alpha: Sequence[float] = (),
        rho_n: float | None = None,
        vertex_z: float = 0.0,
    ) -> None:
        self._R = _length("R", R)
        self._k = real_number(k, "k", *K_RANGE, expected="a finite conic constant")
        self._rim_radius = _length("rim_radius", rim_radius)
        self._rho_n = self._rim_radius if rho_n is None else _length("rho_n", rho_n)
        self._vertex_z = real_number(
            vertex_z, "vertex_z", -LENGTH_RANGE[1], LENGTH_RANGE[1], expected="a finite height"
        )
        if isinstance(alpha, (str, bytes)) or not isinstance(alpha, (Sequence, np.ndarray)):
            raise ValueError(f"alpha must be a sequence of numbers, got {alpha!r}")
        self._alpha = tuple(
            real_number(a, f"alpha[{j}]", -ALPHA_LIMIT, ALPHA_LIMIT, expected="a finite number")
            for j, a in enumerate(alpha)
        )
        if len(self._alpha) > MAX_ALPHA:
            raise ValueError(f"alpha must have at most {MAX_ALPHA} terms, got {len(self._alpha)}")
        if not (1.0 + self._k) * self._rim_radius**2 < self._R**2:
            raise ValueError(
                f"rim_radius must be below R / sqrt(1 + k) = "
                f"{self._R / math.sqrt(1.0 + self._k):g}, where the conic ends, got "
                f"{self._rim_radius!r}"
            )
        rho = np.linspace(0.0, self._rim_radius, CONVEXITY_SAMPLES)
        _z, h1, h2 = self._sag_u(rho * rho)
        # principal curvatures (up to a positive factor): f'/rho = 2 h1, f'' = 2 h1 + 4 h2 u
        if not (np.all(h1 > 0.0) and np.all(2.0 * h1 + 4.0 * h2 * rho * rho > 0.0)):
            raise ValueError(
                "alpha: the mirror must be convex inside the rim (f'' > 0 and f' > 0 there), "
                f"got alpha={list(self._alpha)!r}"
            )

    # -- constructors of common families ------------------------------------------------------
    @classmethod
    def sphere(cls, radius: float, rim_radius: float, vertex_z: float = 0.0) -> AsphericMirror:
        """Sphere of ``radius`` (``k = 0``): the cap below its centre ``vertex_z + radius``."""
        return cls(radius, 0.0, rim_radius, vertex_z=vertex_z)

    @classmethod
    def paraboloid(cls, R: float, rim_radius: float, vertex_z: float = 0.0) -> AsphericMirror:
        """Paraboloid ``Z = vertex_z + rho^2 / (2 R)`` (``k = -1``)."""
        return cls(R, -1.0, rim_radius, vertex_z=vertex_z)

    @classmethod
    def ellipsoid(
        cls, R: float, k: float, rim_radius: float, vertex_z: float = 0.0
    ) -> AsphericMirror:
        """Ellipsoid: prolate for ``-1 < k < 0`` (the vertex on its long axis), oblate for
        ``k > 0``; ``ValueError`` naming ``k`` otherwise."""
        k = real_number(k, "k", *K_RANGE, expected="a finite conic constant")
        if not (-1.0 < k < 0.0 or k > 0.0):
            raise ValueError(f"k must be in (-1, 0) or > 0 for an ellipsoid, got {k!r}")
        return cls(R, k, rim_radius, vertex_z=vertex_z)

    @classmethod
    def equiangular(
        cls, alpha: float, r0: float, rim_radius: float, n_terms: int = 5
    ) -> AsphericMirror:
        """Chahl & Srinivasan's equiangular mirror fitted by a conic and ``n_terms`` even
        terms (:func:`fit_equiangular`, which also gives the fit's error); the camera's centre
        of projection is the origin, so ``vertex_z = r0``."""
        return fit_equiangular(alpha, r0, rim_radius, n_terms)[0]

    # -- parameters ---------------------------------------------------------------------------
    @property
    def R(self) -> float:
        """Vertex radius of curvature."""
        return self._R

    @property
    def k(self) -> float:
        """Conic constant."""
        return self._k

    @property
    def alpha(self) -> tuple[float, ...]:
        """Coefficients of ``(rho / rho_n)^4, ^6, ...``."""
        return self._alpha

    @property
    def rho_n(self) -> float:
        """Normalisation radius of the polynomial terms."""
        return self._rho_n

    @property
    def vertex_z(self) -> float:
        """Height of the vertex, the lowest point of the surface."""
        return self._vertex_z

    @property
    def rim_radius(self) -> float:
        """Radius of the rim circle."""
        return self._rim_radius

    @property
    def z_rim(self) -> float:
        """Height of the rim, ``vertex_z + sag(rim_radius)``."""
        return float(self._vertex_z + self._sag_u(np.array(self._rim_radius**2))[0])

    @property
    def length_scale(self) -> float:
        """``2 rim_radius``: the length the kernels' Newton tolerances are relative to."""
        return 2.0 * self._rim_radius

    def kernel_params(self) -> tuple[float, ...]:
        """The mirror as the kernels take it (:mod:`omnicam._kernels.mirror`): ``(KIND_ASPHERE,
        rim_radius, 2 rim_radius, R, k, vertex_z, rho_n, len(alpha), *alpha)`` padded with
        zeros to 16 floats (the length tells the kernels the kind)."""
        head = (1.0, self._rim_radius, self.length_scale, self._R, self._k, self._vertex_z)
        params = (*head, self._rho_n, float(len(self._alpha)), *self._alpha)
        return params + (0.0,) * (16 - len(params))

    def _key(self) -> tuple[object, ...]:
        return (self._R, self._k, self._rim_radius, self._alpha, self._rho_n, self._vertex_z)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, AsphericMirror):
            return NotImplemented
        return self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    def __repr__(self) -> str:
        return (
            f"AsphericMirror(R={self._R!r}, k={self._k!r}, rim_radius={self._rim_radius!r}, "
            f"alpha={self._alpha!r}, rho_n={self._rho_n!r}, vertex_z={self._vertex_z!r})"
        )

    # -- geometry -----------------------------------------------------------------------------
    def _sag_u(self, u: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(sag, d sag / du, d^2 sag / du^2)`` at ``u = rho^2``; NaN past the conic's end.

        Conic: ``w = c u / (1 + q)``, ``q = sqrt(1 - (1 + k) c^2 u)``, ``c = 1 / R``; from
        ``u - 2 R w + (1 + k) w^2 = 0``: ``w' = 1 / (2 R q)`` and ``w'' = 2 (1 + k) w'^3``.
        """
        c = 1.0 / self._R
        k1 = 1.0 + self._k
        with np.errstate(invalid="ignore", divide="ignore"):
            q = np.sqrt(1.0 - k1 * c * c * u)
            w = c * u / (1.0 + q)
            w1 = 0.5 * c / q
        w2 = 2.0 * k1 * w1**3
        t = u / self._rho_n**2
        for j, a in enumerate(self._alpha):
            m = j + 2  # the term a t^m, t = u / rho_n^2
            w = w + a * t**m
            w1 = w1 + a * m * t ** (m - 1) / self._rho_n**2
            w2 = w2 + a * m * (m - 1) * t ** (m - 2) / self._rho_n**4
        return w, w1, w2

    def sag(self, rho: ArrayLike) -> FloatArray:
        """``sag(rho)``: height of the surface above the vertex at radius ``rho``."""
        r = float_array(rho, "rho", "radii", copy=False)
        return self._sag_u(r * r)[0]

    def surface_z(self, X: ArrayLike, Y: ArrayLike) -> FloatArray:
        """Height of the surface ``Z = vertex_z + sag(sqrt(X^2 + Y^2))``; defined past the rim
        where the conic is (NaN beyond)."""
        X = float_array(X, "X", "mirror-frame coordinates", copy=False)
        Y = float_array(Y, "Y", "mirror-frame coordinates", copy=False)
        return self._vertex_z + self._sag_u(X * X + Y * Y)[0]

    def normal(self, points: ArrayLike) -> FloatArray:
        """Unnormalised normal ``N = (f_X, f_Y, -1) = (2 s' X, 2 s' Y, -1)`` (``s' = d sag /
        d rho^2``; eq. 14's form), pointing down and out of the mirror, at ``(..., 3)``
        points of the surface (only their X, Y are used)."""
        P = float_array(points, "points", "(..., 3) mirror-frame points", copy=False)
        h1 = self._sag_u(P[..., 0] ** 2 + P[..., 1] ** 2)[1]
        return np.stack([2.0 * h1 * P[..., 0], 2.0 * h1 * P[..., 1], -np.ones_like(h1)], axis=-1)

    def unit_normal(self, points: ArrayLike) -> FloatArray:
        """Unit normal, pointing out of the mirror (towards the camera)."""
        N = self.normal(points)
        length: FloatArray = np.linalg.norm(N, axis=-1, keepdims=True)
        return N / length

    def _g(self, F: FloatArray, V: FloatArray, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``g(t) = Z - f(rho)`` along ``F + t V`` and ``dg/dt``: negative below the surface."""
        P = F + t[..., None] * V
        s, s1, _s2 = self._sag_u(P[..., 0] ** 2 + P[..., 1] ** 2)
        du = 2.0 * (P[..., 0] * V[..., 0] + P[..., 1] * V[..., 1])
        return P[..., 2] - self._vertex_z - s, V[..., 2] - s1 * du

    def intersect(self, origins: ArrayLike, directions: ArrayLike) -> FloatArray:
        """First hit of rays ``F + t V`` with the mirror cap, entering from outside.

        Inside the rim's cylinder ``g(t) = Z(t) - f(rho(t))`` is concave in t (the surface is
        convex), so from a ray that enters the cylinder below the surface (``g < 0``) Newton
        on g, started at the closed-form hit of the conic part (or at the entry), reaches the
        first root monotonically from the left after at most one step, grazing rays included;
        a ray that never gets above the surface inside the rim misses (``g' <= 0`` first, or
        the root past the cylinder's exit).

        Parameters
        ----------
        origins, directions : (..., 3) array_like
            Ray origins and directions (need not be unit), mirror frame.

        Returns
        -------
        points : (..., 3) ndarray
            The hit; NaN where the ray misses the cap or meets it from inside.
        """
        F = float_array(origins, "origins", "(..., 3) mirror-frame points", copy=False)
        V = float_array(directions, "directions", "(..., 3) directions", copy=False)
        F, V = np.broadcast_arrays(F, V)
        shape = F.shape[:-1]
        F = F.reshape(-1, 3)
        V = V.reshape(-1, 3)
        A = V[:, 0] ** 2 + V[:, 1] ** 2
        B = F[:, 0] * V[:, 0] + F[:, 1] * V[:, 1]
        C = F[:, 0] ** 2 + F[:, 1] ** 2 - self._rim_radius**2
        with np.errstate(invalid="ignore", divide="ignore"):
            sq = np.sqrt(B * B - A * C)
            vertical = A == 0.0
            t_in = np.where(vertical, np.where(C <= 0.0, -np.inf, np.nan), (-B - sq) / A)
            t_out = np.where(vertical, np.where(C <= 0.0, np.inf, np.nan), (-B + sq) / A)
            t0 = np.maximum(t_in, 0.0)
            alive = (t0 < t_out) & (self._g(F, V, np.where(np.isfinite(t0), t0, 0.0))[0] < 0.0)
            t = np.where(alive, t0, np.nan)
            tc = self._conic_hit(F, V)
            use = alive & (tc > t0) & (tc < t_out)
            use &= self._g(F, V, np.where(use, tc, 0.0))[1] > 0.0
            t = np.where(use, tc, t)
            tol = 1e-13 * self.length_scale
            for _ in range(HIT_MAX_ITER):
                g, gp = self._g(F, V, np.where(alive, t, 0.0))
                alive &= gp > 0.0
                step = np.where(alive, -g / gp, 0.0)
                t = np.where(alive, np.maximum(t + step, t0), np.nan)
                alive &= t <= t_out
                if not np.any(alive & (np.abs(step) > tol)):
                    break
            t = np.where(alive, t, np.nan)
        return (F + t[:, None] * V).reshape(*shape, 3)

    def _conic_hit(self, F: FloatArray, V: FloatArray) -> FloatArray:
        """Smallest ``t > 0`` where ``F + t V`` meets the conic part's branch through the
        vertex (``R - (1 + k) w >= 0``), in closed form; NaN if none."""
        k1 = 1.0 + self._k
        R = self._R
        wF = F[:, 2] - self._vertex_z
        a = V[:, 0] ** 2 + V[:, 1] ** 2 + k1 * V[:, 2] ** 2
        b = F[:, 0] * V[:, 0] + F[:, 1] * V[:, 1] + k1 * wF * V[:, 2] - R * V[:, 2]
        c = F[:, 0] ** 2 + F[:, 1] ** 2 + k1 * wF * wF - 2.0 * R * wF
        with np.errstate(invalid="ignore", divide="ignore"):
            q = -(b + np.copysign(np.sqrt(b * b - a * c), b))
            roots = np.stack([q / a, c / q])
            ok = (roots > 0.0) & (R - k1 * (wF + roots * V[:, 2]) >= 0.0)
            best = np.where(ok, roots, np.inf).min(axis=0)
        return np.where(np.isfinite(best), best, np.nan)

    @staticmethod
    def reflect(directions: ArrayLike, unit_normals: ArrayLike) -> FloatArray:
        """Reflection law ``V_out = V - 2 n (n, V)`` with a unit normal (eq. 15)."""
        V = float_array(directions, "directions", "(..., 3) directions", copy=False)
        n = float_array(unit_normals, "unit_normals", "(..., 3) unit normals", copy=False)
        nV: FloatArray = np.einsum("...i,...i->...", n, V)
        return V - 2.0 * n * nV[..., None]

    def rim_points(self, n: int | float = 360) -> FloatArray:
        """``n`` points evenly spaced on the rim circle, ``(n, 3)``, mirror frame."""
        if isinstance(n, bool) or not isinstance(n, numbers.Integral) or not 1 <= n <= 10**7:
            if not (isinstance(n, float) and n.is_integer() and 1 <= n <= 10**7):
                raise ValueError(f"n must be an integer number of points in [1, 10**7], got {n!r}")
        t = np.linspace(0.0, 2.0 * np.pi, int(n), endpoint=False)
        r = self._rim_radius
        return np.stack([r * np.cos(t), r * np.sin(t), np.full_like(t, self.z_rim)], axis=1)


# -- the equiangular mirror ---------------------------------------------------------------------
def equiangular_profile(alpha: float, r0: float, theta: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Chahl & Srinivasan's equiangular profile ``(rho, z)`` at polar angles ``theta``.

    ``r(theta) = r0 cos((1 + alpha) theta / 2)^(-2 / (1 + alpha))`` about the camera's centre
    of projection at the origin, ``theta`` from the mirror axis (+Z): ``rho = r sin(theta)``,
    ``z = r cos(theta)``. A ray leaving the camera at ``theta`` leaves the mirror at
    ``alpha theta`` from the downward axis (the equiangular property: the normal makes
    ``(1 + alpha) theta / 2`` with the radius).
    """
    th = np.asarray(theta, dtype=np.float64)
    r = r0 * np.cos(0.5 * (1.0 + alpha) * th) ** (-2.0 / (1.0 + alpha))
    return r * np.sin(th), r * np.cos(th)


def fit_equiangular(
    alpha: float, r0: float, rim_radius: float, n_terms: int = 5
) -> tuple[AsphericMirror, float]:
    """Even asphere through Chahl & Srinivasan's equiangular profile, and its fit error.

    The profile (:func:`equiangular_profile`) is sampled densely up to the rim; ``vertex_z =
    r0`` and ``R = 2 r0 / (alpha - 1)`` (its curvature at the vertex: ``z ~ r0 + (alpha - 1)
    rho^2 / (4 r0)``) are exact; ``k`` and the ``n_terms`` coefficients of ``(rho /
    rim_radius)^4, ^6, ...`` are fitted by least squares on the height (linear in the
    coefficients for each k, so only k is searched).

    Returns
    -------
    mirror : AsphericMirror
    max_error : float
        ``max |Z_fit - Z_profile|`` over the aperture, divided by ``rim_radius``.
    """
    from scipy.optimize import minimize_scalar

    alpha = real_number(alpha, "alpha", 1.0, 1e3, expected="a gain > 1 (a convex mirror)")
    if not alpha > 1.0:
        raise ValueError(f"alpha must be > 1 for a convex equiangular mirror, got {alpha!r}")
    r0 = _length("r0", r0)
    rim_radius = _length("rim_radius", rim_radius)
    if (
        isinstance(n_terms, bool)
        or not isinstance(n_terms, numbers.Integral)
        or not 0 <= n_terms <= MAX_ALPHA
    ):
        raise ValueError(f"n_terms must be an integer in [0, {MAX_ALPHA}], got {n_terms!r}")
    theta_max = math.pi / (1.0 + alpha)
    lo, hi = 0.0, theta_max * (1.0 - 1e-12)
    for _ in range(200):  # bisection for the rim's polar angle: rho(theta) increases
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if equiangular_profile(alpha, r0, mid)[0] < rim_radius else (lo, mid)
    theta = np.linspace(0.0, hi, 4001)
    rho, z = equiangular_profile(alpha, r0, theta)
    rho[-1] = rim_radius
    R = 2.0 * r0 / (alpha - 1.0)
    u = rho * rho
    t = u / rim_radius**2
    basis = np.stack([t ** (j + 2) for j in range(n_terms)], axis=1)

    def conic(k: float) -> FloatArray:
        q2 = 1.0 - (1.0 + k) * u / R**2
        return np.where(q2 >= 0.0, u / (R * (1.0 + np.sqrt(np.maximum(q2, 0.0)))), np.inf)

    def solve(k: float) -> tuple[FloatArray, float]:
        rest = z - r0 - conic(k)
        if not np.all(np.isfinite(rest)):
            return np.zeros(n_terms), math.inf
        coef = np.linalg.lstsq(basis, rest, rcond=None)[0] if n_terms else np.zeros(0)
        return coef, float(np.max(np.abs(basis @ coef - rest)))

    k_top = R**2 / rim_radius**2 - 1.0  # the conic must reach the rim
    best = minimize_scalar(
        lambda k: solve(k)[1],
        bounds=(-50.0, min(50.0, k_top * (1 - 1e-9))),
        method="bounded",
        options={"xatol": 1e-10},
    )
    k = float(best.x)
    coef, err = solve(k)
    mirror = AsphericMirror(R, k, rim_radius, tuple(coef.tolist()), vertex_z=r0)
    check = float(np.max(np.abs(mirror.surface_z(rho, 0.0 * rho) - z)))
    return mirror, check / rim_radius
