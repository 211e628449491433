"""The non-central bundle adjustment of chessboard views: its parameters, residuals, solver and
uncertainty (beyond the paper).

:class:`BundleAdjustment` holds ``fx, fy, cx, cy`` (skew optional), the free distortion
coefficients, the 5-DOF posture (two small rotations of the mirror frame about its own x and y
axes and ``tvec``; the turn about the axis is put in the gauge of docs/conventions.md once, at
the end), every board's 6-DOF pose and, optionally, the mirror's shape (:mod:`.shape_params`: a
hyperboloid's ``a, b`` or an asphere's ``R, k`` and polynomial terms; ``rim_radius`` fixes the
scale) and the plane of the camera's reflection. Residuals, in px:
every corner's reprojection through the exact non-central projection
(:func:`omnicam.raytrace.project`, what ``camera.project`` runs), every rim point's orthogonal
distance to the image of the rim circle and, when the camera's own reflection is seen, its
outline residual (:mod:`omnicam.calibration.reflection`). The robust ``soft_l1`` cost is
minimised by MINPACK's Levenberg-Marquardt (:meth:`BundleAdjustment.solve`) with a Jacobian
by central differences, each taken where its parameter acts (:meth:`BundleAdjustment.jacobian`):
``K`` and ``D`` only turn the traced normalised coordinates into pixels again, the rim's
distances move with the rim image at fixed foot points, and a board's pose moves only its own
view's rows, so the columns of all boards are perturbed together (6 groups instead of 6 per
view, traced in one call).

What the fit knows: :func:`std_from_jacobian` (the parameters), :func:`ray_uncertainty` (the
viewing directions over the mirror's image, what panoramas use) and
:func:`pattern_uncertainty` (the information limit: the same at the truth, a Cramer-Rao bound).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import cv2
import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from .. import raytrace
from .._progress import Meter
from .._typing import FloatArray
from ..calibration.reflection import fit_circle, plane_radius
from ..camera import MisalignedCatadioptricCamera
from ..gauge import gauge_rotation
from ..raytrace import normalize, to_pixels
from .board_pose import object_points, rodrigues
from .geodesic_lm import geodesic_lm
from .intrinsics import check_pattern_size
from .shape_params import LOG_NAMES, shape_names, shape_steps, shape_vector, with_shape

__all__ = [
    "DIST_MODELS",
    "D_NAMES",
    "AdjustmentModel",
    "BundleAdjustment",
    "covariance",
    "n_coefficients",
    "pattern_uncertainty",
    "ray_uncertainty",
    "rim_curve",
    "rim_foot_normals",
    "rim_normalized",
    "robust_residuals",
    "std_from_jacobian",
]


#: OpenCV's distortion coefficients, in its order (``CALIB_RATIONAL_MODEL``'s 8).
D_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")

#: Distortion models: which of OpenCV's ``(k1, k2, p1, p2, k3, k4, k5, k6)`` are estimated.
#: ``radial6`` and ``rational`` are OpenCV's rational model, the radial factor
#: ``(1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)`` (a wide-angle lens),
#: without and with the tangential ``p1, p2``.
DIST_MODELS = {
    "none": (),
    "k1": (0,),
    "k1k2": (0, 1),
    "k1k2p1p2": (0, 1, 2, 3),
    "k1k2p1p2k3": (0, 1, 2, 3, 4),
    "radial6": (0, 1, 4, 5, 6, 7),
    "rational": (0, 1, 2, 3, 4, 5, 6, 7),
}


def n_coefficients(free_d, D_size=None) -> int:
    """The length of ``D`` an adjustment of the free coefficients ``free_d`` works with,
    ``D_size`` that of a given start (None: none): 0 (no distortion), 4, 5 or 8 (OpenCV's
    lengths; the shortest that holds both)."""
    if not free_d and D_size is None:
        return 0
    top = max([*free_d, (D_size or 4) - 1])
    return 4 if top < 4 else (5 if top == 4 else 8)


#: The power of the normalised radius each distortion coefficient multiplies, relative to the
#: pinhole's (``r^2`` for ``k1``, ``r`` times ``x`` or ``y`` for ``p1, p2``...): in pixels
#: ``k_j`` is ``kappa_j / f^p_j`` (:meth:`BundleAdjustment._solver_coordinates`).
_D_POWERS = {"k1": 2.0, "k2": 4.0, "p1": 1.0, "p2": 1.0, "k3": 6.0, "k4": 2.0, "k5": 4.0, "k6": 6.0}

#: Mirrors :meth:`BundleAdjustment.unpack` keeps by their shape vector: a Jacobian steps the
#: shape in a few of its columns only, and an asphere checks its convexity when it is made.
_SHAPES_KEPT = 64

#: Parameters that act after the mirror (the pinhole and its distortion).
_AFTER_MIRROR = frozenset(("fx", "fy", "cx", "cy", "skew", *D_NAMES))


def rim_normalized(R, t, mirror, phi) -> FloatArray:
    """Normalised coordinates ``(N, 2)`` of the rim circle's points at angles ``phi`` (rad,
    about the mirror axis) under the posture ``R, t``."""
    r, z = mirror.rim_radius, mirror.z_rim
    X = np.stack([r * np.cos(phi), r * np.sin(phi), np.full_like(phi, z)], axis=1) @ R.T + t
    return X[:, :2] / X[:, 2:3]


def rim_curve(K, D, R, t, mirror, phi) -> FloatArray:
    """Pixels ``(N, 2)`` of the rim circle's points at angles ``phi`` (:func:`rim_normalized`,
    :func:`to_pixels`)."""
    return to_pixels(rim_normalized(R, t, mirror, phi), K, D)


def rim_foot_normals(cam_K, D, R, t, mirror, u, phi) -> tuple[FloatArray, FloatArray]:
    """Orthogonal distances of pixels ``u`` to the rim image and the unit normals of the rim
    image at their foot points, ``(d (N,), n (N, 2))``, ``d = n . (u - c(phi))``; the foot
    parameters ``phi`` are refined in place by Newton's method.

    At the foot point the curve's tangent is orthogonal to ``u - c``, so a parameter ``p`` of
    the curve moves the distance by ``-n . dc/dp`` at fixed ``phi`` (the foot's own motion is
    along the tangent and changes it only to second order): what
    :meth:`BundleAdjustment.jacobian` uses."""
    h = 1e-4
    n = len(phi)

    def curve(ph):
        return rim_curve(cam_K, D, R, t, mirror, ph)

    for _ in range(4):
        c0, cp, cm = np.split(curve(np.concatenate([phi, phi + h, phi - h])), [n, 2 * n])
        d1 = (cp - cm) / (2 * h)
        d2 = (cp - 2 * c0 + cm) / (h * h)
        w = c0 - u
        g = np.einsum("ij,ij->i", w, d1)
        gp = np.einsum("ij,ij->i", d1, d1) + np.einsum("ij,ij->i", w, d2)
        phi -= g / gp
    c0, cp, cm = np.split(curve(np.concatenate([phi, phi + h, phi - h])), [n, 2 * n])
    tang = cp - cm
    nrm = np.stack([tang[:, 1], -tang[:, 0]], axis=1)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return np.einsum("ij,ij->i", u - c0, nrm), nrm


@dataclasses.dataclass(frozen=True)
class AdjustmentModel:
    """What the bundle adjustment estimates besides the posture and the boards' poses.

    Attributes
    ----------
    free_d : tuple of int
        The free coefficients of ``D = (k1, k2, p1, p2, k3, k4, k5, k6)``
        (:data:`DIST_MODELS`).
    n_d : int
        Coefficients of ``D`` (0: no distortion, 4, 5 or 8: :func:`n_coefficients`).
    fit_skew, fit_shape : bool
        Also the skew ``K[0, 1]``; also the mirror's shape (:mod:`.shape_params`).
    lens_px : (M, 2) ndarray or None
        Outline pixels of the camera's reflection (None: not used).
    lens_z : float or None
        Its plane, known (None: a parameter).
    """

    free_d: tuple
    n_d: int
    fit_skew: bool
    fit_shape: bool
    lens_px: np.ndarray | None = None
    lens_z: float | None = None


class BundleAdjustment:
    """Parameter vector, residuals and Jacobian of the non-central bundle adjustment.

    ``x = [fx, fy, cx, cy, (skew), d_free..., w1, w2, t_x, t_y, t_z, (shape), (lens_z),
    boards...]``
    with ``R = R0 R(w1, w2, 0)``: the mirror frame of the start turned about its own x and y
    axes, so the axis moves with no twist about it (the gauge's smallest rotation would add a
    twist of second order, which turns every board about the axis and bends the valley the
    fit must follow); ``tvec = t``; 6 numbers per board (``rvec_b, tvec_b``). The gauge of
    docs/conventions.md is imposed once, on the result (:meth:`to_gauge`).
    """

    def __init__(self, cam0, mirror, obj, views, rim_px, model):
        lens_px, lens_z = model.lens_px, model.lens_z
        free_d, n_d, fit_skew, fit_shape = model.free_d, model.n_d, model.fit_skew, model.fit_shape
        self.mirror, self.obj, self.views, self.rim_px = mirror, obj, views, rim_px
        self.lens_px = lens_px
        self.lens_z, self.fit_lens_z = lens_z, False
        if lens_px is not None and lens_z is None:  # its plane: started by a fit, then free
            Ki = np.linalg.inv(cam0.K)
            circle = fit_circle(
                mirror, cam0.R, cam0.tvec, normalize(lens_px, cam0.K, cam0.D), Ki[:2, :2]
            )
            self.lens_z = circle.z if math.isfinite(circle.rms) else None
            if self.lens_z is None:
                self.lens_px = None
            else:
                self.fit_lens_z = True
        self.free_d, self.n_d, self.fit_skew, self.fit_shape = free_d, n_d, fit_skew, fit_shape
        self.R0 = cam0.R.copy()
        self.D0 = np.zeros(n_d)
        if cam0.D is not None:  # padded with zeros to n_d (a start of 4 for the rational model)
            D = np.ravel(np.asarray(cam0.D, np.float64))
            self.D0 = np.concatenate([D, np.zeros(max(n_d - D.size, 0))])
        self.rim_phi = None
        self.last = None  # (x, traced(x)...) of the last evaluation
        self._shapes = {}  # mirrors of the last shape vectors (:meth:`unpack`), immutable
        K = cam0.K
        g = [K[0, 0], K[1, 1], K[0, 2], K[1, 2]] + ([K[0, 1]] if fit_skew else [])
        g += [self.D0[i] for i in free_d]
        g += [0.0, 0.0, *cam0.tvec]
        # the mirror's shape (:mod:`.shape_params`: a hyperboloid's ln a, ln b; an
        # asphere's ln R, k and polynomial terms)
        self.shape_names = shape_names(mirror) if fit_shape else []
        g += shape_vector(mirror) if fit_shape else []
        if self.fit_lens_z:
            g += [self.lens_z]
        self.n_global = len(g)
        self.names = (
            ["fx", "fy", "cx", "cy"]
            + (["skew"] if fit_skew else [])
            + [D_NAMES[i] for i in free_d]
            + ["w1", "w2", "tx", "ty", "tz"]
            + self.shape_names
            + (["lens_z"] if self.fit_lens_z else [])
        )
        self.x0_global = np.array(g, np.float64)
        self.fixed = set()  # names of global parameters held at their value
        self.skew0 = K[0, 1]
        n = len(obj)
        self.n_rows_view = 2 * n
        self.obs = np.concatenate(views) if len(views) else np.zeros((0, 2))

    def unpack(self, x) -> tuple[FloatArray, FloatArray | None, FloatArray, FloatArray, Any]:
        """``(K, D, R, tvec, mirror)`` of the parameter vector ``x``."""
        i = 0
        fx, fy, cx, cy = x[0:4]
        i = 4
        skew = self.skew0
        if self.fit_skew:
            skew = x[i]
            i += 1
        K = np.array([[fx, skew, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        D = None
        if self.n_d:
            D = self.D0.copy()
            for j in self.free_d:
                D[j] = x[i]
                i += 1
        w1, w2 = x[i : i + 2]
        R = self.R0 @ rodrigues(np.array([w1, w2, 0.0]))
        tvec = x[i + 2 : i + 5].copy()
        i += 5
        mirror = self.mirror
        if self.fit_shape:
            n = len(self.shape_names)
            key = tuple(x[i : i + n].tolist())
            mirror = self._shapes.get(key)
            if mirror is None:  # (the Jacobian's steps of all but the shape share one)
                if len(self._shapes) >= _SHAPES_KEPT:
                    self._shapes.clear()
                mirror = self._shapes[key] = with_shape(self.mirror, x[i : i + n])
            i += n
        return K, D, R, tvec, mirror

    def to_gauge(self, x, image_size=None) -> tuple[Any, list[tuple[np.ndarray, FloatArray]]]:
        """The camera in the gauge of docs/conventions.md and the board poses in its mirror frame.

        The fitted ``R`` and the gauge's ``R_g = gauge(R e_z)`` differ by a turn ``Z`` about
        the mirror axis, ``R = R_g Z``: the gauge's mirror frame holds ``Z X`` for the fit's
        ``X``, so every board becomes ``(Z R_b, Z t_b)``.
        """
        K, D, R, tvec, mirror = self.unpack(x)
        Rg = gauge_rotation(R[:, 2])
        Z = Rg.T @ R
        cam = MisalignedCatadioptricCamera(
            K, mirror, cv2.Rodrigues(Rg)[0].ravel(), tvec, D=D, image_size=image_size
        )
        poses = [
            (cv2.Rodrigues(Z @ rodrigues(b[:3]))[0].ravel(), Z @ b[3:]) for b in self.boards(x)
        ]
        return cam, poses

    def boards(self, x) -> FloatArray:
        """The boards' poses in ``x``, one ``(rvec_b, tvec_b)`` row of 6 per view."""
        return x[self.n_global :].reshape(-1, 6)

    def board_points(self, boards) -> FloatArray:
        """The corners ``(N, 3)`` of boards ``(V, 6)`` in the mirror frame, view by view."""
        return np.concatenate([self.obj @ rodrigues(b[:3]).T + b[3:] for b in boards])

    def normalized_corners(self, x, points=None) -> FloatArray:
        """The undistorted normalised coordinates ``(N, 2)`` of mirror-frame ``points`` (default:
        every board's corners, :meth:`board_points`) under the posture and mirror of ``x``,
        through the exact non-central projection (NaN where the rig cannot see it): what
        ``K`` and ``D`` turn into pixels."""
        _, _, R, tvec, mirror = self.unpack(x)
        if points is None:
            points = self.board_points(self.boards(x))
        # the exact non-central projection of the camera's project(), on the fit's frame
        return raytrace.project(
            np.ascontiguousarray(points), False, np.eye(3), None, R, tvec, -R.T @ tvec, mirror
        )

    def corners_from_pixels(self, px) -> FloatArray:
        """The corner residuals (px; 50 where the rig cannot see a corner) of ``S`` sets of
        projected corners ``px`` (``(S N, 2)``, each set view by view): ``(S, 2 N)``."""
        r = px.reshape(-1, *self.obs.shape) - self.obs
        r[~np.isfinite(r)] = 50.0  # a corner the rig cannot see: a large, constant residual
        return r.reshape(len(r), -1)

    def corner_residuals(self, x) -> FloatArray:
        """Every corner's reprojection error (px; 50 where the rig cannot see it), through the exact
        non-central projection."""
        K, D, _, _, _ = self.unpack(x)
        return self.corners_from_pixels(to_pixels(self.normalized_corners(x), K, D))[0]

    def rim_start(self, K, R, tvec, mirror) -> FloatArray:
        """The rim points' foot parameters at the start, by dense sampling (kept, and refined
        at every evaluation by :func:`rim_foot_normals`)."""
        if self.rim_phi is None:
            ph = np.linspace(0, 2 * np.pi, 3600, endpoint=False)
            c = to_pixels(rim_normalized(R, tvec, mirror, ph), K, None)
            j = np.argmin(((self.rim_px[:, None, :] - c[None]) ** 2).sum(-1), axis=1)
            self.rim_phi = ph[j]
        return self.rim_phi.copy()

    def lens_residuals(self, x) -> FloatArray:
        """The camera's reflection (:mod:`.reflection`): ``(rho(u) - r) / |grad rho|`` px for every
        outline pixel (50 where its reflected ray does not cross the plane), ``rho`` the radius
        at which its reflected ray crosses the plane of the coaxial circle (``z`` known, or the
        parameter ``lens_z`` started by :func:`.reflection.fit_circle` under the start posture)
        and ``r`` fitted in closed form at each evaluation."""
        K, D, R, tvec, mirror = self.unpack(x)
        Ki = np.linalg.inv(K)
        xn = normalize(self.lens_px, K, D)
        z = x[self.names.index("lens_z")] if self.fit_lens_z else self.lens_z
        rho, g = plane_radius(mirror, R, tvec, xn, z, Ki[:2, :2])
        ok = np.isfinite(rho) & np.isfinite(g) & (g > 0)
        r = np.full(len(rho), 50.0)  # an outline pixel whose ray misses the plane: as a corner
        if ok.sum() >= 3:  # the rig cannot see (not 0, a perfect fit the solver would seek)
            w = 1.0 / g[ok] ** 2
            r[ok] = (rho[ok] - float((w * rho[ok]).sum() / w.sum())) / g[ok]
        return r

    def traced(self, x) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """``(xn, phi, d, n)`` at ``x``: the corners' normalised coordinates
        (:meth:`normalized_corners`), the rim points' foot parameters, distances and normals
        (:func:`rim_foot_normals`); the last ``x``'s are kept, since MINPACK asks for the
        Jacobian where it last evaluated the residuals."""
        if self.last is None or not np.array_equal(self.last[0], x):
            K, D, R, tvec, mirror = self.unpack(x)
            phi = self.rim_start(K, R, tvec, mirror)
            d, nrm = rim_foot_normals(K, D, R, tvec, mirror, self.rim_px, phi)
            self.last = (np.array(x, np.float64), self.normalized_corners(x), phi, d, nrm)
        return self.last[1:]

    def residuals(self, x) -> FloatArray:
        """The corner, rim and (when used) outline residuals, px, in that order; 50 px each
        where ``x`` holds a shape no mirror has (a step of the solver out of the mirror
        family's range, :func:`.shape_params.with_shape`), as for a corner the rig cannot
        see."""
        try:
            K, D, _, _, _ = self.unpack(x)
        except ValueError:
            n = len(self.obs) * 2 + len(self.rim_px)
            return np.full(n + (0 if self.lens_px is None else len(self.lens_px)), 50.0)
        xn, _, d, _ = self.traced(x)
        parts = [self.corners_from_pixels(to_pixels(xn, K, D))[0], d]
        if self.lens_px is not None:
            parts.append(self.lens_residuals(x))
        return np.concatenate(parts)

    def steps(self, x) -> FloatArray:
        """Central-difference steps of the parameters (:meth:`jacobian`)."""
        h = np.empty_like(x)
        g = self.n_global
        shape_h = dict(zip(self.shape_names, shape_steps(self.mirror)))
        for k, name in enumerate(self.names):
            if name in ("fx", "fy", "cx", "cy", "skew"):
                h[k] = 1e-6 * max(abs(x[0]), 1.0)
            elif name in ("w1", "w2"):
                h[k] = 1e-7
            elif name in ("tx", "ty", "tz", "lens_z"):
                h[k] = 1e-6 * self.mirror.rim_radius
            elif name in shape_h:  # (:func:`.shape_params.shape_steps`)
                h[k] = shape_h[name]
            else:
                h[k] = 1e-7
        B = h[g:].reshape(-1, 6)
        B[:, :3] = 1e-7
        B[:, 3:] = 1e-6 * self.mirror.rim_radius
        return h

    def imaged(self, x, phi, points, normalized=None) -> tuple[FloatArray, FloatArray]:
        """The corner residuals of the boards' corners ``points`` (mirror frame) and the pixels
        of the rim circle's points at ``phi`` under ``x``; ``normalized``: their normalised
        coordinates ``(corners, rim)`` already traced (when only ``K`` or ``D`` differ from
        where they were)."""
        K, D, R, tvec, mirror = self.unpack(x)
        if normalized is None:
            normalized = (
                self.normalized_corners(x, points),
                rim_normalized(R, tvec, mirror, phi),
            )
        n = len(normalized[0])
        px = to_pixels(np.concatenate(normalized), K, D)
        return self.corners_from_pixels(px[:n])[0], px[n:]

    def steps_within_the_family(self, x, k, step) -> tuple[FloatArray, FloatArray, float]:
        """``(x_plus, x_minus, their distance)`` of the central difference in parameter ``k``;
        where one side holds a shape no mirror of the family has (an asphere's step past the
        convex ones), the one-sided difference from ``x`` on the other side."""
        xp, xm = x.copy(), x.copy()
        xp[k] += step
        xm[k] -= step
        if not self.fit_shape:
            return xp, xm, 2.0 * step
        ok = []
        for xs in (xp, xm):
            try:
                self.unpack(xs)
                ok.append(True)
            except ValueError:
                ok.append(False)
        if ok == [True, False]:
            return xp, x.copy(), step
        if ok == [False, True]:
            return x.copy(), xm, step
        return xp, xm, 2.0 * step

    def jacobian(self, x) -> FloatArray:
        """Central differences, evaluated where each parameter acts; columns of parameters
        held fixed (``self.fixed``) are zero.

        - ``K`` and ``D`` act after the mirror: their columns only turn the normalised
          coordinates of the corners (:meth:`normalized_corners`, traced once) and of the rim
          into pixels again.
        - The rim: at the foot points the distance moves by ``-n . dc/dp`` (the rim image's
          point ``c`` at fixed ``phi``, :func:`rim_foot_normals`), one projection of the rim
          circle per step instead of a foot search.
        - The boards: a board's pose moves only its own view's rows, so their columns are
          perturbed in 6 groups (block structure), all 12 steps traced in one call.
        """
        h = self.steps(x)
        g, nv, rows = self.n_global, len(self.views), self.n_rows_view
        nc, nr = nv * rows, len(self.rim_px)
        J = np.zeros((nc + nr + (0 if self.lens_px is None else len(self.lens_px)), len(x)))
        K, D, R, tvec, mirror = self.unpack(x)
        xn, phi, _, nrm = self.traced(x)
        xr = rim_normalized(R, tvec, mirror, phi)
        pts = self.board_points(self.boards(x))  # (the posture's steps do not move them)
        for k in [i for i, name in enumerate(self.names) if name not in self.fixed]:
            xp, xm, span = self.steps_within_the_family(x, k, h[k])
            if self.lens_px is not None:
                J[nc + nr :, k] = (self.lens_residuals(xp) - self.lens_residuals(xm)) / span
            if self.names[k] == "lens_z":  # the corners and the rim do not see its plane
                continue
            after = self.names[k] in _AFTER_MIRROR
            cp, rp = self.imaged(xp, phi, pts, (xn, xr) if after else None)
            cm, rm = self.imaged(xm, phi, pts, (xn, xr) if after else None)
            J[:nc, k] = (cp - cm) / span
            J[nc : nc + nr, k] = -np.einsum("ij,ij->i", nrm, rp - rm) / span
        # the boards: 6 groups of steps (+ and -), one trace of all 12 sets of corners
        B = self.boards(x)
        hb = h[g:].reshape(-1, 6)
        sets = []
        for j in range(6):
            for sign in (1.0, -1.0):
                Bs = B.copy()
                Bs[:, j] += sign * hb[:, j]
                sets.append(self.board_points(Bs))
        px = to_pixels(self.normalized_corners(x, np.concatenate(sets)), K, D)
        r = self.corners_from_pixels(px).reshape(6, 2, nv, rows)
        diff = (r[:, 0] - r[:, 1]) / (2 * hb.T[:, :, None])  # (6, views, rows)
        for v in range(nv):
            J[v * rows : (v + 1) * rows, g + 6 * v : g + 6 * v + 6] = diff[:, v].T
        return J

    def solve(self, x0, f_scale=1.0, max_nfev=None, tol=1e-10, accelerate=None) -> OptimizeResult:
        """The ``soft_l1`` fit of scale ``f_scale`` px, the global parameters named in
        ``self.fixed`` held at ``x0``; :meth:`jacobian` gives the derivatives.

        The solver minimises a plain sum of squares; the robust cost ``sum rho(r^2)``,
        ``rho(s) = 2 f^2 (sqrt(1 + s / f^2) - 1)``, is one, of the residuals
        ``z = sign(r) sqrt(rho(r^2))`` (:func:`robust_residuals`), whose Jacobian is
        ``dz/dr J``, so the minimum is the robust one exactly.

        With the mirror's shape fixed, or ``accelerate=False``: MINPACK's Levenberg-Marquardt
        (``scipy.optimize.least_squares(method="lm")``). With it free (``accelerate`` None,
        the default, or True) the fit follows the valley where the focal length, the
        camera's distance, the shape and the distortion trade: Levenberg-Marquardt with
        geodesic acceleration (:mod:`.geodesic_lm`), in the coordinates
        :meth:`_solver_coordinates` gives (the distortion in pixel units, which the valley
        bends less). (The trust-region solvers of ``least_squares`` with the
        ``soft_l1`` loss, with ``jac_sparsity`` or this Jacobian, exact or ``lsmr`` steps,
        stopped at their 100 evaluations still descending along the valley; MINPACK's
        reaches KaidanOmni's minimum in 338, this one in 109:
        ``benchmarks/bench_chessboard_real.py``.)

        ``tol`` is the solvers' ``ftol``, ``xtol`` and ``gtol``; ``max_nfev`` (default 100
        times the free parameters plus one) counts the residuals' evaluations. Returns the
        ``OptimizeResult`` with ``x`` the whole parameter vector."""
        x0 = np.asarray(x0, np.float64)
        free = np.ones(len(x0), bool)
        free[[k for k, n in enumerate(self.names) if n in self.fixed]] = False
        accelerated = self.fit_shape if accelerate is None else accelerate
        to_x, chain = self._solver_coordinates(x0, accelerated)
        y0 = to_x(x0, inverse=True)

        def full(yf):
            y = y0.copy()
            y[free] = yf
            return to_x(y)

        last = {}  # the solvers ask for the Jacobian where they last evaluated the residuals

        meter = Meter(f"adjustment of {int(free.sum())} parameters")  # progress (silent by default)

        def fun(yf):
            last["y"], last["z"] = yf.copy(), robust_residuals(self.residuals(full(yf)), f_scale)
            meter(float(last["z"][0] @ last["z"][0]))  # progress: the robust cost
            return last["z"][0]

        def jac(yf):
            if "y" not in last or not np.array_equal(last["y"], yf):
                fun(yf)
            x = full(yf)
            return chain(self.jacobian(x), x)[:, free] * last["z"][1][:, None]

        if accelerated:
            n_max = max_nfev if max_nfev is not None else 100 * (int(free.sum()) + 1)
            sol = geodesic_lm(fun, jac, y0[free], n_max, tol)
        else:
            sol = least_squares(
                fun,
                y0[free],
                jac=jac,
                method="lm",
                x_scale="jac",
                max_nfev=max_nfev,
                xtol=tol,
                ftol=tol,
                gtol=tol,
            )
        sol.x = full(sol.x)
        sol.cost = float(sol.cost)
        meter.done(2.0 * sol.cost)
        return sol

    def _solver_coordinates(self, x0, accelerated):
        """``(to_x, chain)``: the coordinates ``y`` the solver works in and back, and the chain
        rule of a Jacobian in ``x`` to one in ``y``.

        For the accelerated solver, each free distortion coefficient is held in pixel units at
        the start's focal length ``f0``: ``k_j = kappa_j (fx / f0)^p_j`` with ``p_j`` the power
        of ``r`` it multiplies relative to the pinhole's (:data:`_D_POWERS`), so a step of
        ``fx`` at fixed ``kappa`` keeps the image's radial profile in pixels, which the
        valley's walk to a shorter ``f`` otherwise bends with ``k1, k2`` tens of times their
        value (KaidanOmni: 36 Jacobians instead of 54). For MINPACK's: ``y = x``."""
        powers = np.zeros(len(x0))
        if accelerated:  # (a coefficient held stays at its value in x)
            for k, name in enumerate(self.names):
                powers[k] = 0.0 if name in self.fixed else _D_POWERS.get(name, 0.0)
        if not powers.any():
            return (lambda x, inverse=False: x), (lambda J, x: J)
        f0 = float(x0[0])
        live = powers > 0

        def to_x(v, inverse=False):
            out = np.array(v, np.float64)
            s = (v[0] / f0) ** powers[live]
            out[live] = v[live] / s if inverse else v[live] * s
            return out

        def chain(J, x):
            s = x[0] / f0
            Jy = J.copy()
            Jy[:, live] = J[:, live] * s ** powers[live]
            # dk_j/dfx at fixed kappa = p_j k_j / fx
            Jy[:, 0] += J[:, live] @ (powers[live] * x[live] / x[0])
            return Jy

        return to_x, chain


