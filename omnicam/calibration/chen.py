"""Mirror posture from the rim ellipse: Chen's conic method (paper section 3.1 and appendix).

The rim of the mirror is a circle of known radius ``r`` in the plane ``Z = z_rim`` of the mirror
frame. Its image is the conic ``x~^T Q_I x~ = 0`` (eqs. 20-22); with the camera ray
``X = s K^-1 x~`` (eq. 6) the rim lies on the cone

    X^T Q_e X = 0,   Q_e = K^T Q_I K                                  (eqs. 23-24)

(with distortion ``D`` the conic is fitted to undistorted pixels ``K x_n``, so eq. 24 still holds
with the same ``K``). Chen's method decomposes ``Q_e = V Lambda V^T`` (eq. 25) and finds the
rotations ``U`` that turn the cone into the cone of a circle, ``-U^T Lambda U / lambda_3 = k Q_C``
(eqs. 26-28); ``R = V U`` (eq. 29) and the circle's centre follow. There are four solutions
(the parities ``l, m`` of eqs. 39-41): two planes of circular section, each with two
orientations of its normal. Which orientation is physical follows from the rig's geometry:

* the rim must be in front of the camera (the cone's forward nappe, ``z > 0``);
* the mirror axis ``R e_z`` points *away* from the camera: the camera looks at the convex sheet
  from below, the apex ``(0, 0, b)`` is nearer to the camera than the rim plane ``z_rim``, so the
  rim centre ``C`` satisfies ``(C, R e_z) > 0``;
* the camera centre is below the mirror sheet (on its reflecting, convex side).

Candidates failing a test are kept and marked ``physical = False`` with the reason. The two
physical candidates are the two circular sections; section 3.2 (:mod:`.selection`) picks one.

Paper errata followed here (``docs/conventions.md``): the conic's sign is fixed so that ``Q_e`` has
exactly one negative eigenvalue; ``V`` is made a rotation (``det V = +1``) so ``R = V U`` is one;
the free variable of eqs. 39-40 is ``theta`` (the unobservable rotation about the mirror axis,
set to 0 and then replaced by the gauge of :func:`omnicam.gauge.canonical_rvec`); the third
column of ``U`` (printed as a second ``u2``, eq. 41) is ``u3``; ``delta`` of eq. 42 is the
square root of the printed ratio.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from .._typing import FloatArray
from .._validate import validate_K
from ..asphere import AsphericMirror
from ..gauge import canonical_rvec
from ..mirror import HyperbolicMirror

__all__ = [
    "Candidate",
    "normalized_conic",
    "chen_candidates",
    "rim_cone",
    "rim_conic",
    "physical_reasons",
]


@dataclasses.dataclass(frozen=True, eq=False)
class Candidate:
    """One of the four postures of Chen's method.

    Attributes
    ----------
    rvec : (3,) float64 ndarray
        Mirror rotation (mirror -> camera), in the gauge of docs/conventions.md.
    tvec : (3,) float64 ndarray
        Mirror origin in the camera frame, ``rim_centre - z_rim * axis``.
    axis : (3,) float64 ndarray
        Mirror axis ``R e_z`` (unit) in the camera frame: the circle's normal ``r_3`` (sec. 3.1).
    rim_centre : (3,) float64 ndarray
        Centre of the rim circle in the camera frame, ``C_C = R C_0`` (sec. 3.1).
    physical : bool
        Whether the posture is physically possible.
    reasons : tuple of str
        Why it is not (empty when physical).
    l, m : int
        Parities of eqs. 39-41 that produced it.
    score : float
        Selection score of eq. 31 (NaN until :mod:`.selection` sets it, and for candidates not
        evaluated).
    """

    rvec: np.ndarray
    tvec: np.ndarray
    axis: np.ndarray
    rim_centre: np.ndarray
    physical: bool
    reasons: tuple
    l: int
    m: int
    score: float = math.nan

    def with_score(self, score) -> Candidate:
        """A copy with ``score`` set."""
        return dataclasses.replace(self, score=float(score))

    @property
    def R(self) -> np.ndarray:
        """(3, 3) rotation matrix of ``rvec``."""
        return cv2.Rodrigues(np.asarray(self.rvec, np.float64).reshape(3, 1))[0]

    def __repr__(self) -> str:
        tag = "physical" if self.physical else "impossible: " + "; ".join(self.reasons)
        return (
            f"Candidate(l={self.l}, m={self.m}, rvec={np.round(self.rvec, 9).tolist()}, "
            f"tvec={np.round(self.tvec, 9).tolist()}, score={self.score:.6g}, {tag})"
        )


# -- the conic ---------------------------------------------------------------------------------
def normalized_conic(Q_I, K) -> FloatArray:
    """The rim cone ``Q_e = K^T Q_I K`` (eq. 24), unit norm, signed for Chen's method.

    Parameters
    ----------
    Q_I : (3, 3) array_like
        Rim conic in (undistorted) pixel coordinates, any scale and sign (eq. 22).
    K : (3, 3) array_like
        Camera matrix (skew allowed), non-singular.

    Returns
    -------
    Q_e : (3, 3) float64 ndarray
        Symmetric, unit Frobenius norm, with exactly one negative eigenvalue (paper erratum).

    Raises
    ------
    ValueError
        ``K`` singular, ``Q_I`` not a finite 3x3 matrix, or not a real non-degenerate ellipse.
    """
    K = validate_K(K)
    Q = np.asarray(Q_I, dtype=np.float64)
    if Q.shape != (3, 3) or not np.isfinite(Q).all():
        raise ValueError(f"the rim conic must be a finite 3x3 matrix, got shape {Q.shape}")
    Q = 0.5 * (Q + Q.T)
    # Q_e = K^T Q_I K  (eq. 24)
    Qe = K.T @ Q @ K
    nrm = np.linalg.norm(Qe)
    if not nrm > 0:
        raise ValueError("the rim conic is zero; fit it to points along the mirror boundary")
    Qe = Qe / nrm
    lam = np.linalg.eigvalsh(Qe)
    if np.min(np.abs(lam)) < 1e-12 * np.max(np.abs(lam)):
        raise ValueError(
            "the rim conic is degenerate (a pair of lines or a point); give boundary "
            "points spread along the whole mirror rim"
        )
    # errata: the conic's sign is free; make exactly one eigenvalue negative  (eqs. 32-33)
    if np.count_nonzero(lam < 0) == 2:
        Qe, lam = -Qe, -lam[::-1]
    if np.count_nonzero(lam < 0) != 1:
        raise ValueError(
            "the rim conic is an imaginary ellipse (no real points); fit it to "
            "points along the mirror boundary"
        )
    # a real ellipse in the image plane z = 1: the upper-left 2x2 block is positive definite
    if np.linalg.det(Qe[:2, :2]) <= 0 or Qe[0, 0] <= 0:
        raise ValueError(
            "the rim conic is not an ellipse in the image (a hyperbola or parabola "
            "means the rim would cross the camera's plane); check the boundary "
            "points and K"
        )
    return Qe


# -- Chen's method (eqs. 25-29, 32-42) -----------------------------------------------------------
def _eigen(Qe):
    """``Q_e = V Lambda V^T`` (eq. 25) ordered as eqs. 32-33: ``lambda_1 >= lambda_2 > 0 >
    lambda_3``, ``det V = +1``."""
    lam, V = np.linalg.eigh(Qe)  # ascending: lam[0] < 0 < lam[1] <= lam[2]
    order = [2, 1, 0]
    lam, V = lam[order], V[:, order]
    if np.linalg.det(V) < 0:  # errata: R = V U is a rotation only with det V = +1
        V[:, 2] = -V[:, 2]
    return lam, V


def _chen_U(delta, l, m, theta=0.0):
    """``U = [u_1, u_2, u_3]`` of eqs. 39-41 (``u_3`` is the circle's normal)."""
    s = math.sqrt(max(0.0, 1.0 - delta * delta))
    ct, st = math.cos(theta), math.sin(theta)
    sl, sm, slm = (-1.0) ** l, (-1.0) ** m, (-1.0) ** (l - m)
    u1 = np.array([delta * ct, st, slm * s * ct])  # eq. 39
    u2 = np.array([sm * delta * st, -sm * ct, sl * s * st])  # eq. 40
    u3 = np.array([sl * s, 0.0, -sm * delta])  # eq. 41 (printed as u2: erratum)
    return np.stack([u1, u2, u3], axis=1)


def physical_reasons(R, tvec, mirror, rim_centre=None) -> tuple[str, ...]:
    """Why the posture ``(R, tvec)`` cannot be a real rig (empty tuple if it can).

    Tests: the rim in front of the camera; the mirror axis pointing away from the camera (the
    camera looks at the convex side); the camera centre below the mirror sheet.
    """
    R = np.asarray(R, np.float64)
    tvec = np.asarray(tvec, np.float64)
    axis = R[:, 2]
    if rim_centre is None:
        rim_centre = tvec + mirror.z_rim * axis
    reasons = []
    rim = mirror.rim_points(64) @ R.T + tvec
    if not (rim[:, 2] > 0).all():
        reasons.append("rim behind the camera")
    if not float(rim_centre @ axis) > 0:
        reasons.append("mirror facing away (axis points towards the camera)")
    C = -R.T @ tvec  # camera centre in the mirror frame (F_M, eq. 17)
    if not C[2] < float(mirror.surface_z(C[0], C[1])):
        reasons.append("camera not below the mirror")
    return tuple(reasons)


def chen_candidates(Qe, mirror) -> list[Candidate]:
    """The four mirror postures of Chen's method (eqs. 25-29, 32-42).

    Parameters
    ----------
    Qe : (3, 3) array_like
        Rim cone from :func:`normalized_conic` (one negative eigenvalue).
    mirror : HyperbolicMirror or AsphericMirror
        Gives the rim radius ``r`` and height ``z_rim`` (the rim is a circle on the axis for
        every mirror of revolution: nothing else of the mirror enters).

    Returns
    -------
    list of Candidate
        Four candidates in the order ``(l, m) = (0, 0), (0, 1), (1, 0), (1, 1)``; ``(l, m)`` and
        ``(l+1, m+1)`` share the rim circle and have opposite axes. Non-physical ones are marked.
    """
    if not isinstance(mirror, HyperbolicMirror | AsphericMirror):
        raise ValueError(
            f"mirror must be a HyperbolicMirror or an AsphericMirror, got {type(mirror).__name__}"
        )
    Qe = np.asarray(Qe, np.float64)
    lam, V = _eigen(Qe)
    if not (lam[0] >= lam[1] > 0 > lam[2]):
        raise ValueError("Q_e must have exactly one negative eigenvalue; use normalized_conic")
    # 1/alpha^2 = -lambda_1/lambda_3, 1/beta^2 = -lambda_2/lambda_3  (eq. 35)
    ia2, ib2 = -lam[0] / lam[2], -lam[1] / lam[2]
    # Q_E = -Lambda / lambda_3 = diag(1/alpha^2, 1/beta^2, -1)  (eq. 36)
    QE = np.diag([ia2, ib2, -1.0])
    # delta^2 = (1 + 1/beta^2) / (1 + 1/alpha^2)  (eq. 42)
    delta = math.sqrt((1.0 + ib2) / (1.0 + ia2))
    r = mirror.rim_radius
    out = []
    for l in (0, 1):
        for m in (0, 1):
            U = _chen_U(delta, l, m)
            # -U^T Lambda U / lambda_3 = k Q_C  (eq. 28), Q_C of eq. 26
            M = U.T @ QE @ U
            k = M[0, 0]
            x0z, y0z = -M[0, 2] / k, -M[1, 2] / k
            q = M[2, 2] / k  # (x0^2 + y0^2 - r^2) / z0^2
            rz2 = x0z * x0z + y0z * y0z - q  # r^2 / z0^2
            if not (np.isfinite(rz2) and rz2 > 0):
                raise ValueError(
                    "the rim conic does not fit a circle seen by this camera "
                    "(numerically degenerate); check K and the boundary points"
                )
            z0 = r / math.sqrt(rz2)
            R = V @ U  # eq. 29
            C = R @ (z0 * np.array([x0z, y0z, 1.0]))  # C_C = R C_0
            if C[2] < 0:  # the rim is on the forward nappe of the cone
                C = -C
            axis = R[:, 2]
            tvec = C - mirror.z_rim * axis  # mirror origin = rim centre - z_rim * axis
            rvec = canonical_rvec(cv2.Rodrigues(R)[0].ravel())
            Rg = cv2.Rodrigues(rvec.reshape(3, 1))[0]
            reasons = physical_reasons(Rg, tvec, mirror, C)
            out.append(
                Candidate(
                    rvec=rvec,
                    tvec=tvec,
                    axis=axis,
                    rim_centre=C,
                    physical=not reasons,
                    reasons=reasons,
                    l=l,
                    m=m,
                )
            )
    return out


# -- the forward model of the rim ---------------------------------------------------------------
def rim_cone(R, tvec, mirror) -> FloatArray:
    """The cone ``Q_n`` of the rim seen from the camera: ``x~^T Q_n x~ = 0`` in normalised
    (undistorted) coordinates ``x~ = (x, y, 1)``.

    A ray ``s x~`` meets the rim plane at ``s = (z_rim + b_z) / a_z`` with ``a = R^T x~``,
    ``b = R^T tvec``; the rim circle then reads ``(w_1, a)^2 + (w_2, a)^2 - r^2 a_z^2 = 0``.
    """
    R = np.asarray(R, np.float64)
    b = R.T @ np.asarray(tvec, np.float64)
    h = mirror.z_rim + b[2]
    w1 = np.array([h, 0.0, -b[0]])
    w2 = np.array([0.0, h, -b[1]])
    e3 = np.array([0.0, 0.0, 1.0])
    W = np.outer(w1, w1) + np.outer(w2, w2) - mirror.rim_radius**2 * np.outer(e3, e3)
    Q = R @ W @ R.T
    return Q / np.linalg.norm(Q)


def rim_conic(K, R, tvec, mirror) -> FloatArray:
    """``Q_I = K^-T Q_n K^-1``: the rim ellipse in (undistorted) pixels, unit norm."""
    Ki = np.linalg.inv(np.asarray(K, np.float64))
    Q = Ki.T @ rim_cone(R, tvec, mirror) @ Ki
    return Q / np.linalg.norm(Q)
