"""The mirror profile a central model implies (chessboard.profile) and its even asphere."""

import math

import numpy as np
import pytest

from omnicam import HyperbolicMirror
from omnicam.chessboard.heldout import unified_predictor
from omnicam.chessboard.profile import fit_convex_asphere, fit_even_asphere, profile_from_central


def _hyperbolic_elevations(mirror, f):
    """alpha(rho) of the aligned rig with its camera at the outer focus, from Mei's model of
    it (central.py's closed form: xi = d / sqrt(d^2 + 4 p^2), gamma = f sqrt(1 - xi^2))."""
    a, b, c = mirror.a, mirror.b, mirror.c
    xi = 2 * c / math.sqrt(4 * c * c + (a * a / b) ** 2)  # d = 2c, 2p = a^2 / b
    gamma = f * math.sqrt(1 - xi * xi)
    K = np.array([[gamma, 0, 0], [0, gamma, 0], [0, 0, 1.0]])
    directions = unified_predictor(K, xi, np.zeros(4))[1]

    def alpha(rho):
        rho = np.atleast_1d(np.asarray(rho, np.float64))
        d = directions(np.stack([rho, np.zeros_like(rho)], axis=1))[1]
        return np.arctan2(-d[:, 2], d[:, 0])  # Mei's z is the physical elevation reversed

    return alpha


@pytest.mark.parametrize("a, b, rim", [(23.4, 28.1, 30.0), (28.1, 23.4, 30.0), (10.0, 30.0, 22.0)])
def test_hyperboloid_seen_from_its_outer_focus_is_rebuilt_from_its_central_model(a, b, rim):
    mirror = HyperbolicMirror(a, b, rim)
    f = 400.0
    rho_rim = f * rim / (mirror.z_rim + mirror.c)
    prof = profile_from_central(_hyperbolic_elevations(mirror, f), f, rho_rim, rim)
    # eq. 1 with the camera at the lower focus: z = b sqrt(1 + r^2 / a^2) + c
    z_true = b * np.sqrt(1 + prof.r**2 / a**2) + mirror.c
    assert np.max(np.abs(prof.z - z_true)) < 1e-6 * rim
    assert prof.vertex_distance == pytest.approx(b + mirror.c, rel=1e-9)
    slope = b * prof.r / (a * a * np.sqrt(1 + prof.r**2 / a**2))  # eq. 3's exact slopes
    assert np.max(np.abs(prof.slope - slope)) < 1e-9
    fit = fit_even_asphere(prof.r, prof.z, rim, n_terms=0, slope=prof.slope)
    assert fit.k == pytest.approx(-1 - a * a / (b * b), rel=1e-6)
    assert fit.R == pytest.approx(a * a / b, rel=1e-6)
    assert fit.vertex_z == pytest.approx(b + mirror.c, rel=1e-9)
    assert fit.max_error < 1e-6 * rim


def _sphere_elevations(radius, centre_z, f):
    """alpha(rho) of a pinhole at the origin looking up at a sphere (centre (0, centre_z)):
    the reflection law, directly."""

    def alpha(rho):
        phi = np.arctan(np.atleast_1d(np.asarray(rho, np.float64)) / f)
        u = np.stack([np.sin(phi), np.cos(phi)], axis=1)
        s = centre_z * np.cos(phi) - np.sqrt(radius**2 - (centre_z * np.sin(phi)) ** 2)
        n = (s[:, None] * u - [0.0, centre_z]) / radius
        d = u - 2 * np.sum(u * n, axis=1, keepdims=True) * n
        return np.arctan2(d[:, 1], d[:, 0])

    return alpha


def test_sphere_seen_by_a_pinhole_is_rebuilt_from_its_exact_elevations():
    radius, centre_z, rim, f = 40.0, 100.0, 25.0, 500.0
    z_rim = centre_z - math.sqrt(radius**2 - rim**2)
    rho_rim = f * rim / z_rim
    prof = profile_from_central(_sphere_elevations(radius, centre_z, f), f, rho_rim, rim)
    z_true = centre_z - np.sqrt(radius**2 - prof.r**2)
    assert np.max(np.abs(prof.z - z_true)) < 1e-6 * rim
    fit = fit_even_asphere(prof.r, prof.z, rim, n_terms=2, slope=prof.slope)
    assert abs(fit.k) < 1e-6 and fit.R == pytest.approx(radius, rel=1e-6)
    assert np.max(np.abs(fit.alphas)) < 1e-6 * rim and fit.max_error < 1e-6 * rim


@pytest.mark.parametrize("gain", [3.0, 5.0, 11.0])
def test_equiangular_elevations_give_chahl_and_srinivasans_profile(gain):
    # alpha = gain phi - pi/2 by design; r(theta) = r0 cos((1 + g) theta / 2)^(-2 / (1 + g))
    f, rim = 300.0, 20.0
    rho_rim = f * math.tan(0.8 * np.pi / (1 + gain))  # the profile ends at (1 + g) phi = pi
    prof = profile_from_central(lambda rho: gain * np.arctan(rho / f) - np.pi / 2, f, rho_rim, rim)
    p = (1 + gain) / 2
    r_polar = np.cos(p * prof.phi) ** (-1 / p)
    r0 = rim / (r_polar[-1] * np.sin(prof.phi[-1]))  # the rim fixes r0
    assert np.max(np.abs(np.hypot(prof.r, prof.z) - r0 * r_polar)) < 1e-6 * rim
    fit = fit_even_asphere(prof.r, prof.z, rim, n_terms=5, slope=prof.slope)
    assert fit.max_error < 1e-6 * rim  # 5e-9 at gain 5 (the conic alone: 1e-3)
    assert fit.R == pytest.approx(2 * r0 / (gain - 1), rel=1e-5)  # its vertex curvature


def test_profile_refuses_elevations_no_mirror_reflects():
    with pytest.raises(ValueError, match="alpha_of_rho"):
        profile_from_central(lambda rho: np.full_like(rho, np.pi / 2), 300.0, 100.0, 20.0)
    with pytest.raises(ValueError, match="rim_radius"):
        profile_from_central(lambda rho: rho * 0 - np.pi / 2, 300.0, 100.0, -1.0)


def test_convex_asphere_keeps_the_convex_fit_of_least_error():
    f, rim, gain = 300.0, 20.0, 11.0
    rho_rim = f * math.tan(0.8 * np.pi / (1 + gain))
    prof = profile_from_central(lambda rho: gain * np.arctan(rho / f) - np.pi / 2, f, rho_rim, rim)
    best = fit_convex_asphere(prof.r, prof.z, rim, max_terms=3, slope=prof.slope)
    fits = [fit_even_asphere(prof.r, prof.z, rim, n, slope=prof.slope) for n in range(4)]
    assert best.convex and fits[0].convex  # the conic alone always is
    assert best.slope_error <= min(f.slope_error for f in fits if f.convex) * (1 + 1e-9)
