"""K, D and the mirror posture from chessboards seen through the mirror (beyond the paper).

For rigs whose camera cannot be calibrated without the mirror. The pipeline of
:func:`calibrate_pattern`:

1. **the rim** (eqs. 20-22): :func:`.rim.detect_rim` on the first image where it is found (or
   the given ``boundary_points``);
2. **the boards and a start without an initial-value problem**: OpenCV's detectors on every raw
   image (:func:`.pattern_detect.detect_pattern`); with ``mirror=None`` the central start of
   :mod:`.central` (``cv2.omnidir.calibrate`` of those corners; ``xi`` gives the mirror's shape,
   its focal length the pinhole's, the rim's image the mirror's size at ``rim_radius``, which
   fixes the scale). With a mirror and without ``K``, the focal length from the rim's
   size (an aligned rig images the rim circle of radius ``r`` at depth ``z_rim + c`` with radius
   ``f r / (z_rim + c)`` px) and the principal point at the image centre; the posture from the
   rim by :func:`omnicam.calibration.calibrate` (Chen's method, eqs. 23-42); every board's pose
   from its corners' rays (:func:`board_pose_from_rays`: a central PnP from the best-fit
   viewpoint, then the non-central point-to-ray fit);
3. **the non-central bundle adjustment** (:class:`_Adjustment`): ``fx, fy, cx, cy`` (skew
   optional), the free distortion coefficients, the 5-DOF posture (two small rotations of the
   mirror frame about its own x and y axes and the three components of ``tvec``; the rotation
   about the axis is put in the gauge of docs/conventions.md once, at the end), every board's 6-DOF
   pose and, optionally, the mirror's ``a, b`` (``rim_radius`` fixes the scale). Residuals, in
   px: every corner's reprojection through the exact non-central projection
   (:func:`omnicam.raytrace.project`, what ``camera.project`` runs), every rim point's
   orthogonal distance to the image of the rim circle (so the rim keeps constraining) and,
   when the camera's own reflection is seen, its outline residual (:mod:`.reflection`, a
   circle coaxial with the optical axis). Levenberg-Marquardt with the robust ``soft_l1``
   loss (IRLS weights) and a Jacobian by central differences that uses its block structure: a
   board's pose moves only its own view's rows,
   so the columns of all boards are perturbed together (6 groups instead of ``6 n``). A first
   stage holds the principal point and the distortion at the start, a second frees them;
4. views whose RMS stands out are dropped (or only reported) and the fit is run again; boards
   not found yet are looked for in the views of the fitted camera, and found ones fitted again;
5. a :class:`PatternReport`: RMS overall and per view, poses, standard deviations from
   ``sigma^2 (J^T J)^-1``, warnings.

What the data determine (``benchmarks/bench_pattern.py``, which prints the bound of
:func:`pattern_uncertainty`: the adjustment's a posteriori standard deviations at the truth, a
Cramer-Rao bound): a turn of the camera about its centre is a shift of the principal point to
first order, for the boards and the rim alike; only second-order perspective over the camera's
narrow field (the mirror fills about +-20 deg) tells them apart, tangential distortion
(``p1, p2``) absorbs even that, and ``k1, k2`` trade against the focal length. The outline of
the camera's reflection separates tilt and shift (it moves with twice the tilt); it is detected
in every image and pooled. On the benchmark's rig (12 views of 1000x1000, 0.2 px corner noise,
the lens barrel's outline pooled over the views, its plane known) the bound is:
``dist_model="k1k2p1p2"`` fx 0.83 %, principal point 4.9 px, axis 0.28 deg, origin 0.54 mm
(estimates, median of 5 trials: 0.59 %, 4.1 px, 0.20 deg, 0.36 mm); ``"k1k2"`` 0.78 %, 2.6 px,
0.12 deg, 0.51 mm; ``"none"`` 0.19 %, 0.35 px, 0.014 deg, 0.17 mm (all met by the estimates:
0.07 %, 0.32 px, 0.011 deg, 0.07 mm); with the plane fitted 8.3 px and 0.38 deg; without the
reflection 69 px and 3.7 deg; with ``find_pattern``'s corners (0.06 px) 0.25 %, 3.8 px,
0.22 deg, 0.17 mm. The estimates follow these bounds, while the rays (what a panorama uses)
stay accurate to 0.02-0.2 deg in every case. The reported standard deviations say which case a
calibration is in.
"""

from __future__ import annotations

import dataclasses
import math
import os
import warnings as _warnings

import cv2
import numpy as np
from scipy.optimize import least_squares

from ..raytrace import trace
from .boards import board_pose_from_rays, object_points, rodrigues
from .ellipse import conic_distance
from .heldout import HeldOut, cross_validate
from .intrinsics import _pattern  # one check of pattern_size (cv2.findChessboardCorners)
from .pattern_detect import detect_pattern
from .plausibility import check_plausibility
from .rim import detect_rim, fit_rim

__all__ = [
    "DIST_MODELS",
    "PatternReport",
    "calibrate_pattern",
    "pattern_uncertainty",
]

#: Distortion models: which of OpenCV's ``(k1, k2, p1, p2, k3)`` are estimated.
DIST_MODELS = {
    "none": (),
    "k1": (0,),
    "k1k2": (0, 1),
    "k1k2p1p2": (0, 1, 2, 3),
    "k1k2p1p2k3": (0, 1, 2, 3, 4),
}
_MIN_VIEWS = 3
_EDGE_ON_SIN = math.sin(math.radians(5.0))  # a board plane within 5 deg of the viewpoint
_N_RIM = 360  # rim points kept for the adjustment
#: Detections of the camera's reflection farther than this (px, centre or radius) from the
#: median of all images' are not pooled.
_LENS_AGREE_PX = 1.0
#: A relative standard deviation of ``a`` or ``b`` above this: the shape is not determined.
_SHAPE_WEAK = 0.01
#: Rounds of detection and adjustment: a board the views of the fitted camera find that the
#: start's did not is added and the rig fitted again, until no new board is found.
_DETECT_ROUNDS = 3


