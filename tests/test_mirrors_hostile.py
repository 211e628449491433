"""calibrate_pattern(mirror=None) on mirrors of revolution other than the hyperboloid (issue 28,
item 9): misaligned sphere, paraboloid (a perspective camera makes it non-central), prolate
ellipsoid and Chahl & Srinivasan's equiangular mirrors of gain 3, 5 and 7, behind a
near-pinhole and a wide-angle lens.

The ground truth is the independent forward model (``tests/quadric_rig.py`` for the quadrics,
``tests/revolution_rig.py`` for the equiangular profile): it shares nothing with omnicam. The
truth as omnicam's camera (:func:`omnicam_truth`) only evaluates what is stated at the truth
(the benchmark's information bound); it is checked to trace the model's rays first.
Every rig is misaligned as in ``tests/test_chessboard_hostile.py`` (3 deg, 3.1 mm), 12 views at
depths drawn log-uniformly over a range, 0.15 px of corner noise, 0.1 px of rim noise.
"""

import functools
import math

import cv2
import numpy as np
import pytest
import quadric_rig as qr
import revolution_rig as rr
import test_chessboard_hostile as T

import omnicam
from omnicam.chessboard.other_starts import RAYS_WEAK_DEG
from omnicam.chessboard.report import STARTS_STATED

#: (lens label) -> (image size, k1, k2, focal length or None: the rim fills 0.85 of the image)
LENSES = {
    "near-pinhole": ((1024, 768), -0.05, 0.01, None),
    "wide-angle": ((1280, 1080), -0.27, 0.06, 180.0),
}
#: The wide-angle lens sees a quadric's rim 243 px from the image centre (the hyperbolic
#: wide-angle case's), the camera moved along the axis for it but kept ``WIDE_CLEARANCE`` mm
#: below the vertex (the sphere's and the ellipsoid's rims are then nearer the centre); an
#: equiangular mirror is designed for its own camera position, so it stays there and its image
#: is as small as the lens makes it.
WIDE_RIM_PX, WIDE_CLEARANCE = 243.0, 15.0

#: (mirror label) -> (the model's mirror, the near-pinhole camera's height on the axis)
MIRRORS = {
    "sphere": (qr.sphere(40.0, 0.0, 30.0), -90.0),  # vertex at -40
    "paraboloid": (qr.paraboloid(30.0, 0.0, 30.0), -50.0),
    "prolate ellipsoid": (qr.ellipsoid(25.0, 40.0, 0.0, 22.0), -90.0),  # k = -0.61, vertex -40
    "equiangular 3": (rr.equiangular(3.0, 40.0), 0.0),
    "equiangular 5": (rr.equiangular(5.0, 40.0), 0.0),
    "equiangular 7": (rr.equiangular(7.0, 40.0), 0.0),
}

#: (lens label) -> boards: pattern, square (mm), distance range (mm) from the mirror point
BOARDS = {
    "near-pinhole": ((7, 5), 60.0, (250.0, 1200.0)),
    "wide-angle": ((7, 6), 30.0, (300.0, 1500.0)),
}


def _wide_camera_z(mirror, k1, k2, f):
    """The camera height at which the aligned rim's image is ``WIDE_RIM_PX`` from the centre."""
    lo, hi = 0.0, 10.0  # the undistorted tan of the rim's angle (the lens has no fold there)
    for _ in range(100):
        x = 0.5 * (lo + hi)
        lo, hi = (x, hi) if f * x * (1.0 + k1 * x * x + k2 * x**4) < WIDE_RIM_PX else (lo, x)
    return min(mirror.z_rim - mirror.rim_radius / x, mirror.height(0.0) - WIDE_CLEARANCE)


def rig(mirror_label, lens_label):
    """The misaligned rig of a case (the model's)."""
    mirror, camera_z = MIRRORS[mirror_label]
    size, k1, k2, f = LENSES[lens_label]
    if f is not None and isinstance(mirror, qr.Quadric):
        camera_z = _wide_camera_z(mirror, k1, k2, f)
    R, t = qr.posture(T.TILT_DEG, T.TILT_AZIMUTH_DEG, T.OFFSET, -camera_z)
    return qr.rig_filling(mirror, size, camera_z, k1=k1, k2=k2, R=R, t=t, f=f)


CASES = [(m, lens) for lens in LENSES for m in MIRRORS]