def robust_residuals(r, f_scale) -> tuple[FloatArray, FloatArray]:
    """``z = sign(r) sqrt(rho(r^2))`` for the ``soft_l1`` loss ``rho(s) = 2 f^2 (sqrt(1 +
    s / f^2) - 1)``, so that ``sum z^2`` is the robust cost, and ``dz/dr``.

    With ``q = sqrt(1 + (r / f)^2)``: ``z = r sqrt(2 / (1 + q))`` (``z ~ r`` for ``|r| << f``,
    no cancellation) and ``dz/dr = r rho'(r^2) / z = sqrt((1 + q) / 2) / q``."""
    q = np.sqrt(1.0 + (r / f_scale) ** 2)
    return r * np.sqrt(2.0 / (1.0 + q)), np.sqrt((1.0 + q) / 2.0) / q


def covariance(J, row_sigma, unweighted=False) -> FloatArray:
    """The covariance of the least-squares estimate from residuals with Jacobian ``J`` and
    independent noise of ``row_sigma`` per row. Weighted by ``1 / row_sigma^2`` (the default):
    ``(J^T W J)^-1``, the Cramer-Rao bound. ``unweighted``: of the fit that weighs every row
    alike (the adjustment's), ``A^-1 (J^T S J) A^-1`` with ``A = J^T J``, ``S =
    diag(row_sigma^2)`` (the sandwich; the bound's when all sigmas are equal). Columns scaled
    to unit norm; a parameter no residual depends on (a zero column) gets NaN variance instead
    of a number the regularisation made up."""
    n = J.shape[1]
    sig = np.asarray(row_sigma, np.float64)
    Jw = J if unweighted else J / sig[:, None]
    scale = np.linalg.norm(Jw, axis=0)
    live = scale > 0
    Js = Jw[:, live] / scale[live]
    m = int(live.sum())
    Ainv = np.linalg.solve(np.einsum("ij,ik->jk", Js, Js) + 1e-12 * np.eye(m), np.eye(m))
    if unweighted:
        Ainv = Ainv @ np.einsum("ij,i,ik->jk", Js, sig * sig, Js) @ Ainv
    cov = np.full((n, n), math.nan)
    cov[np.ix_(live, live)] = Ainv / np.outer(scale[live], scale[live])
    return cov