@dataclasses.dataclass(frozen=True, eq=False)
class PatternReport:
    """Outcome of :func:`calibrate_pattern`.

    Attributes
    ----------
    rms : float
        RMS corner reprojection error over the views used, px.
    view_rms : dict
        ``{image index: RMS px}`` of every view used.
    corners_used : dict
        ``{image index: number of corners}`` of every view used.
    board_poses : dict
        ``{image index: (rvec_b, tvec_b)}``, ``X_mirror = R(rvec_b) X_board + tvec_b``.
    image_points : list
        Per input image the ``(N, 1, 2)`` float32 corners detected or given (None if none).
    reprojected : dict
        ``{image index: (N, 1, 2) float64}`` corners reprojected by the calibrated camera.
    rim_points : (M, 2) float64 ndarray
        The rim points used.
    rim_rms : float
        RMS distance of the rim points to the calibrated rim image, px.
    std : dict
        Standard deviations (1 sigma, from ``sigma^2 (J^T J)^-1`` with ``sigma^2`` the residual
        variance): ``fx, fy, cx, cy`` (px), ``skew`` if estimated, ``k1``... of the free
        distortion coefficients, ``axis_deg`` (RMS angle of the mirror axis), ``origin`` (RMS
        distance of the camera centre in the mirror frame, mirror units), ``a, b`` with
        ``refine_mirror_shape``.
    warnings : tuple of str
    dropped : dict
        ``{image index: reason}`` of the views left out.
    nfev : int
        Residual evaluations of the last adjustment.
    camera : MisalignedHyperbolicCamera
    start : MisalignedHyperbolicCamera
        The start of the adjustment (K from the rim, posture from Chen's method).
    lens_rms : float
        RMS outline residual of the camera's reflection, px (NaN when not used).
    lens_note : str
        Whether and how the camera's reflection was used.
    central : CentralFit or None
        The central start (:func:`.central.fit_central` of the corners found on the raw
        images), or None when it could not be made.
    found_by : dict
        ``{image index: how its corners were found}``: ``"given"``, one of
        :data:`.pattern_detect.METHODS` (``"raw"``, ``"raw-sb"``: OpenCV's detectors on the
        image as it is; ``"views"``: in the start camera's unwarped views) or ``"views (fitted
        camera)"`` (a later round, in the views of the camera fitted to the boards found
        before).
    ray_std_deg : (float, float)
        Standard deviation of the viewing directions over the mirror's image (deg; median,
        worst), the parameters' covariance propagated to the rays (what panoramas use): small
        even when ``a, b`` or ``fx`` are not.
    names : dict
        ``{image index: file name}`` of the images given as paths (the table shows them).
    heldout : HeldOut or None
        With ``calibrate_pattern(heldout=k)``, the k-fold held-out corner RMS of the views
        used (:mod:`.heldout`), ``cv2.omnidir``'s on the same folds beside it.
    """

    rms: float
    view_rms: dict
    corners_used: dict
    board_poses: dict
    image_points: list
    reprojected: dict
    rim_points: np.ndarray
    rim_rms: float
    std: dict
    warnings: tuple
    dropped: dict
    nfev: int
    camera: object
    start: object
    lens_rms: float = math.nan
    lens_note: str = ""
    found_by: dict = dataclasses.field(default_factory=dict)
    central: object = None
    heldout: HeldOut | None = None
    ray_std_deg: tuple = (math.nan, math.nan)
    names: dict = dataclasses.field(default_factory=dict)

    def table(self, names=None):
        """The per-view table as text: image, corners, RMS px, distance and elevation of the
        board and how it was found, or why the view was dropped. ``names``: a sequence of the
        images' names (default :attr:`names`, else the indices)."""
        names = dict(enumerate(names)) if names is not None else self.names
        rows = sorted(set(self.view_rms) | set(self.dropped))
        label = {i: str(names.get(i, i)) for i in rows}
        wide = max([5] + [len(v) for v in label.values()])
        lines = [
            f"{'image':>{wide}} {'corners':>7} {'rms px':>8} {'dist':>8} {'elev deg':>8}  found by"
        ]
        for i in rows:
            if i in self.view_rms:
                t = np.asarray(self.board_poses[i][1])
                el = math.degrees(math.atan2(t[2], math.hypot(t[0], t[1])))
                lines.append(
                    f"{label[i]:>{wide}} {self.corners_used[i]:>7} {self.view_rms[i]:>8.3f} "
                    f"{np.linalg.norm(t):>8.1f} {el:>8.1f}  {self.found_by.get(i, '-')}"
                )
            else:
                lines.append(f"{label[i]:>{wide}} {'-':>7} {'-':>8}   dropped: {self.dropped[i]}")
        return "\n".join(lines)

    def draw(self, image, index):
        """BGR overlay of view ``index``: detected corners (green circles) and reprojected ones
        (red crosses), with the rim (blue)."""
        from .report import _to_bgr8

        img = _to_bgr8(image, None).copy()
        rim = self.camera.rim_image_points(720)
        if np.isfinite(rim).all():
            cv2.polylines(
                img, [np.round(rim * 16).astype(np.int32)], True, (255, 0, 0), 1, cv2.LINE_AA, 4
            )
        det = self.image_points[index]
        if det is not None:
            for p in np.asarray(det).reshape(-1, 2):
                cv2.circle(
                    img,
                    tuple(int(v) for v in np.round(p * 16)),
                    4 * 16,
                    (0, 200, 0),
                    1,
                    cv2.LINE_AA,
                    4,
                )
        rep = self.reprojected.get(index)
        if rep is not None:
            for p in np.asarray(rep).reshape(-1, 2):
                if np.isfinite(p).all():
                    cv2.drawMarker(
                        img, tuple(round(v) for v in p), (0, 0, 255), cv2.MARKER_CROSS, 6, 1
                    )
        return img


# -- helpers ----------------------------------------------------------------------------------
def _distort(xn, K, D):
    """OpenCV's distortion with ``D = (k1, k2, p1, p2[, k3])`` then ``K`` (skew included), in
    numpy: the same formula as ``cv2.projectPoints``, without its per-call overhead."""
    x, y = xn[:, 0], xn[:, 1]
    r2 = x * x + y * y
    k1, k2, p1, p2 = D[:4]
    k3 = D[4] if len(D) > 4 else 0.0
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=1)


def _rim_foot(cam_K, D, R, t, mirror, u, phi):
    """Orthogonal distances of pixels ``u`` to the rim image, with foot parameters ``phi``
    refined in place by Newton's method. Returns signed distances (px)."""
    r, z = mirror.rim_radius, mirror.z_rim

    def curve(ph):
        X = np.stack([r * np.cos(ph), r * np.sin(ph), np.full_like(ph, z)], axis=1) @ R.T + t
        xn = X[:, :2] / X[:, 2:3]
        if D is None:
            return xn @ cam_K[:2, :2].T + cam_K[:2, 2]
        return _distort(xn, cam_K, D)

    h = 1e-4
    n = len(phi)
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
    return np.einsum("ij,ij->i", u - c0, nrm)


def _normalized(pixels, K, D):
    """Undistorted normalised coordinates of pixels (``inv(K)`` with skew)."""
    from ..raytrace import undistort_normalized

    if D is None:
        Ki = np.linalg.inv(K)
        return pixels @ Ki[:2, :2].T + Ki[:2, 2]
    return undistort_normalized(np.ascontiguousarray(pixels, dtype=np.float64), K, D)