def omnicam_mirror(mirror):
    """The model's mirror as omnicam's :class:`~omnicam.AsphericMirror`: a quadric's conic
    exactly (``alpha z^2 + 2 beta z + ...``: ``k = alpha - 1``), the equiangular profile fitted
    (:meth:`~omnicam.AsphericMirror.equiangular`)."""
    if isinstance(mirror, rr.Equiangular):
        return omnicam.AsphericMirror.equiangular(mirror.alpha, mirror.r0, mirror.rim_radius)
    al, be, ga = mirror.alpha, mirror.beta, mirror.gamma
    if al == 0.0:  # z = z0 + rho^2 / (2 h)
        h = -be
        return omnicam.AsphericMirror.paraboloid(h, mirror.rim_radius, -ga / (2.0 * h))
    if al > 0.0:  # rho^2 / A^2 + (z - z0)^2 / C^2 = 1, the lower cap
        z0 = -be / al
        A2 = al * z0 * z0 - ga
        C = math.sqrt(A2 / al)
        return omnicam.AsphericMirror(A2 / C, al - 1.0, mirror.rim_radius, vertex_z=z0 - C)
    raise ValueError(f"no conversion for {mirror.name}")


def omnicam_truth(rig):
    """The rig as omnicam's camera, for what is evaluated at the truth (the benchmark's bound)."""
    return omnicam.MisalignedCatadioptricCamera(
        rig.K,
        omnicam_mirror(rig.mirror),
        cv2.Rodrigues(rig.R)[0].ravel(),
        rig.t,
        D=rig.D,
        image_size=rig.image_size,
    )


def truth_ray_gap_deg(rig, step=10.0):
    """The largest angle between the model's and omnicam's truth's rays over the mirror, deg."""
    px = rig.mirror_pixels(step=step)
    _, d0 = rig.trace(px)
    _, d1 = omnicam_truth(rig).unproject(px)
    return float(np.degrees(np.arccos(np.clip(np.sum(d0 * d1, axis=1), -1.0, 1.0))).max())


class Fit(T.Fit):
    """A case's rig, boards and calibrate_pattern(mirror=None) of their noisy corners;
    ``refused`` the message where calibrate_pattern raised ``ValueError`` (``camera`` None)."""

    def __init__(self, mirror_label, lens_label, seed=0, **kw):
        pattern, square, distance = BOARDS[lens_label]
        self.label = f"{mirror_label}, {lens_label}"
        self.refused, self.camera, self.report = None, None, None
        try:
            super().__init__(rig(mirror_label, lens_label), pattern, square, distance, seed, **kw)
        except ValueError as e:
            self.refused = str(e)


# -- the model keeps its own promises ----------------------------------------------------------
def _rays_from(O, theta, phi):
    V = np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
    return np.broadcast_to(O, V.shape), V


@pytest.mark.parametrize("alpha", [3.0, 5.0, 7.0])
def test_equiangular_mirror_sends_a_ray_at_theta_out_at_alpha_theta_from_the_downward_axis(alpha):
    mirror = rr.equiangular(alpha, 40.0)
    rng = np.random.default_rng(int(alpha))
    theta = rng.uniform(0.001, 0.999 * mirror.theta_rim, 400)
    O, V = _rays_from(np.zeros(3), theta, rng.uniform(0.0, 2.0 * np.pi, 400))
    P, _ = mirror.intersect(O, V)
    d = mirror.reflect(P, V)
    assert np.isfinite(d).all()
    assert np.abs(np.arccos(-d[:, 2]) - alpha * theta).max() < 1e-12
    # the hits lie on the polar curve r(theta), evaluated directly at their polar angle
    r = np.linalg.norm(P, axis=1)
    th = np.arctan2(np.hypot(P[:, 0], P[:, 1]), P[:, 2])
    assert np.abs(r - rr.polar_radius(alpha, 40.0, th)).max() < 1e-12 * 40.0
    assert np.abs(th - theta).max() < 1e-12  # (rays from the origin keep their polar angle)


