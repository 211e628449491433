"""Mirrors of revolution that are no quadric, for the independent rig of ``tests/quadric_rig.py``.

Nothing here comes from omnicam (not ``omnicam.asphere``'s profile, fit or ray tracer): only
numpy. A mirror joins :class:`quadric_rig.Rig` through ``intersect(O, V)``, ``reflect(P, V)``,
``height(rho)``, ``z_rim``, ``rim_radius`` and ``name``.

**The equiangular mirror** (Chahl & Srinivasan, Applied Optics 36(31), 1997): in polar
coordinates about the camera's centre of projection at the origin, ``theta`` from the mirror
axis ``+z``,

    r(theta) = r0 cos((1 + alpha) theta / 2) ^ (-2 / (1 + alpha)),    0 <= theta < pi / (1 + alpha),

so that ``d ln r / d theta = tan(beta)``, ``beta = (1 + alpha) theta / 2``: the normal makes
``beta`` with the radius, the profile's slope is ``dz / d rho = tan(beta - theta) =
tan((alpha - 1) theta / 2)``, and a ray leaving the origin at ``theta`` leaves the mirror at
``alpha theta`` from the downward axis (the equiangular property, ``alpha`` the gain).

The surface is the profile ``z(rho)``, ``rho = r sin(theta)``, ``z = r cos(theta)``: ``theta``
of a radius by Newton on ``rho(theta) = r(theta) sin(theta)`` (increasing; started from a
dense table), and past the rim continued along its tangent (a convex continuation, used only to
bracket the hits). A ray ``O + t V`` meets it where ``H(t) = z(t) - z(rho(t))`` vanishes; ``H``
is concave in ``t`` (a linear function minus a convex function of an affine one), so its
maximum over the segment below the rim's plane is found by golden-section search (where the
ray is not already above the cap at that plane), the first root before it by bisection and
polished by Newton.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


def polar_radius(alpha, r0, theta):
    """Chahl & Srinivasan's ``r(theta)``."""
    return r0 * np.cos(0.5 * (1.0 + alpha) * np.asarray(theta, np.float64)) ** (
        -2.0 / (1.0 + alpha)
    )