class _Adjustment:
    """Parameter vector, residuals and Jacobian of the non-central bundle adjustment.

    ``x = [fx, fy, cx, cy, (skew), d_free..., w1, w2, t_x, t_y, t_z, (ln a, ln b), (lens_z),
    boards...]``
    with ``R = R0 R(w1, w2, 0)``: the mirror frame of the start turned about its own x and y
    axes, so the axis moves with no twist about it (the gauge's smallest rotation would add a
    twist of second order, which turns every board about the axis and bends the valley the
    fit must follow); ``tvec = t``; 6 numbers per board (``rvec_b, tvec_b``). The gauge of
    docs/conventions.md is imposed once, on the result (:meth:`to_gauge`).
    """

    def __init__(
        self,
        cam0,
        mirror,
        obj,
        views,
        rim_px,
        free_d,
        n_d,
        fit_skew,
        fit_shape,
        camera_cls,
        lens_px=None,
        lens_z=None,
    ):
        from ..gauge import gauge_rotation

        self.gauge_rotation = gauge_rotation
        self.mirror, self.obj, self.views, self.rim_px = mirror, obj, views, rim_px
        self.lens_px = lens_px
        self.lens_z, self.fit_lens_z = lens_z, False
        if lens_px is not None and lens_z is None:  # its plane: started by a fit, then free
            from .reflection import fit_circle

            Ki = np.linalg.inv(cam0.K)
            circle = fit_circle(
                mirror, cam0.R, cam0.tvec, _normalized(lens_px, cam0.K, cam0.D), Ki[:2, :2]
            )
            self.lens_z = circle.z if math.isfinite(circle.rms) else None
            if self.lens_z is None:
                self.lens_px = None
            else:
                self.fit_lens_z = True
        self.free_d, self.n_d, self.fit_skew, self.fit_shape = free_d, n_d, fit_skew, fit_shape
        self.camera_cls = camera_cls
        self.R0 = cam0.R.copy()
        self.D0 = np.zeros(n_d) if cam0.D is None else np.array(cam0.D, np.float64)
        self.rim_phi = None
        K = cam0.K
        g = [K[0, 0], K[1, 1], K[0, 2], K[1, 2]] + ([K[0, 1]] if fit_skew else [])
        g += [self.D0[i] for i in free_d]
        g += [0.0, 0.0, *cam0.tvec]
        if fit_shape:  # as logarithms: a, b stay positive wherever a step goes
            g += [math.log(mirror.a), math.log(mirror.b)]
        if self.fit_lens_z:
            g += [self.lens_z]
        self.n_global = len(g)
        self.names = (
            ["fx", "fy", "cx", "cy"]
            + (["skew"] if fit_skew else [])
            + [("k1", "k2", "p1", "p2", "k3")[i] for i in free_d]
            + ["w1", "w2", "tx", "ty", "tz"]
            + (["a", "b"] if fit_shape else [])
            + (["lens_z"] if self.fit_lens_z else [])
        )
        self.x0_global = np.array(g, np.float64)
        self.fixed = set()  # names of global parameters held at their value
        self.skew0 = K[0, 1]
        n = len(obj)
        self.n_rows_view = 2 * n

    def unpack(self, x):
        from ..mirror import HyperbolicMirror

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
            mirror = HyperbolicMirror(math.exp(x[i]), math.exp(x[i + 1]), self.mirror.rim_radius)
            i += 2
        return K, D, R, tvec, mirror

    def to_gauge(self, x, image_size=None):
        """The camera in the gauge of docs/conventions.md and the board poses in its mirror frame.

        The fitted ``R`` and the gauge's ``R_g = gauge(R e_z)`` differ by a turn ``Z`` about
        the mirror axis, ``R = R_g Z``: the gauge's mirror frame holds ``Z X`` for the fit's
        ``X``, so every board becomes ``(Z R_b, Z t_b)``.
        """
        K, D, R, tvec, mirror = self.unpack(x)
        Rg = self.gauge_rotation(R[:, 2])
        Z = Rg.T @ R
        cam = self.camera_cls(
            K, mirror, cv2.Rodrigues(Rg)[0].ravel(), tvec, D=D, image_size=image_size
        )
        poses = [
            (cv2.Rodrigues(Z @ rodrigues(b[:3]))[0].ravel(), Z @ b[3:]) for b in self.boards(x)
        ]
        return cam, poses

    def boards(self, x):
        return x[self.n_global :].reshape(-1, 6)

    def corner_residuals(self, x):
        from .. import raytrace

        K, D, R, tvec, mirror = self.unpack(x)
        B = self.boards(x)
        pts = np.concatenate([self.obj @ rodrigues(b[:3]).T + b[3:] for b in B])
        # the exact non-central projection of the camera's project(), on the fit's frame
        px = raytrace.project(np.ascontiguousarray(pts), False, K, D, R, tvec, -R.T @ tvec, mirror)
        obs = np.concatenate(self.views)
        r = px - obs
        r[~np.isfinite(r)] = 50.0  # a corner the rig cannot see: a large, constant residual
        return r.ravel()

    def rim_residuals(self, x):
        K, D, R, tvec, mirror = self.unpack(x)
        if self.rim_phi is None:  # foot points of the start, by dense sampling
            ph = np.linspace(0, 2 * np.pi, 3600, endpoint=False)
            X = (
                np.stack(
                    [
                        mirror.rim_radius * np.cos(ph),
                        mirror.rim_radius * np.sin(ph),
                        np.full_like(ph, mirror.z_rim),
                    ],
                    axis=1,
                )
                @ R.T
                + tvec
            )
            xn = X[:, :2] / X[:, 2:3]
            c = xn @ K[:2, :2].T + K[:2, 2]
            j = np.argmin(((self.rim_px[:, None, :] - c[None]) ** 2).sum(-1), axis=1)
            self.rim_phi = ph[j]
        phi = self.rim_phi.copy()
        return _rim_foot(K, D, R, tvec, mirror, self.rim_px, phi)

    def lens_residuals(self, x):
        """The camera's reflection (:mod:`.reflection`): ``(rho(u) - r) / |grad rho|`` px for
        every outline pixel, ``rho`` the radius at which its reflected ray crosses the plane of
        the coaxial circle (``z`` known, or the parameter ``lens_z`` started by
        :func:`.reflection.fit_circle` under the start posture) and ``r`` fitted in closed form
        at each evaluation."""
        from .reflection import plane_radius

        K, D, R, tvec, mirror = self.unpack(x)
        Ki = np.linalg.inv(K)
        xn = _normalized(self.lens_px, K, D)
        z = x[self.names.index("lens_z")] if self.fit_lens_z else self.lens_z
        rho, g = plane_radius(mirror, R, tvec, xn, z, Ki[:2, :2])
        ok = np.isfinite(rho) & np.isfinite(g) & (g > 0)
        r = np.zeros(len(rho))
        if ok.sum() >= 3:
            w = 1.0 / g[ok] ** 2
            r[ok] = (rho[ok] - float((w * rho[ok]).sum() / w.sum())) / g[ok]
        return r

    def residuals(self, x):
        parts = [self.corner_residuals(x), self.rim_residuals(x)]
        if self.lens_px is not None:
            parts.append(self.lens_residuals(x))
        return np.concatenate(parts)

    def steps(self, x):
        h = np.empty_like(x)
        g = self.n_global
        for k, name in enumerate(self.names):
            if name in ("fx", "fy", "cx", "cy", "skew"):
                h[k] = 1e-6 * max(abs(x[0]), 1.0)
            elif name in ("w1", "w2"):
                h[k] = 1e-7
            elif name in ("tx", "ty", "tz", "lens_z"):
                h[k] = 1e-6 * self.mirror.rim_radius
            elif name in ("a", "b"):  # their logarithms
                h[k] = 1e-6
            else:
                h[k] = 1e-7
        B = h[g:].reshape(-1, 6)
        B[:, :3] = 1e-7
        B[:, 3:] = 1e-6 * self.mirror.rim_radius
        return h

    def jacobian(self, x):
        """Central differences; the boards' columns in 6 groups (block structure). Columns of
        parameters held fixed (``self.fixed``) are zero."""
        h = self.steps(x)
        g = self.n_global
        nv = len(self.views)
        m = (
            nv * self.n_rows_view
            + len(self.rim_px)
            + (0 if self.lens_px is None else len(self.lens_px))
        )
        J = np.zeros((m, len(x)))
        for k in range(g):
            if self.names[k] in self.fixed:
                continue
            xp, xm = x.copy(), x.copy()
            xp[k] += h[k]
            xm[k] -= h[k]
            J[:, k] = (self.residuals(xp) - self.residuals(xm)) / (2 * h[k])
        rows = self.n_rows_view
        for k in range(6):
            xp, xm = x.copy(), x.copy()
            xp[g + k :: 6] += h[g + k :: 6]
            xm[g + k :: 6] -= h[g + k :: 6]
            diff = self.corner_residuals(xp) - self.corner_residuals(xm)
            for v in range(nv):
                col = g + 6 * v + k
                J[v * rows : (v + 1) * rows, col] = diff[v * rows : (v + 1) * rows] / (2 * h[col])
        return J

    def solve(self, x0, f_scale=1.0, max_nfev=None):
        """The ``soft_l1`` fit of scale ``f_scale`` px by MINPACK's Levenberg-Marquardt
        (``scipy.optimize.least_squares(method="lm")``), the global parameters named in
        ``self.fixed`` held at ``x0``; :meth:`jacobian` gives the derivatives.

        MINPACK minimises a plain sum of squares; the robust cost ``sum rho(r^2)``,
        ``rho(s) = 2 f^2 (sqrt(1 + s / f^2) - 1)``, is one, of the residuals
        ``z = sign(r) sqrt(rho(r^2))`` (:func:`_robust_residuals`), whose Jacobian is
        ``dz/dr J``, so the minimum is the robust one exactly. (The trust-region solvers of
        ``least_squares`` with the ``soft_l1`` loss, with ``jac_sparsity`` or this Jacobian,
        exact or ``lsmr`` steps, stopped at their 100 evaluations still descending along the
        valley where ``a, b`` trade against ``f``, where this one converges in a few dozen:
        ``benchmarks/bench_chessboard_real.py``.)

        Returns the ``OptimizeResult`` with ``x`` the whole parameter vector."""
        x0 = np.asarray(x0, np.float64)
        free = np.ones(len(x0), bool)
        free[[k for k, n in enumerate(self.names) if n in self.fixed]] = False

        def full(xf):
            x = x0.copy()
            x[free] = xf
            return x

        last = {}  # MINPACK asks for the Jacobian where it last evaluated the residuals

        def fun(xf):
            last["x"], last["z"] = xf.copy(), _robust_residuals(self.residuals(full(xf)), f_scale)
            return last["z"][0]

        def jac(xf):
            if "x" not in last or not np.array_equal(last["x"], xf):
                fun(xf)
            return self.jacobian(full(xf))[:, free] * last["z"][1][:, None]

        sol = least_squares(
            fun,
            x0[free],
            jac=jac,
            method="lm",
            x_scale="jac",
            max_nfev=max_nfev,
            xtol=1e-10,
            ftol=1e-10,
            gtol=1e-10,
        )
        sol.x = full(sol.x)
        sol.cost = float(sol.cost)
        return sol