def std_from_jacobian(
    adj, x, J, row_sigma, unweighted=False
) -> tuple[dict[str, float], FloatArray]:
    """Standard deviations (:func:`covariance`, ``unweighted`` as there) of the named global
    parameters of ``adj`` at ``x``, the mirror axis (``axis_deg``, RMS angle) and the camera
    centre in the mirror frame (``origin``, RMS distance, the 5 posture parameters linearised
    through ``C = -R^T tvec``, eq. 17); and the covariance of the global parameters."""
    cov = covariance(J, row_sigma, unweighted)
    var = np.diag(cov)
    std = {}
    for k, name in enumerate(adj.names):
        if name in ("w1", "w2", "tx", "ty", "tz"):
            continue
        std[name] = float(math.sqrt(max(var[k], 0.0))) if math.isfinite(var[k]) else math.nan
        if name in LOG_NAMES:  # the parameter is the logarithm
            std[name] *= math.exp(x[k])
    ip = adj.names.index("w1")
    std["axis_deg"] = math.degrees(math.sqrt(max(var[ip] + var[ip + 1], 0.0)))

    def centre(xx):
        _, _, R, t, _ = adj.unpack(xx)
        return -R.T @ t

    G = np.zeros((3, 5))
    for k in range(5):
        hk = 1e-7 if k < 2 else 1e-6 * adj.mirror.rim_radius
        xp, xm = x.copy(), x.copy()
        xp[ip + k] += hk
        xm[ip + k] -= hk
        G[:, k] = (centre(xp) - centre(xm)) / (2 * hk)
    std["origin"] = float(math.sqrt(max(np.trace(G @ cov[ip : ip + 5, ip : ip + 5] @ G.T), 0.0)))
    g = adj.n_global
    return std, cov[:g, :g]


