"""Slow, obviously correct references for the kernels (one point at a time, textbook formulas).

Nothing here is fast or vectorised on purpose: it is what the numba kernels are checked against.
"""

import math

import numpy as np
from scipy.optimize import least_squares


def trace_pixel(u, v, K, R, tvec, a, b, rim_radius):
    """Ray tracing of one pixel (eqs. 6-19) with ``numpy.roots``; returns (P, d) or None."""
    Vc = np.linalg.solve(K, [u, v, 1.0])  # eq. 6
    V = R.T @ Vc  # eq. 16
    V = V / np.linalg.norm(V)
    F = -R.T @ tvec  # eq. 17
    # (F + kV) on (X^2+Y^2)/a^2 - Z^2/b^2 + 1 = 0, as a polynomial in k (eqs. 8-11)
    A = (V[0] ** 2 + V[1] ** 2) / a**2 - V[2] ** 2 / b**2
    B = 2 * ((V[0] * F[0] + V[1] * F[1]) / a**2 - V[2] * F[2] / b**2)
    C = (F[0] ** 2 + F[1] ** 2) / a**2 - F[2] ** 2 / b**2 + 1
    hits = []
    for k in np.roots([A, B, C]):
        if abs(k.imag) < 1e-12 and k.real > 0:
            P = F + k.real * V
            if P[2] > 0:
                hits.append((k.real, P))
    if not hits:
        return None
    _, P = min(hits, key=lambda h: h[0])
    N = np.array([b**2 * P[0] / (a**2 * P[2]), b**2 * P[1] / (a**2 * P[2]), -1.0])  # eq. 14
    if N @ V >= 0 or P[0] ** 2 + P[1] ** 2 > rim_radius**2:  # eq. 12, rim
        return None
    n = N / np.linalg.norm(N)
    return P, V - 2 * n * (n @ V)  # eq. 15


def project_point(X, K, R, tvec, a, b, rim_radius, guess):
    """The pixel whose traced ray passes through X, by generic least squares on the pixel."""

    def residual(uv):
        hit = trace_pixel(uv[0], uv[1], K, R, tvec, a, b, rim_radius)
        if hit is None:
            return np.array([1e3, 1e3, 1e3])
        P, d = hit
        w = X - P
        return np.cross(w / np.linalg.norm(w), d)  # sine of the angle between ray and P->X

    sol = least_squares(residual, guess, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    return sol.x


def hyperomni_direction(u, v, a, b, f_C, x_c, y_c):
    """Direction seen by pixel (u, v) of the aligned HyperOmni rig, eqs. 2-5 as printed.

    In our frame eq. 2 is ``Y/X = +(y - y_c)/(x - x_c)`` and eq. 4's alpha is the elevation
    (docs/conventions.md). Returns the unit direction and the point where the ray crosses the axis.
    """
    c = math.hypot(a, b)
    rho = math.hypot(u - x_c, v - y_c)
    beta = math.atan2(f_C, rho)  # eq. 5
    alpha = math.atan(
        ((b**2 + c**2) * math.sin(beta) - 2 * b * c) / ((b**2 - c**2) * math.cos(beta))
    )  # eq. 4
    azimuth = math.atan2(v - y_c, u - x_c)  # eq. 2
    d = np.array(
        [math.cos(alpha) * math.cos(azimuth), math.cos(alpha) * math.sin(azimuth), math.sin(alpha)]
    )
    return d, np.array([0.0, 0.0, c])  # eq. 3


def asphere_height(rho, R, k, alpha, rho_n, vertex_z):
    """The even asphere's height at one radius, as optical designers write it (textbook sag)."""
    z = vertex_z + rho**2 / (R * (1 + math.sqrt(1 - (1 + k) * rho**2 / R**2)))
    for j, a in enumerate(alpha):
        z += a * (rho / rho_n) ** (2 * j + 4)
    return z


def trace_pixel_surface(u, v, K, R, tvec, height, rim_radius, samples=20000):
    """Ray tracing of one pixel to a mirror of revolution ``Z = height(rho)``, brute force.

    The ray is sampled from the camera outwards for the first sign change, inside the rim,
    of ``Z - height(rho)`` from below to above, refined by bisection; the normal comes from
    central differences of ``height``. Returns (P, d) or None (no hit inside the rim).
    """
    V = R.T @ np.linalg.solve(K, [u, v, 1.0])
    V = V / np.linalg.norm(V)
    F = -R.T @ tvec

    def g(t):
        P = F + t * V
        rho = math.hypot(P[0], P[1])
        return None if rho > rim_radius else P[2] - height(rho)

    reach = 4.0 * (np.linalg.norm(F) + rim_radius + abs(height(0.0)))
    ts = np.linspace(0.0, reach, samples)
    prev = None
    for t0, t1 in zip(ts[:-1], ts[1:]):
        g0, g1 = g(t0), g(t1)
        if g0 is not None and g1 is not None and g0 < 0 <= g1:
            prev = (t0, t1)
            break
    if prev is None:
        return None
    lo, hi = prev
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if g(mid) < 0:
            lo = mid
        else:
            hi = mid
    P = F + 0.5 * (lo + hi) * V
    rho = math.hypot(P[0], P[1])
    e = 1e-5 * rim_radius
    slope = (height(rho + e) - height(rho - e)) / (2 * e)  # dZ/drho
    N = (
        np.array([slope * P[0] / rho, slope * P[1] / rho, -1.0])
        if rho > 0
        else np.array([0, 0, -1.0])
    )
    n = N / np.linalg.norm(N)
    return P, V - 2 * n * (n @ V)  # eq. 15