def _robust_residuals(r, f_scale):
    """``z = sign(r) sqrt(rho(r^2))`` for the ``soft_l1`` loss ``rho(s) = 2 f^2 (sqrt(1 +
    s / f^2) - 1)``, so that ``sum z^2`` is the robust cost, and ``dz/dr``.

    With ``q = sqrt(1 + (r / f)^2)``: ``z = r sqrt(2 / (1 + q))`` (``z ~ r`` for ``|r| << f``,
    no cancellation) and ``dz/dr = r rho'(r^2) / z = sqrt((1 + q) / 2) / q``."""
    q = np.sqrt(1.0 + (r / f_scale) ** 2)
    return r * np.sqrt(2.0 / (1.0 + q)), np.sqrt((1.0 + q) / 2.0) / q


def _covariance(J, row_sigma):
    """``(J^T W J)^-1``, ``W = diag(1 / row_sigma^2)`` (the Cramer-Rao bound of independent
    Gaussian residuals of those sigmas), columns scaled to unit norm; a parameter no residual
    depends on (a zero column) gets NaN variance instead of a number the regularisation made up.
    """
    n = J.shape[1]
    Jw = J / np.asarray(row_sigma, np.float64)[:, None]
    scale = np.linalg.norm(Jw, axis=0)
    live = scale > 0
    Js = Jw[:, live] / scale[live]
    N = np.einsum("ij,ik->jk", Js, Js)
    cov = np.full((n, n), math.nan)
    m = int(live.sum())
    cov[np.ix_(live, live)] = np.linalg.solve(N + 1e-12 * np.eye(m), np.eye(m)) / np.outer(
        scale[live], scale[live]
    )
    return cov


def _std_from_jacobian(adj, x, J, row_sigma):
    """Standard deviations (:func:`_covariance`) of the named global parameters of ``adj`` at
    ``x``, the mirror axis (``axis_deg``, RMS angle) and the camera centre in the mirror frame
    (``origin``, RMS distance, the 5 posture parameters linearised through ``C = -R^T tvec``,
    eq. 17); and the covariance of the global parameters."""
    cov = _covariance(J, row_sigma)
    var = np.diag(cov)
    std = {}
    for k, name in enumerate(adj.names):
        if name in ("w1", "w2", "tx", "ty", "tz"):
            continue
        std[name] = float(math.sqrt(max(var[k], 0.0))) if math.isfinite(var[k]) else math.nan
        if name in ("a", "b"):  # the parameter is the logarithm
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