def ray_uncertainty(adj, x, cov_global, image_size, n=24) -> tuple[float, float]:
    """Standard deviation (deg) of the viewing directions over the mirror's image: the rays of
    an ``n x n`` grid of pixels (those that see the mirror, eqs. 6-19), each linearised in the
    global parameters (central differences) and propagated through their covariance
    ``cov_global``. Returns ``(median, max)``; NaN when the covariance is not finite."""
    w, h = (int(v) for v in image_size)
    u, v = np.meshgrid(np.linspace(0, w - 1, n), np.linspace(0, h - 1, n))
    px = np.stack([u.ravel(), v.ravel()], axis=1)

    def rays(xx, pixels):
        K, D, R, t, mirror = adj.unpack(xx)
        return raytrace.trace(pixels, K, D, R, -R.T @ t, mirror)[1]

    px = px[np.isfinite(rays(x, px)).all(axis=1)]
    live = np.isfinite(np.diag(cov_global))
    if len(px) == 0 or not live.any():
        return math.nan, math.nan
    steps = adj.steps(x)
    G = np.zeros((len(px), 3, adj.n_global))
    for k in np.flatnonzero(live):
        xp, xm, span = adj.steps_within_the_family(x, k, steps[k])
        G[:, :, k] = (rays(xp, px) - rays(xm, px)) / span
    C = cov_global[np.ix_(live, live)]
    Gl = G[:, :, live]
    var = np.einsum("nik,kl,nil->n", Gl, C, Gl)
    deg = np.degrees(np.sqrt(np.maximum(var[np.isfinite(var)], 0.0)))
    if len(deg) == 0:
        return math.nan, math.nan
    return float(np.median(deg)), float(np.max(deg))