@dataclasses.dataclass(frozen=True, eq=False)
class Equiangular:
    """Chahl & Srinivasan's mirror of gain ``alpha`` (> 1), vertex at ``z = r0``, its rim at
    the polar angle ``theta_rim`` (module docstring); the camera's centre of projection, for
    which the mirror is designed, is the mirror frame's origin.

    Attributes
    ----------
    alpha, r0, theta_rim : float
    """

    alpha: float
    r0: float
    theta_rim: float

    def __post_init__(self):
        if not (self.alpha > 1.0 and self.r0 > 0.0):
            raise ValueError(f"alpha > 1 and r0 > 0 expected, got {self.alpha}, {self.r0}")
        if not 0.0 < self.theta_rim < math.pi / (1.0 + self.alpha):
            raise ValueError(f"theta_rim must be in (0, pi / (1 + alpha)), got {self.theta_rim}")

    @property
    def name(self):
        return f"equiangular {self.alpha:g}"

    # -- the profile ------------------------------------------------------------------------
    def _rho_z(self, theta):
        r = polar_radius(self.alpha, self.r0, theta)
        return r * np.sin(theta), r * np.cos(theta)

    @functools.cached_property
    def rim_radius(self) -> float:
        return float(self._rho_z(self.theta_rim)[0])

    @functools.cached_property
    def z_rim(self) -> float:
        return float(self._rho_z(self.theta_rim)[1])

    @functools.cached_property
    def _rim_slope(self) -> float:
        return math.tan(0.5 * (self.alpha - 1.0) * self.theta_rim)

    @functools.cached_property
    def _table(self):
        theta = np.linspace(0.0, self.theta_rim, 20001)
        return self._rho_z(theta)[0], theta

    def theta_of_rho(self, rho):
        """The polar angle of the profile's point at radius ``rho`` (``0 <= rho <= rim``)."""
        rho = np.asarray(rho, np.float64)
        th = np.interp(rho, *self._table)
        for _ in range(3):  # Newton on rho(theta) - rho; d rho / d theta = r (tan b sin + cos)
            r = polar_radius(self.alpha, self.r0, th)
            b = 0.5 * (1.0 + self.alpha) * th
            th = th - (r * np.sin(th) - rho) / (r * (np.tan(b) * np.sin(th) + np.cos(th)))
        return th

    def slope(self, rho):
        """``dz / d rho`` of the profile, ``tan((alpha - 1) theta / 2)``; the rim's past it."""
        rho = np.asarray(rho, np.float64)
        th = self.theta_of_rho(np.minimum(rho, self.rim_radius))
        return np.tan(0.5 * (self.alpha - 1.0) * th)

    def height(self, rho):
        """``z`` of the profile at radius ``rho``; past the rim, along the rim's tangent."""
        rho = np.asarray(rho, np.float64)
        R = self.rim_radius
        inside = np.minimum(rho, R)
        th = self.theta_of_rho(inside)
        z = polar_radius(self.alpha, self.r0, th) * np.cos(th)
        return np.where(rho <= R, z, self.z_rim + self._rim_slope * (rho - R))

    def gradient(self, P):
        """``grad (z - z(rho))`` at ``(N, 3)`` points: ``(-s x / rho, -s y / rho, 1)``."""
        rho = np.hypot(P[:, 0], P[:, 1])
        s = self.slope(rho)
        with np.errstate(invalid="ignore", divide="ignore"):
            k = np.where(rho > 0.0, s / rho, 0.0)
        return np.column_stack([-k * P[:, 0], -k * P[:, 1], np.ones(len(P))])

    # -- rays -------------------------------------------------------------------------------
    def _H(self, O, V, t):
        X = O + t[:, None] * V
        return X[:, 2] - self.height(np.hypot(X[:, 0], X[:, 1]))

    def intersect(self, O, V, iterations=45):
        """First hit of the rays ``O + t V`` (``t > 0``) on the cap inside the rim, from below.

        Returns ``(P (N, 3), t (N,))``, NaN where the ray misses the cap (module docstring).
        """
        V = np.asarray(V, np.float64).reshape(-1, 3)
        O = np.broadcast_to(np.asarray(O, np.float64), V.shape).copy()
        n = len(V)
        nan = np.full(n, np.nan)
        up = V[:, 2] > 1e-12
        with np.errstate(invalid="ignore", divide="ignore"):
            t_top = np.where(up, (self.z_rim - O[:, 2]) / V[:, 2], 0.0)
        # where the ray is above the cap at the rim's plane (inside the rim), t_top brackets the
        # hit; elsewhere the maximum of the concave H on [0, t_top] (golden section) does
        t_max = t_top.copy()
        H_max = self._H(O, V, t_max)
        g = np.flatnonzero(up & ~(H_max >= 0.0))
        if len(g):
            Og, Vg = O[g], V[g]
            a, b = np.zeros(len(g)), t_top[g]
            c, d = b - GOLDEN * (b - a), a + GOLDEN * (b - a)
            Hc, Hd = self._H(Og, Vg, c), self._H(Og, Vg, d)
            for _ in range(iterations):
                left = Hc > Hd
                b, a = np.where(left, d, b), np.where(left, a, c)
                c, d = b - GOLDEN * (b - a), a + GOLDEN * (b - a)
                Hc, Hd = self._H(Og, Vg, c), self._H(Og, Vg, d)
            t_max[g] = 0.5 * (a + b)
            H_max[g] = self._H(Og, Vg, t_max[g])
        below = self._H(O, V, np.zeros(n)) < 0.0
        hits = up & below & (H_max >= 0.0)
        # the first root on [0, t_max]: bisection to 2^-28 of the segment, then Newton (kept in
        # the bracket), H' = V_z - s (d rho / d t)
        lo, hi = np.zeros(n), np.where(hits, t_max, 0.0)
        for _ in range(28):
            mid = 0.5 * (lo + hi)
            pos = self._H(O, V, mid) >= 0.0
            lo, hi = np.where(pos, lo, mid), np.where(pos, mid, hi)
        t = 0.5 * (lo + hi)
        for _ in range(3):
            X = O + t[:, None] * V
            rho = np.hypot(X[:, 0], X[:, 1])
            with np.errstate(invalid="ignore", divide="ignore"):
                drho = np.where(rho > 0, (X[:, 0] * V[:, 0] + X[:, 1] * V[:, 1]) / rho, 0.0)
            t = np.clip(t - self._H(O, V, t) / (V[:, 2] - self.slope(rho) * drho), lo, hi)
        P = O + t[:, None] * V
        ok = hits & (np.hypot(P[:, 0], P[:, 1]) <= self.rim_radius * (1.0 + 1e-9)) & (t > 1e-9)
        P[~ok] = np.nan
        return P, np.where(ok, t, nan)

    def reflect(self, P, V):
        """Unit reflected directions of the unit rays ``V`` at the cap points ``P``."""
        n = self.gradient(P)
        n = n / np.linalg.norm(n, axis=1, keepdims=True)
        d = V - 2.0 * np.einsum("ij,ij->i", V, n)[:, None] * n
        return d / np.linalg.norm(d, axis=1, keepdims=True)


def equiangular(alpha, r0, fraction=0.8):
    """The equiangular mirror of gain ``alpha``, vertex ``r0`` above the camera, its rim at
    ``fraction`` of the profile's polar range ``pi / (1 + alpha)``."""
    return Equiangular(float(alpha), float(r0), fraction * math.pi / (1.0 + alpha))