@pytest.mark.parametrize("label", sorted(MIRRORS))
def test_reflection_law_holds_on_every_mirror(label):
    """Off-centre rays: the reflected ray is the incident one turned about the normal's line
    (equal angles, coplanar), the hit on the surface, inside the rim."""
    mirror, camera_z = MIRRORS[label]
    rng = np.random.default_rng(4)
    O = np.array([2.0, -1.5, camera_z + 1.0])
    O, V = _rays_from(O, rng.uniform(0.0, 0.5, 600), rng.uniform(0.0, 2.0 * np.pi, 600))
    P, _ = mirror.intersect(O, V)
    ok = np.isfinite(P).all(axis=1)
    assert ok.sum() > 300
    P, V = P[ok], V[ok]
    d = mirror.reflect(P, V)
    rho = np.hypot(P[:, 0], P[:, 1])
    assert rho.max() <= mirror.rim_radius * (1 + 1e-9)
    assert np.abs(P[:, 2] - mirror.height(rho)).max() < 1e-9 * mirror.rim_radius
    # the normal of the profile by central differences of the height, not the mirror's own
    h = 1e-5 * mirror.rim_radius
    slope = (mirror.height(rho + h) - mirror.height(np.maximum(rho - h, 0.0))) / (
        rho + h - np.maximum(rho - h, 0.0)
    )
    n = np.column_stack([-slope * P[:, 0] / rho, -slope * P[:, 1] / rho, np.ones(len(P))])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    assert np.abs(np.sum(d * n, 1) + np.sum(V * n, 1)).max() < 1e-6  # equal angles
    assert np.abs(np.cross(d - V, n)).max() < 1e-6  # d - V along the normal
    assert np.all(np.sum(V * n, 1) > 0.0)  # n points up, into the body: met from below


def test_prolate_ellipsoid_sends_rays_from_one_focus_through_the_other():
    """From inside, the ellipsoid's defining property: a ray from a focus reflects through the
    other (checked on the whole quadric, the cap's test of facing aside)."""
    A, C, z0 = 25.0, 40.0, 0.0
    mirror = qr.ellipsoid(A, C, z0, 22.0)
    e = math.sqrt(C * C - A * A)
    rng = np.random.default_rng(5)
    theta = rng.uniform(0.0, 0.3, 300)
    O, V = _rays_from(np.array([0.0, 0.0, z0 + e]), math.pi - theta, rng.uniform(0, 6.3, 300))
    # the far root of F(O + t V) = 0 from inside: the lower cap below the upper focus
    al, be = mirror.alpha, mirror.beta
    a2 = V[:, 0] ** 2 + V[:, 1] ** 2 + al * V[:, 2] ** 2
    b1 = O[:, 0] * V[:, 0] + O[:, 1] * V[:, 1] + al * O[:, 2] * V[:, 2] + be * V[:, 2]
    t = (-b1 + np.sqrt(b1 * b1 - a2 * mirror.value(O))) / a2
    P = O + t[:, None] * V
    d = mirror.reflect(P, V)
    f2 = np.array([0.0, 0.0, z0 - e]) - P
    miss = np.linalg.norm(f2 - np.sum(f2 * d, 1)[:, None] * d, axis=1)
    assert (
        np.abs(P[:, 2] - (z0 - C * np.sqrt(1 - (P[:, 0] ** 2 + P[:, 1] ** 2) / A**2))).max() < 1e-9
    )
    assert miss.max() < 1e-9 * C


@pytest.mark.parametrize("label", ["sphere", "prolate ellipsoid", "equiangular 5"])
def test_projected_corners_trace_back_onto_the_board_corners(label):
    r = rig(label, "near-pinhole")
    pattern, square, distance = BOARDS["near-pinhole"]
    ((Rb, tb, q),) = qr.place_boards(r, 1, pattern, square, distance, np.random.default_rng(3))
    P, d = r.trace(q)
    n = Rb[:, 2]
    on_board = P + (((tb - P) @ n) / (d @ n))[:, None] * d
    X = qr.board_object_points(pattern, square) @ Rb.T + tb
    assert np.abs(on_board - X).max() < 1e-6


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"{c[0]}, {c[1]}")
def test_omnicams_truth_traces_the_models_rays_within_1e_4_deg(case):
    """Not the ground truth's source, the truth for the bound: its rays are the model's."""
    assert truth_ray_gap_deg(rig(*case)) < 1e-4


# -- calibrate_pattern(mirror=None) ------------------------------------------------------------
#: Two fast cases: a sphere (no single viewpoint, Mei's xi > 1) and an equiangular mirror (no
#: conic: its asphere needs the polynomial terms), both behind the near-pinhole lens.
#: The last: its shape converges next to the convex aspheres' edge, where a central difference
#: of the adjustment stepped out of the family and refused the calibration (one-sided there now).
FAST = [
    ("sphere", "near-pinhole"),
    ("equiangular 5", "near-pinhole"),
    ("equiangular 5", "wide-angle"),
]


@functools.cache
def _fast_fit(i):
    return Fit(*FAST[i], seed=0)