def pattern_uncertainty(
    camera,
    pattern_size,
    square_size,
    board_poses,
    rim_points,
    sigma_corner,
    sigma_rim,
    *,
    lens_points=None,
    lens_z=None,
    sigma_lens=None,
    dist_model="k1k2p1p2",
    refine_mirror_shape=False,
) -> dict[str, float]:
    """The information limit of :func:`calibrate_pattern`: a posteriori standard deviations of
    its bundle adjustment evaluated at the truth (a Cramer-Rao bound).

    The Jacobian of the adjustment's residuals (corners, rim and, with ``lens_points``, the
    camera's reflection) at the true ``camera`` and board poses, every row weighted by its
    noise (``sigma_corner`` px per corner coordinate, ``sigma_rim`` px per rim point,
    ``sigma_lens`` px per outline point): ``cov = (J^T W J)^-1``. No estimate can be
    consistently better than these standard deviations on such data; when they exceed a
    target, the data, not the solver, are what is missing.

    Parameters
    ----------
    camera : MisalignedCatadioptricCamera
        The truth.
    pattern_size, square_size
        As :func:`calibrate_pattern`.
    board_poses : list of (rvec_b, tvec_b)
        The true board poses (mirror frame).
    rim_points : (M, 2) array_like
        Pixels on the rim (their foot points are taken on the true rim image).
    sigma_corner, sigma_rim : float
    lens_points : (L, 2) array_like, optional
        Outline pixels of the camera's reflection.
    lens_z : float, optional
        Its circle's plane, known (None: fitted, as :func:`calibrate_pattern` does).
    sigma_lens : float, optional
    dist_model : str
    refine_mirror_shape : bool

    Returns
    -------
    dict
        The ``std`` of :class:`PatternReport` (``fx, fy, cx, cy``, distortion, ``axis_deg``,
        ``origin``, ``a, b`` with ``refine_mirror_shape``), and the bound of the viewing
        directions over the mirror's image (the report's ``ray_std_deg``, by
        :func:`ray_uncertainty`): ``ray_deg_median`` and ``ray_deg_max`` (NaN without the
        camera's ``image_size``).
    """
    cols, rows = check_pattern_size(pattern_size)
    if dist_model not in DIST_MODELS:
        raise ValueError(f"dist_model must be one of {sorted(DIST_MODELS)}, got {dist_model!r}")
    free_d = DIST_MODELS[dist_model]
    n_d = n_coefficients(free_d, None if camera.D is None else np.size(camera.D))
    obj = object_points((cols, rows), square_size)
    views = [
        camera.project(obj @ rodrigues(rv).T + np.asarray(tv, np.float64)) for rv, tv in board_poses
    ]
    lens_px = None if lens_points is None else np.asarray(lens_points, np.float64).reshape(-1, 2)
    model = AdjustmentModel(free_d, n_d, False, refine_mirror_shape, lens_px, lens_z)
    rim_px = np.asarray(rim_points, np.float64).reshape(-1, 2)
    adj = BundleAdjustment(camera, camera.mirror, obj, views, rim_px, model)
    x = np.concatenate(
        [adj.x0_global] + [np.concatenate([np.ravel(rv), np.ravel(tv)]) for rv, tv in board_poses]
    )
    J = adj.jacobian(x)
    nc = len(views) * adj.n_rows_view
    sig = np.full(J.shape[0], float(sigma_corner))
    sig[nc : nc + len(adj.rim_px)] = float(sigma_rim)
    if adj.lens_px is not None:
        sig[nc + len(adj.rim_px) :] = float(sigma_lens)
    std, cov = std_from_jacobian(adj, x, J, sig)
    std["ray_deg_median"], std["ray_deg_max"] = (
        (math.nan, math.nan)
        if camera.image_size is None
        else ray_uncertainty(adj, x, cov, camera.image_size)
    )
    return std