def ray_uncertainty(adj, x, cov_global, image_size, n=24):
    """Standard deviation (deg) of the viewing directions over the mirror's image: the rays of
    an ``n x n`` grid of pixels (those that see the mirror, eqs. 6-19), each linearised in the
    global parameters (central differences) and propagated through their covariance
    ``cov_global``. Returns ``(median, max)``; NaN when the covariance is not finite."""
    w, h = (int(v) for v in image_size)
    u, v = np.meshgrid(np.linspace(0, w - 1, n), np.linspace(0, h - 1, n))
    px = np.stack([u.ravel(), v.ravel()], axis=1)

    def rays(xx, pixels):
        K, D, R, t, mirror = adj.unpack(xx)
        return trace(pixels, K, D, R, -R.T @ t, mirror)[1]

    px = px[np.isfinite(rays(x, px)).all(axis=1)]
    live = np.isfinite(np.diag(cov_global))
    if len(px) == 0 or not live.any():
        return math.nan, math.nan
    steps = adj.steps(x)
    G = np.zeros((len(px), 3, adj.n_global))
    for k in np.flatnonzero(live):
        xp, xm = x.copy(), x.copy()
        xp[k] += steps[k]
        xm[k] -= steps[k]
        G[:, :, k] = (rays(xp, px) - rays(xm, px)) / (2 * steps[k])
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
    lens_points=None,
    lens_z=None,
    sigma_lens=None,
    dist_model="k1k2p1p2",
    refine_mirror_shape=False,
):
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
    camera : MisalignedHyperbolicCamera
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
        ``origin``, ``a, b`` with ``refine_mirror_shape``).
    """
    cols, rows = _pattern(pattern_size)
    if dist_model not in DIST_MODELS:
        raise ValueError(f"dist_model must be one of {sorted(DIST_MODELS)}, got {dist_model!r}")
    free_d = DIST_MODELS[dist_model]
    n_d = 0 if not free_d and camera.D is None else (5 if 4 in free_d else 4)
    obj = object_points((cols, rows), square_size)
    views = [
        camera.project(obj @ rodrigues(rv).T + np.asarray(tv, np.float64)) for rv, tv in board_poses
    ]
    lens_px = None if lens_points is None else np.asarray(lens_points, np.float64).reshape(-1, 2)
    adj = _Adjustment(
        camera,
        camera.mirror,
        obj,
        views,
        np.asarray(rim_points, np.float64).reshape(-1, 2),
        free_d,
        n_d,
        False,
        refine_mirror_shape,
        type(camera),
        lens_px,
        lens_z,
    )
    x = np.concatenate(
        [adj.x0_global] + [np.concatenate([np.ravel(rv), np.ravel(tv)]) for rv, tv in board_poses]
    )
    J = adj.jacobian(x)
    nc = len(views) * adj.n_rows_view
    sig = np.full(J.shape[0], float(sigma_corner))
    sig[nc : nc + len(adj.rim_px)] = float(sigma_rim)
    if adj.lens_px is not None:
        sig[nc + len(adj.rim_px) :] = float(sigma_lens)
    return _std_from_jacobian(adj, x, J, sig)[0]


# -- input handling ---------------------------------------------------------------------------
def _load_image(image, index):
    if isinstance(image, (str, os.PathLike)):
        img = cv2.imread(os.fspath(image), cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
        if img is None:
            raise ValueError(f"images[{index}]: cannot read image file {os.fspath(image)!r}")
        return img
    if not isinstance(image, np.ndarray) or image.ndim not in (2, 3) or image.size == 0:
        raise ValueError(
            f"images[{index}] must be an image array (H, W) or (H, W, C) or a file "
            f"path, got {type(image).__name__}"
        )
    return image


def _check_points(points, n, index, pattern_size):
    arr = np.asarray(points, np.float64)
    if arr.ndim == 3 and arr.shape[1:] == (1, 2):
        arr = arr.reshape(-1, 2)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(
            f"image_points[{index}] must be an (N, 1, 2) or (N, 2) array, got shape {arr.shape}"
        )
    if len(arr) != n:
        raise ValueError(
            f"image_points[{index}] has {len(arr)} corners but pattern_size "
            f"{tuple(pattern_size)} has {n}: fix pattern_size (inner corners "
            f"(columns, rows), not squares)"
        )
    if not np.isfinite(arr).all():
        raise ValueError(f"image_points[{index}] has non-finite values")
    return arr


def _azimuth_gap_deg(centres):
    az = np.sort(np.degrees(np.arctan2(centres[:, 1], centres[:, 0])))
    gaps = np.diff(np.append(az, az[0] + 360.0))
    return float(gaps.max())


def calibrate_pattern(
    images,
    pattern_size,
    square_size,
    mirror=None,
    K=None,
    D=None,
    image_size=None,
    image_points=None,
    refine_mirror_shape=False,
    dist_model="k1k2",
    *,
    rim_radius=None,
    boundary_points=None,
    camera_cls=None,
    fit_skew=False,
    drop_outlier_views=True,
    outlier_factor=3.0,
    outlier_min_px=1.0,
    f_scale=1.0,
    lens="auto",
    lens_z=None,
    heldout=0,
    progress=None,
):
    """Calibrate ``K``, ``D`` and the mirror posture from chessboards seen through the mirror.

    Parameters
    ----------
    images : sequence of ndarray or path, or None
        Images of the rig (BGR or grey), each showing the whole board once; used to detect the
        corners (:func:`omnicam.find_pattern`, unless ``image_points``) and the rim (unless
        ``boundary_points``). ``None`` needs ``image_points``, ``boundary_points`` and
        ``image_size``.
    pattern_size : (int, int)
        Inner corners ``(columns, rows)``, as ``cv2.findChessboardCorners``.
    square_size : float
        Side of a square in the mirror's length unit (mm by convention).
    mirror : HyperbolicMirror or None
        The mirror (a start: only its shape's agreement with the central fit is checked, and
        with ``refine_mirror_shape`` its ``a, b`` are estimated). ``None``: unknown, its shape
        from the central fit's ``xi`` and its size from the rim's image at ``rim_radius``
        (:func:`.central.hyperbolic_start`).
    K : (3, 3) array_like, optional
        Start of the camera matrix (refined). Default: from the central fit of the corners
        (:func:`.central.fit_central`), else from the rim (see the module docstring).
    D : array_like, optional
        Start of the distortion (4 or 5 coefficients); its free coefficients follow
        ``dist_model``.
    image_size : (int, int), optional
        ``(width, height)``; defaults to the images' size.
    image_points : sequence of (N, 1, 2) array_like or None, optional
        Corners per image in OpenCV's order (None for an image without a board); skips
        detection.
    refine_mirror_shape : bool
        Also estimate the mirror's ``a, b`` (``rim_radius`` fixes the scale; up to 400
        iterations). Exact corners started from ``a, b`` 2 % off give them back to 1e-6, but
        the data hardly determine them: ``a, b`` trade against the focal length and the
        camera's distance to the mirror, which only the rig's non-centrality tells apart. The
        bound of :func:`pattern_uncertainty` on the benchmark's rig (12 views, 0.2 px) is
        7 % for ``a``, 14 % for ``b`` and 12 % for ``fx``; the report gives their standard
        deviations and warns that they are not determined when either exceeds 1 %.
    dist_model : str
        One of ``"none", "k1", "k1k2", "k1k2p1p2", "k1k2p1p2k3"``: the OpenCV coefficients
        estimated (the others stay at ``D``'s values, or 0). Default ``"k1k2"``: a decentred
        lens (``p1, p2``) moves the image as a tilt of the mirror does, which the posture
        already holds, so the tangential terms mostly trade against it (see the module
        docstring) and predict held-out views worse
        (``benchmarks/bench_chessboard_real.py --dist-model``).
    rim_radius : float, optional
        With ``mirror=None``: the rim's radius (mirror units), which fixes the scale of the
        mirror and of the camera's position in its frame (default
        :data:`.central.NOMINAL_RIM_RADIUS`; the report then says the scale is assumed). No
        view of boards tells the scale apart but through the rig's small non-centrality; the
        viewing directions, ``K`` and ``D`` do not depend on it, distances do in proportion.
    boundary_points : (M, 2) array_like, optional
        Pixels on the rim (as seen), instead of detecting it in the images.
    camera_cls : type
        The camera class to build (``MisalignedHyperbolicCamera``; its classmethod passes it).
    fit_skew : bool
        Also estimate the skew ``K[0, 1]``.
    drop_outlier_views : bool
        Drop views whose RMS exceeds ``max(outlier_factor * median, outlier_min_px)`` and fit
        again (else they are only reported); either way a ``RuntimeWarning`` names them.
    f_scale : float
        Scale of the robust ``soft_l1`` loss, px (residuals well below it count fully).
    lens : "auto", None or (M, 2) array_like
        The camera's own reflection (:mod:`.reflection`, a circle coaxial with the optical
        axis): ``"auto"`` detects its outline in every image and pools the detections that
        agree (and goes on without it if there is none); an array gives the outline pixels;
        ``None`` does not use it. Its residuals join the adjustment, ``r`` fitted in closed
        form.
    lens_z : float, optional
        The circle's known axial distance from the camera centre (the front edge of the lens
        barrel, mirror length unit). With it the reflection separates a tilt of the mirror
        from a shift of the principal point, which corners and rim alone determine only
        through second-order perspective (see the report's ``std``); without it ``z`` is a
        parameter of the adjustment (``std["lens_z"]``), started by
        :func:`.reflection.fit_circle` under the start posture, and the reflection helps less
        (a tilt trades partly with ``z``: on the benchmark's rig the principal point's bound is
        8.3 px with ``z`` free, 4.9 px with it known, 69 px without the reflection).

    heldout : int
        With ``k >= 2``, also the ``k``-fold held-out check (:mod:`.heldout`: the rig
        calibrated on the other folds with the same options, each held-out view's board pose
        alone fitted; ``cv2.omnidir.calibrate`` on the same folds beside it) in
        ``report.heldout``; it costs ``k`` more calibrations. 0: not run.
    progress : callable, optional
        ``progress(index, text)`` hears of each image as its board is looked for (a command
        line prints it).

    Returns
    -------
    camera : MisalignedHyperbolicCamera
    report : PatternReport

    Raises
    ------
    ValueError
        Bad arguments, fewer than 3 usable views, no board found anywhere, all boards seen
        edge-on (coplanar with the camera), corner arrays that do not match ``pattern_size``;
        the message says what to change.
    """
    cols, rows, square, D, free_d, n_d, images, image_points, image_size = _check_arguments(
        images,
        pattern_size,
        square_size,
        mirror,
        D,
        dist_model,
        image_points,
        image_size,
        camera_cls,
    )
    mirror_given, K_given = mirror, K
    names = {
        i: os.path.basename(os.fspath(im))
        for i, im in enumerate(images if images is not None else [])
        if isinstance(im, (str, os.PathLike))
    }
    found_by = ["given" if p is not None else None for p in (image_points or [])]
    if image_points is None:
        image_points, found_by = _raw_detection_step(images, (cols, rows), progress)
    rim_fit, rim_seen, rim_image, rim_warns = _rim_step(
        images, boundary_points, image_size, image_points
    )
    lens_px, lens_note = _reflection_step(lens, images, rim_image, rim_fit)
    obj = object_points((cols, rows), square)  # (_corner_step returns the same)
    K, mirror, central, start_warns = _central_step(
        image_points, obj, image_size, rim_fit, mirror, rim_radius, K
    )
    cam0 = _start_step(K, mirror, rim_fit, rim_seen, D, image_size, camera_cls)
    missing = [i for i, p in enumerate(image_points) if p is None] if images else []
    for i, corners in _redetect(images, missing, (cols, rows), cam0, progress).items():
        image_points[i], found_by[i] = corners, "views"
    start, shape = cam0, mirror
    for _round in range(_DETECT_ROUNDS):
        pts, poses, dropped, obj = _corner_step(image_points, (cols, rows), square, start)
        adj, sol, used, vr, rim_px, warns = _adjustment_step(
            start,
            shape,
            obj,
            pts,
            poses,
            dropped,
            rim_seen,
            free_d,
            n_d,
            fit_skew,
            refine_mirror_shape,
            camera_cls,
            lens_px,
            lens_z,
            f_scale,
            drop_outlier_views,
            outlier_factor,
            outlier_min_px,
        )
        missing = [i for i, p in enumerate(image_points) if p is None and found_by[i] is None]
        if not images or not missing or _round == _DETECT_ROUNDS - 1:
            break  # (a board found after the last fit would be reported but not fitted)
        # the fitted camera aims the views better than the start did: look again, and fit
        # again only if a board is found that was not
        start = adj.to_gauge(sol.x, image_size)[0]
        shape = start.mirror
        new = _redetect(images, missing, (cols, rows), start, progress)
        if not new:
            break
        for i in new:
            image_points[i], found_by[i] = new[i], "views (fitted camera)"
    camera, report = _report_step(
        adj,
        sol,
        used,
        vr,
        rim_px,
        warns,
        mirror,
        obj,
        pts,
        dropped,
        cam0,
        image_size,
        cols * rows,
        refine_mirror_shape,
        lens_note,
        central,
    )
    found = {i: m for i, m in enumerate(found_by) if m is not None}
    start_warns = rim_warns + start_warns
    warns_all = tuple(start_warns) + report.warnings
    for w in start_warns:
        _warnings.warn(w, RuntimeWarning, stacklevel=2)
    held = None
    if heldout:
        options = dict(
            K=K_given,
            D=D,
            image_size=image_size,
            refine_mirror_shape=refine_mirror_shape,
            dist_model=dist_model,
            rim_radius=rim_radius,
            boundary_points=rim_seen,
            camera_cls=camera_cls,
            fit_skew=fit_skew,
            drop_outlier_views=False,
            f_scale=f_scale,
            lens=lens_px,
            lens_z=lens_z,
        )
        held = _heldout_step(report, mirror_given, (cols, rows), square, options, heldout)
    report = dataclasses.replace(
        report, found_by=found, central=central, warnings=warns_all, heldout=held, names=names
    )
    return camera, report


# -- the steps of calibrate_pattern ----------------------------------------------------------
def _check_arguments(
    images, pattern_size, square_size, mirror, D, dist_model, image_points, image_size, camera_cls
):
    """Validated arguments: ``(cols, rows, square, D, free_d, n_d, images, image_points,
    image_size)``; ``ValueError`` naming what to change."""
    from ..mirror import HyperbolicMirror

    if camera_cls is None:
        raise ValueError(
            "camera_cls is required (omnicam.calibrate_pattern passes the camera class)"
        )
    cols, rows = _pattern(pattern_size)
    try:
        square = float(square_size)
    except (TypeError, ValueError):
        raise ValueError(f"square_size must be a positive number, got {square_size!r}") from None
    if not (math.isfinite(square) and square > 0):
        raise ValueError(f"square_size must be a positive number, got {square_size!r}")
    if mirror is not None and not isinstance(mirror, HyperbolicMirror):
        raise ValueError(  # noqa: TRY004 (ValueError for bad arguments, as everywhere)
            f"mirror must be a HyperbolicMirror or None (unknown), got {type(mirror).__name__}"
        )
    if dist_model not in DIST_MODELS:
        raise ValueError(f"dist_model must be one of {sorted(DIST_MODELS)}, got {dist_model!r}")
    from .._validate import validate_D

    D = validate_D(D)
    if D is not None and D.size not in (4, 5):
        raise ValueError(
            f"D must have 4 or 5 coefficients (k1, k2, p1, p2[, k3]) for pattern "
            f"calibration, got {D.size}"
        )
    free_d = DIST_MODELS[dist_model]
    if not free_d and D is None:
        n_d = 0
    else:
        n_d = 5 if (4 in free_d or (D is not None and D.size == 5)) else 4
    if D is not None and D.size < n_d:
        D = np.concatenate([D, np.zeros(n_d - D.size)])
    images, image_points, image_size = _images_and_size(images, image_points, image_size)
    return cols, rows, square, D, free_d, n_d, images, image_points, image_size


def _images_and_size(images, image_points, image_size):
    """The images as arrays (paths read), ``image_points`` as a list matching them, and the
    one ``image_size`` they share."""
    from .._validate import validate_image_size

    if images is None:
        images = []
    elif isinstance(images, (str, os.PathLike)) or (
        isinstance(images, np.ndarray)
        and images.ndim in (2, 3)
        and images.dtype != object
        and (images.ndim == 2 or images.shape[2] in (1, 3, 4))
    ):
        images = [images]
    images = [_load_image(im, i) for i, im in enumerate(images)]
    if image_points is not None:
        image_points = list(image_points)
        if images and len(images) != len(image_points):
            raise ValueError(
                f"image_points has {len(image_points)} entries for {len(images)} "
                f"images: give one (or None) per image"
            )
    elif not images:
        raise ValueError(
            "give images (corners and rim are detected) or image_points with "
            "boundary_points and image_size"
        )
    if image_size is None and images:
        image_size = (images[0].shape[1], images[0].shape[0])
    image_size = validate_image_size(image_size)
    for i, im in enumerate(images):
        if (im.shape[1], im.shape[0]) != image_size:
            raise ValueError(
                f"images[{i}] is {im.shape[1]}x{im.shape[0]}, expected "
                f"{image_size[0]}x{image_size[1]}: all images must come from the "
                f"same camera mode"
            )
    return images, image_points, image_size


def _corners_outside(rim_fit, corners):
    """How many of the corners lie outside the rim's ellipse by more than 1 px."""
    if not corners:
        return 0
    return int((conic_distance(rim_fit.conic, np.concatenate(corners)) > 1.0).sum())


def _rim_step(images, boundary_points, image_size, image_points=None):
    """1. The rim: ``(rim_fit, rim_seen, rim_image, warnings)`` from the points or the first
    image that shows it. Every corner found must lie inside the mirror: a rim that leaves
    corners outside (an inner edge of the mirror's image, a reflection) is rejected and a
    larger one sought (:func:`.rim.detect_rim` with the size the corners need), in that image
    and the next; the warnings say which was rejected."""
    corners = [
        np.asarray(p, np.float64).reshape(-1, 2) for p in image_points or [] if p is not None
    ]
    warns = []
    rim_image = 0
    if boundary_points is not None:
        rim_seen = np.asarray(boundary_points, np.float64).reshape(-1, 2)
        if len(rim_seen) < 6 or not np.isfinite(rim_seen).all():
            raise ValueError("boundary_points must be at least 6 finite pixels on the rim")
        rim_fit = fit_rim(rim_seen)
        rim_seen = rim_seen[np.asarray(rim_fit.inliers, bool)]
        n_out = _corners_outside(rim_fit, corners)
        if n_out:
            warns.append(
                f"{n_out} corner(s) lie outside the rim of the boundary_points given (semi-axes "
                f"{rim_fit.axes[0]:.1f}, {rim_fit.axes[1]:.1f} px): are they the mirror's rim?"
            )
    else:
        rim_fit, errors = None, []
        for i, im in enumerate(images):
            try:
                found = detect_rim(im)
            except ValueError as e:
                errors.append(f"images[{i}]: {e}")
                continue
            n_out = _corners_outside(found, corners)
            if n_out:
                need = float(np.max(np.linalg.norm(np.concatenate(corners) - found.center, axis=1)))
                what = (
                    f"the rim found in image {i} (centre {found.center[0]:.1f}, "
                    f"{found.center[1]:.1f}, semi-axes {found.axes[0]:.1f}, {found.axes[1]:.1f} "
                    f"px) leaves {n_out} corner(s) outside: rejected"
                )
                try:
                    larger = detect_rim(im, expected=(need, 2.0 * need))
                except ValueError:
                    larger = None
                if larger is None or _corners_outside(larger, corners):
                    errors.append(f"images[{i}]: {what}")
                    warns.append(what)
                    continue
                warns.append(
                    f"{what}; the rim taken has semi-axes {larger.axes[0]:.1f}, "
                    f"{larger.axes[1]:.1f} px"
                )
                found = larger
            rim_fit, rim_image = found, i
            break
        if rim_fit is None:
            raise ValueError(
                "the mirror rim was not found in any image ("
                + "; ".join(errors[:2])
                + "); give boundary_points"
            )
        rim_seen = np.asarray(rim_fit.points, np.float64)
    if image_size is None:
        raise ValueError("image_size (width, height) is needed when no image is given")
    return rim_fit, rim_seen, rim_image, warns


def _pooled_reflection(images, rim_image, rim_fit):
    """The outline of the camera's reflection detected in every image and pooled.

    The rig is rigid, so every image shows the same outline; its detection error is partly
    noise (it averages out over the images) and partly systematic (it does not): on the
    benchmark's renders 0.12 px RMS in one image, 0.066 px RMS per direction averaged over 13,
    and the principal point's error over 3 trials 2-24 px from one image against 4-6 px pooled.
    Detections whose centre or radius is more than :data:`_LENS_AGREE_PX` from the median of
    the images' are left out (a board or a hand over the reflection).
    """
    from .reflection import detect_reflection

    order = [rim_image] + [i for i in range(len(images)) if i != rim_image]
    fits, errors = [], []
    for i in order:
        try:
            fits.append(detect_reflection(images[i], rim_fit))
        except ValueError as e:
            errors.append(str(e))
    if not fits:
        return None, f"not used: {errors[0]}"
    centre = np.median([f.center for f in fits], axis=0)
    radius = float(np.median([f.radius for f in fits]))
    kept = [
        f
        for f in fits
        if np.linalg.norm(f.center - centre) <= _LENS_AGREE_PX
        and abs(f.radius - radius) <= _LENS_AGREE_PX
    ]
    pts = np.concatenate([np.asarray(f.points, np.float64) for f in kept])
    return pts, (
        f"used: {len(pts)} outline points detected in {len(kept)} of {len(images)} image(s)"
    )


def _reflection_step(lens, images, rim_image, rim_fit):
    """The camera's own reflection: ``(outline pixels or None, note)``."""
    # the camera's own reflection (its outline pins the tilt against the principal point)
    lens_px, lens_note = None, "not used (lens=None)"
    if isinstance(lens, str):
        if lens != "auto":
            raise ValueError(
                f"lens must be 'auto', None or an (M, 2) array of outline pixels, got {lens!r}"
            )
        if not images:
            lens_note = "not used: no image (give lens=outline pixels to use it)"
        else:
            lens_px, lens_note = _pooled_reflection(images, rim_image, rim_fit)
    elif lens is not None and lens is not False:
        lens_px = np.asarray(lens, np.float64).reshape(-1, 2)
        if len(lens_px) < 8 or not np.isfinite(lens_px).all():
            raise ValueError(
                "lens must hold at least 8 finite pixels along the outline of the "
                "camera's reflection"
            )
        lens_note = f"used: {len(lens_px)} outline points given"

    return lens_px, lens_note


def _start_step(K, mirror, rim_fit, rim_seen, D, image_size, camera_cls):
    """2. The start: ``K`` from the rim's size unless given, the posture by Chen's method."""
    from .._validate import validate_K
    from . import calibrate

    # 2. the start: K from the rim, posture by Chen's method
    if K is None:
        r_px = math.sqrt(float(rim_fit.axes[0] * rim_fit.axes[1]))
        f0 = r_px * (mirror.z_rim + mirror.c) / mirror.rim_radius
        w, h = image_size
        K0 = np.array([[f0, 0.0, (w - 1) / 2.0], [0.0, f0, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
    else:
        K0 = validate_K(K)
    try:
        cam0, _ = calibrate(
            K0,
            mirror,
            boundary_points=rim_seen,
            D=D,
            image_size=image_size,
            refine=True,
            camera_cls=camera_cls,
            lens=None,
        )
    except ValueError as e:
        raise ValueError(f"the posture could not be started from the rim: {e}") from None

    return cam0


def _raw_detection_step(images, pattern_size, progress=None):
    """2a. Every image's board by OpenCV's detectors on the raw image, which need no camera
    (:func:`.pattern_detect.detect_pattern`). Returns ``(corners or None per image, how each
    was found or None)``; ``progress(index, text)`` hears of each image."""
    points, found_by = [], []
    for k, im in enumerate(images):
        det = detect_pattern(im, pattern_size, None, methods=("raw", "raw-sb"))
        points.append(None if det is None else det.corners)
        found_by.append(None if det is None else det.method)
        if progress is not None:
            progress(k, "no board on the raw image" if det is None else f"board ({det.method})")
    return points, found_by


def _central_step(image_points, obj, image_size, rim_fit, mirror, rim_radius, K):
    """2b. Without a mirror, the central start (:mod:`.central`): ``cv2.omnidir.calibrate``
    of the corners found so far and the hyperbolic rig it describes, at ``rim_radius``.
    Returns ``(K, mirror, central fit or None, warnings)``; a given mirror is returned as it
    is, with ``K`` (None: from the rim), and the central fit only for comparison. The central
    fit's shape is not used to judge a given mirror: with the pinhole's distortion fixed its
    ``xi`` is biased on misaligned rigs (``a / b`` 1.22-1.28 on the test rig whose mirror has
    0.83), and with it free ``xi`` trades with ``k1``."""
    from .central import NOMINAL_RIM_RADIUS, fit_central, hyperbolic_start

    warns = []
    views = [np.asarray(p, np.float64).reshape(-1, 2) for p in image_points if p is not None]
    views = [v for v in views if len(v) == len(obj)]
    if mirror is not None:  # the rim's start (module docstring); the central fit to compare
        try:
            central = fit_central(views, obj, image_size)
        except ValueError:
            central = None
        return K, mirror, central, warns
    try:
        central = fit_central(views, obj, image_size)
    except ValueError as e:
        raise ValueError(
            f"the rig could not be started without a mirror: {e}; give the mirror "
            f"(a, b, rim_radius) as a start"
        ) from None
    r_px = math.sqrt(float(rim_fit.axes[0] * rim_fit.axes[1]))
    centre = ((image_size[0] - 1) / 2.0, (image_size[1] - 1) / 2.0)  # as the rim's start
    R = NOMINAL_RIM_RADIUS if rim_radius is None else float(rim_radius)
    K_c, mirror = hyperbolic_start(central.K, central.xi, r_px, R, K, centre)
    if rim_radius is None:
        warns.append(
            f"the mirror's scale is assumed (rim_radius = {R:g}, nominal): a, b and the "
            f"camera's position in the mirror frame scale with it; K, D and the viewing "
            f"directions do not. Give rim_radius for the true scale"
        )
    return K_c, mirror, central, warns


def _redetect(images, missing, pattern_size, camera, progress=None):
    """3a. ``{index: corners}`` of the boards that the views of ``camera`` find in the images
    ``missing``; ``progress(index, text)`` hears of each."""
    new = {}
    for i in missing:
        det = detect_pattern(images[i], pattern_size, camera, methods=("views",))
        if det is not None:
            new[i] = det.corners
        if progress is not None:
            progress(i, "board (views)" if det is not None else "no board in the views either")
    return new


def _corner_step(image_points, pattern_size, square, cam0):
    """3b. The corners of every view, checked, and each board's start pose from its rays:
    ``(pts, poses, dropped, obj)``."""
    cols, rows = pattern_size
    n_corners = cols * rows
    dropped = {}
    pts = []
    for i, p in enumerate(image_points):
        if p is None:
            pts.append(None)
            dropped[i] = "no board found"
            continue
        pts.append(_check_points(p, n_corners, i, (cols, rows)))
    found = [i for i, p in enumerate(pts) if p is not None]
    if found:  # (with no board at all the error below says it)
        for i in sorted(dropped):
            _warnings.warn(f"view {i} dropped: {dropped[i]}", RuntimeWarning, stacklevel=2)
    if not found:
        raise ValueError(
            f"no {cols}x{rows} chessboard was found in any of the {len(pts)} "
            f"image(s): check pattern_size (inner corners (columns, rows), not "
            f"squares) and that the whole board is seen in the mirror"
        )
    obj = object_points((cols, rows), square)
    viewpoint, _ = cam0.best_fit_viewpoint()
    poses, edge_on = {}, []
    for i in found:
        P, d = cam0.unproject(pts[i])
        if not np.isfinite(d).all():
            dropped[i] = "corners outside the mirror rim"
            _warnings.warn(f"view {i} dropped: {dropped[i]}", RuntimeWarning, stacklevel=2)
            continue
        rvec_b, tvec_b, _ = board_pose_from_rays(P, d, obj, viewpoint)
        n = rodrigues(rvec_b)[:, 2]
        centre = obj.mean(axis=0) @ rodrigues(rvec_b).T + tvec_b - viewpoint
        if abs(n @ centre) < _EDGE_ON_SIN * np.linalg.norm(centre):
            dropped[i] = "board seen edge-on (its plane passes through the camera)"
            _warnings.warn(f"view {i} dropped: {dropped[i]}", RuntimeWarning, stacklevel=2)
            edge_on.append(i)
            continue
        poses[i] = (rvec_b, tvec_b)
    if edge_on and len(edge_on) == len(found):
        raise ValueError(
            "all boards are seen edge-on (their planes pass through the camera): "
            "turn the board towards the mirror"
        )
    used = sorted(poses)
    if len(used) < _MIN_VIEWS:
        raise ValueError(
            f"only {len(used)} usable view(s) of the board (need at least "
            f"{_MIN_VIEWS}; dropped: {dropped}): take more views of the whole "
            f"board around the mirror"
        )

    return pts, poses, dropped, obj


def _adjustment_step(
    cam0,
    mirror,
    obj,
    pts,
    poses,
    dropped,
    rim_seen,
    free_d,
    n_d,
    fit_skew,
    refine_mirror_shape,
    camera_cls,
    lens_px,
    lens_z,
    f_scale,
    drop_outlier_views,
    outlier_factor,
    outlier_min_px,
):
    """4. The bundle adjustment in two stages, views that stand out reported (and dropped):
    ``(adj, sol, used, view_rms, rim_px, warnings)``."""
    warns = []
    used = sorted(poses)
    # 4. the bundle adjustment
    rim_px = rim_seen
    if len(rim_px) > _N_RIM:
        rim_px = rim_px[np.linspace(0, len(rim_px) - 1, _N_RIM).round().astype(int)]

    def adjust(view_ids, x_boards, x_global=None):
        adj = _Adjustment(
            cam0,
            mirror,
            obj,
            [pts[i] for i in view_ids],
            rim_px,
            free_d,
            n_d,
            fit_skew,
            refine_mirror_shape,
            camera_cls,
            lens_px,
            lens_z,
        )
        x0 = np.concatenate(
            [adj.x0_global if x_global is None else x_global, np.concatenate(x_boards)]
        )
        if x_global is None:
            # stage 1: principal point, skew and distortion held at the start, so the fit does
            # not first wander along the valley where a shift of the principal point (or
            # tangential distortion) trades against a tilt of the mirror
            adj.fixed = {"cx", "cy", "skew", "k1", "k2", "p1", "p2", "k3"}
            x0 = adj.solve(x0, f_scale=f_scale, max_nfev=20).x
            adj.fixed = set()
        # with the mirror's shape free the fit follows a long, flat valley (a, b trade against
        # f and the camera's axial position; only the rig's non-centrality tells them apart):
        # on exact corners started 2 % off it needs ~150 iterations to reach the truth
        return adj, adj.solve(x0, f_scale=f_scale, max_nfev=400 if refine_mirror_shape else 100)

    adj, sol = adjust(used, [np.concatenate(poses[i]) for i in used])

    def view_rms(sol, ids):
        r = adj.corner_residuals(sol.x).reshape(len(ids), -1)
        return {i: float(np.sqrt(np.mean(r[k] ** 2) * 2)) for k, i in enumerate(ids)}

    vr = view_rms(sol, used)
    med = float(np.median(list(vr.values())))
    limit = max(outlier_factor * med, outlier_min_px)
    outliers = [i for i in used if vr[i] > limit]
    if outliers:
        what = "dropped" if drop_outlier_views else "kept"
        msg = (
            f"view(s) {outliers} reproject with RMS "
            f"{', '.join(f'{vr[i]:.2f}' for i in outliers)} px against a median of "
            f"{med:.3f} px ({what}; check their corners)"
        )
        warns.append(msg)
        _warnings.warn(msg, RuntimeWarning, stacklevel=2)
        if drop_outlier_views and len(used) - len(outliers) >= _MIN_VIEWS:
            B = adj.boards(sol.x)
            keep = [k for k, i in enumerate(used) if i not in outliers]
            for i in outliers:
                dropped[i] = f"RMS {vr[i]:.2f} px stands out (median {med:.3f} px)"
            used = [used[k] for k in keep]
            adj, sol = adjust(used, [B[k] for k in keep], sol.x[: adj.n_global])
            vr = view_rms(sol, used)
        elif drop_outlier_views:
            warns.append("too few views would remain: the outliers were kept")

    return adj, sol, used, vr, rim_px, warns


def rim_conic(camera):
    """The conic ``Q_I`` of the rim's image in ideal (undistorted) pixels: the circle
    ``x^2 + y^2 = r^2`` of the plane ``z = z_rim`` mapped by ``H = K [R_1, R_2, z_rim R_3 + t]``,
    ``Q_I = H^-T diag(1, 1, -r^2) H^-1``."""
    R, t, m = camera.R, camera.tvec, camera.mirror
    H = camera.K @ np.column_stack([R[:, 0], R[:, 1], m.z_rim * R[:, 2] + t])
    Hi = np.linalg.inv(H)
    return Hi.T @ np.diag([1.0, 1.0, -(m.rim_radius**2)]) @ Hi


def _heldout_step(report, mirror, pattern_size, square, options, k):
    """6. The k-fold held-out check of the views used (:func:`.heldout.cross_validate`), the
    rig on each fold's training views calibrated with the same ``options``, its warnings
    (said once, for the whole fit) silenced."""
    views = {
        i: np.asarray(report.image_points[i], np.float64).reshape(-1, 2) for i in report.view_rms
    }

    def fit(train):
        points = [views[i] for i in train]
        with _warnings.catch_warnings():
            _warnings.simplefilter("ignore")
            camera, _ = calibrate_pattern(
                None, pattern_size, square, mirror, image_points=points, **options
            )
        return camera

    obj = object_points(pattern_size, square)
    return cross_validate(fit, views, obj, options["image_size"], k)


def _report_step(
    adj,
    sol,
    used,
    vr,
    rim_px,
    warns,
    mirror,
    obj,
    pts,
    dropped,
    cam0,
    image_size,
    n_corners,
    refine_mirror_shape,
    lens_note,
    central,
):
    """5. The camera in the gauge and the :class:`PatternReport` with the a posteriori
    standard deviations and the warnings."""
    nv_rows = adj.n_rows_view
    # 5. the report
    camera, gauged = adj.to_gauge(sol.x, image_size)
    r_all = adj.residuals(sol.x)
    m, n = len(r_all), len(sol.x)
    sigma2 = float(r_all @ r_all) / max(m - n, 1)
    std, cov = _std_from_jacobian(adj, sol.x, adj.jacobian(sol.x), np.full(m, math.sqrt(sigma2)))
    ray_deg = ray_uncertainty(adj, sol.x, cov, image_size)
    corner_r = r_all[: len(used) * nv_rows]
    rim_r = r_all[len(used) * nv_rows : len(used) * nv_rows + len(rim_px)]
    lens_r = r_all[len(used) * nv_rows + len(rim_px) :]
    board_poses = {i: gauged[k] for k, i in enumerate(used)}
    reprojected = {i: camera.project(obj, *board_poses[i]).reshape(-1, 1, 2) for i in used}
    if len(used) < 6:
        warns.append(
            f"only {len(used)} views: take 10 or more, spread around the mirror, for a "
            f"reliable K and posture"
        )
    centres = np.array([obj.mean(axis=0) @ rodrigues(p[0]).T + p[1] for p in board_poses.values()])
    if _azimuth_gap_deg(centres) > 180.0:
        warns.append(
            "all boards are on one side of the mirror (an azimuth gap over 180 deg): "
            "add views on the other side, or the principal point and the tilt are "
            "poorly separated"
        )
    if max(std["cx"], std["cy"]) > 1.0:
        warns.append(
            f"the principal point is weakly determined (std {std['cx']:.2f}, "
            f"{std['cy']:.2f} px): add views at other azimuths and elevations"
        )
    if not sol.success:
        warns.append(f"the adjustment did not converge: {sol.message}")
    rays = (
        f"the viewing directions are known to {ray_deg[0]:.3f} deg (median over the mirror's "
        f"image, worst {ray_deg[1]:.3f} deg)"
    )
    if refine_mirror_shape:
        ra = std["a"] / camera.mirror.a
        rb = std["b"] / camera.mirror.b
        weak = max(ra, rb) > _SHAPE_WEAK
        warns.append(
            f"the mirror's a, b were estimated (a = {camera.mirror.a:.3f} +- "
            f"{std['a']:.3f} ({100 * ra:.1f} %), b = {camera.mirror.b:.3f} +- "
            f"{std['b']:.3f} ({100 * rb:.1f} %))"
            + (
                ": NOT determined by these data (they trade against the focal length and the "
                "camera's distance to the mirror, which only the rig's small non-centrality "
                f"tells apart), but {rays}; use the data sheet's values for distances"
                if weak
                else "; they trade against the focal length and the camera's distance to the "
                "mirror: prefer the data sheet's values when there is one"
            )
        )
    if std["fx"] > _SHAPE_WEAK * camera.K[0, 0]:
        warns.append(
            f"the focal length is weakly determined (fx = {camera.K[0, 0]:.1f} +- "
            f"{std['fx']:.1f} px: it trades against the mirror's shape and distance), but {rays}"
        )
    rms = float(np.sqrt(np.mean(corner_r**2) * 2))
    if central is not None and rms > 2.0 * central.rms + 0.1:
        warns.append(
            f"the corners fit this rig to {rms:.3f} px RMS, far above the "
            f"central fit's {central.rms:.3f} px: the mirror may not be a hyperboloid (a "
            f"sphere, a paraboloid, a cone), or the start was far off"
        )
    warns.extend(str(w) for w in check_plausibility(camera, rim_conic(camera), image_size))
    image_points_out = [None if p is None else p.reshape(-1, 1, 2).astype(np.float32) for p in pts]
    report = PatternReport(
        rms=rms,
        ray_std_deg=ray_deg,
        view_rms=vr,
        corners_used={i: n_corners for i in used},
        board_poses=board_poses,
        image_points=image_points_out,
        reprojected=reprojected,
        rim_points=rim_px,
        rim_rms=float(np.sqrt(np.mean(rim_r**2))),
        std=std,
        warnings=tuple(warns),
        lens_rms=float(np.sqrt(np.mean(lens_r**2))) if len(lens_r) else math.nan,
        lens_note=lens_note,
        dropped=dict(sorted(dropped.items())),
        nfev=int(sol.nfev),
        camera=camera,
        start=cam0,
    )
    return camera, report