@pytest.mark.parametrize("i", range(len(FAST)), ids=lambda i: ", ".join(FAST[i]))
def test_unknown_mirror_of_revolution_is_right_or_says_it_is_not(i):
    """Never silently wrong: the rays within 3 times their stated uncertainty of the truth, or
    a warning that the calibration is not to be trusted (a refusal is neither)."""
    fit = _fast_fit(i)
    assert fit.refused is None, fit.refused
    assert T._rays_within_their_uncertainty(fit) or T._says_it_is_wrong(fit), fit.report.warnings


def test_rays_determined_well_are_fitted_from_one_start_only():
    """The other starts cost 7 more fits: a near-pinhole rig's rays are determined to better
    than RAYS_WEAK_DEG, and it is fitted once; the wide-angle one's are not, and the note says
    what the other starts found."""
    near, wide = _fast_fit(0), _fast_fit(2)
    assert near.report.ray_std_deg[0] <= RAYS_WEAK_DEG
    assert not near.warned(STARTS_STATED)
    assert wide.warned(STARTS_STATED)


def test_a_central_fit_with_negative_xi_starts_the_generic_asphere():
    """Mei's model gives xi = -0.32 on these boards (no hyperboloid has xi <= 0): the rig is
    started from the Taylor model, not refused with 'xi must be in (0, 1) for a hyperbolic
    mirror' (what the hyperbolic start said)."""
    fit = Fit("equiangular 7", "wide-angle", seed=2)
    assert fit.refused is None, fit.refused
    assert fit.report.central.xi < 0
    assert fit.warned("which no hyperboloid has (0 to 1)")
    T._assert_rays_within_their_uncertainty(fit)


def test_unknown_paraboloid_behind_a_near_pinhole_is_started_again_from_the_image_centre():
    """The generic start's principal point is the Taylor centre, the image of the mirror's
    axis, 32 px from the principal point on this misaligned rig: the fit from there ends at
    0.35 px RMS, above the central Taylor model's 0.32, with its rays 1.44 deg off for 0.245
    stated; the second start from the image centre fits to 0.199 px, and is taken."""
    fit = Fit("paraboloid", "near-pinhole", seed=0)
    assert fit.refused is None, fit.refused
    assert fit.warned("started again from the principal point at the image centre")
    assert fit.warned("taken")
    T._assert_rays_within_their_uncertainty(fit)


def test_unknown_paraboloid_behind_a_wide_angle_lens_states_the_spread_of_other_starts():
    """The generic start's fit states 1.29 / 2.57 deg (linearised) with its rays 4.17 / 7.27
    deg off: the views determine the rays weakly (above RAYS_WEAK_DEG), so the rig is fitted
    from the other starts too, and fits as good as the one taken, with rays degrees from its,
    widen what is stated."""
    fit = Fit("paraboloid", "wide-angle", seed=2)
    assert fit.refused is None, fit.refused
    assert fit.warned(STARTS_STATED)
    assert STARTS_STATED in "".join(fit.report.notes)  # (stated, not doubted)
    T._assert_rays_within_their_uncertainty(fit)


def test_unknown_sphere_whose_first_fit_runs_off_is_fitted_from_the_other_starts():
    """Behind the wide-angle lens the first start's adjustment ends with the camera above the
    sphere (a rig that cannot be): refused before; the other starts' fits are as good as each
    other, and what is stated is their spread."""
    fit = Fit("sphere", "wide-angle", seed=0)
    assert fit.refused is None, fit.refused
    assert fit.warned("the first start's fit was refused")
    T._assert_rays_within_their_uncertainty(fit)


def test_unknown_prolate_ellipsoid_behind_a_wide_angle_lens_states_the_spread_of_turned_starts():
    """Every start along the focal length ends with the rays 10.73 / 15.58 deg off (median /
    worst) for 1.36 / 1.56 deg stated: a wrong minimum, not an information limit (with 0.001 px
    of noise they stay 11.7 deg off; docs/benchmarks.md). Started again with its mirror turned
    about its centre of curvature, a fit as good for these views ends degrees from it, and
    what is stated is their spread."""
    fit = Fit("prolate ellipsoid", "wide-angle", seed=0)
    assert fit.refused is None, fit.refused
    assert fit.warned(STARTS_STATED)
    assert fit.report.ray_std_deg[0] > 3.0 * 1.36  # (more than the linearised figure says)
    T._assert_rays_within_their_uncertainty(fit)
