"""Steps 4-5 of :func:`~.reflection_detect.detect_reflection`: one voted circle to the outline
of the camera's reflection, or the reason it is not one.

:func:`refine_silhouette` fits the outline to subpixel precision and checks it: round, smooth,
dark inside and with a darker core (the lens glass). A round dark silhouette without a core is a
:class:`Coreless`, one brighter inside than near its edge a :class:`BrightInside` (a dark
surround holding the body); :func:`~.reflection_detect.detect_reflection` decides what to do with
them, and neither reaches its caller.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from .errors import EstimationError
from .rim import fit_rim

__all__ = ["ReflectionFit"]


#: Inlier cut (px) of the consensus on the subpixel outline points (the cut then grows with the
#: points' own scatter, :func:`.rim.fit_rim`).
SUBPIXEL_INLIER_PX = 0.75


#: Subpixel rounds along rays from the current ellipse: at least two, more while the ellipse
#: still moves (by 0.05 px or more in its centre or axes), up to this many (a vote centred a
#: third of the radius off, e.g. on a box's edges, needs a third round).
SUBPIXEL_ROUNDS = 5


#: A silhouette is dark inside when this fraction of the annulus 0.6-0.95 of its radius is
#: darker than the dark centre plus 60 % of the contrast (for the voted circle and again for
#: the refined one).
DARK_INSIDE = 0.8


#: A silhouette is round when its ellipse's axes differ by at most this ratio. The outline of
#: a coaxial circle is nearly a circle (within about 1 % for tilts up to 5 deg, offsets up to
#: 5 mm and mild distortion), and a pixel aspect of a few % adds as much; an ellipse through
#: the barrel's edge on some rays and the glass's on others is flatter.
MAX_ASPECT = 1.1


@dataclasses.dataclass(frozen=True, eq=False)
class ReflectionFit:
    """The outline of the camera's reflection found by :func:`detect_reflection`.

    Attributes
    ----------
    points : (N, 2) float64 ndarray
        Subpixel outline points (outer dark-to-bright edge, inliers of the ellipse fit), px.
    center : (2,) float64 ndarray
        Centre of the fitted ellipse, px.
    radius : float
        Mean semi-axis of the fitted ellipse, px.
    rms : float
        RMS distance of ``points`` to the ellipse, px: the measurement's own scatter (the
        outline of a coaxial circle is close to, not exactly, an ellipse).
    quality : float
        Fraction of the search rays that gave an inlier edge point, in [0, 1].
    contrast : float
        Median grey-level rise across the outline.
    core : bool
        Whether the silhouette has a darker core (the lens glass). Only
        ``detect_reflection(..., allow_coreless=True)`` returns one without: a uniformly dark
        silhouette may be a camera with dark glass or a dark floor, which the caller tells apart
        by the size of its circle.
    """

    points: np.ndarray
    center: np.ndarray
    radius: float
    rms: float
    quality: float
    contrast: float
    core: bool = True

    def __post_init__(self):
        for name in ("points", "center"):
            arr = np.array(getattr(self, name), np.float64)
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)

    def __repr__(self):
        return (
            f"ReflectionFit(center=({self.center[0]:.2f}, {self.center[1]:.2f}), radius="
            f"{self.radius:.2f} px, points={len(self.points)}, rms={self.rms:.3f} px, "
            f"quality={self.quality:.2f}, contrast={self.contrast:.1f})"
        )


class Coreless(EstimationError):
    """A round dark silhouette without a darker core; ``fit`` is its :class:`ReflectionFit`."""

    def __init__(self, message, fit):
        super().__init__(message)
        self.fit = fit


class BrightInside(Coreless):
    """A round dark silhouette whose interior is brighter than its edge band: a dark surround
    (a dark floor, a dark holder) with something brighter, the camera's body, inside; or dark
    glass with bright highlights (``fit``, when nothing is found inside)."""

    def __init__(self, message, fit, interior, shell, spread):
        super().__init__(message, fit)
        self.radius, self.interior = float(fit.radius), float(interior)
        # the level of its edge band (0.75-0.95 of its radius), the 10-90 % spread of 0.85-0.93
        self.shell, self.spread = float(shell), float(spread)


def polar_samples(G, center, radii, angles):
    """Samples of ``G`` along rays: (n_angles, n_radii) float32 (bilinear, NaN outside)."""
    ca, sa = np.cos(angles)[:, None], np.sin(angles)[:, None]
    mx = (center[0] + ca * radii[None, :]).astype(np.float32)
    my = (center[1] + sa * radii[None, :]).astype(np.float32)
    out = cv2.remap(G, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)
    return out


def is_dark_inside(G, center, radius, angles, dark_max):
    """Whether a silhouette is dark inside: :data:`DARK_INSIDE` of the annulus 0.6-0.95 of
    ``radius`` about ``center`` (along ``angles``) is darker than ``dark_max`` (a dark scene
    line or ring is dark only along itself)."""
    band = polar_samples(G, center, np.linspace(0.6, 0.95, 8) * radius, angles)
    ok = np.isfinite(band)
    return bool(ok.any()) and float(np.mean(band[ok] < dark_max)) >= DARK_INSIDE


def core_and_shell(G, center, radius, angles):
    """Median grey of a silhouette's core (within half its radius) and of its edge band
    (0.75-0.95 of it): the lens glass is darker than the ring around it."""
    core = polar_samples(G, center, np.linspace(0.0, 0.5, 12) * radius, angles)
    shell = polar_samples(G, center, np.linspace(0.75, 0.95, 8) * radius, angles)
    return _finite_median(core), _finite_median(shell)


def _finite_median(values):
    """Median of the finite values; NaN (and no numpy warning) when there are none, as for a
    silhouette that lies outside the image."""
    v = np.asarray(values, np.float64)
    v = v[np.isfinite(v)]
    return float(np.median(v)) if v.size else math.nan


def _outermost_peak(d, strength=0.3, valley=0.5):
    """Per row of the radial derivative ``d`` (inside to outside), the index of the outermost
    rise: the steepest sample, or a local maximum outside it of at least ``strength`` times its
    height that is a separate edge (between the two, ``d`` falls below ``valley`` times the
    outer peak's height).

    The steepest sample alone is not the silhouette's edge on a knurled front ring: where a
    bright tooth meets dark glass the inner rise (the glass's edge) can be the steeper one.
    A shoulder of one blurred edge has no valley and does not count.
    """
    n = d.shape[1]
    d = np.where(np.isfinite(d), d, -np.inf)
    m = np.clip(np.argmax(d, axis=1), 1, n - 2)
    idx = np.arange(n)[None, :]
    peak = np.zeros(d.shape, bool)
    peak[:, 1:-1] = (d[:, 1:-1] > 0) & (d[:, 1:-1] >= d[:, :-2]) & (d[:, 1:-1] > d[:, 2:])
    low = np.minimum.accumulate(np.where(idx >= m[:, None], d, np.inf), axis=1)
    outer = (
        peak
        & (idx > m[:, None])
        & (d >= strength * d.max(axis=1, keepdims=True))
        & (low < valley * d)
    )
    last = n - 1 - np.argmax(outer[:, ::-1], axis=1)
    return np.where(outer.any(axis=1), last, m)


def refine_silhouette(gray, G, pts, c_est, r_est, bw, sig, levels, rng):
    """Steps 4-5 of :func:`detect_reflection` for one voted circle; ``levels`` is the contrast
    (scene minus dark centre) and the grey below which a pixel is dark."""
    contrast, dark_max = levels

    rad = np.hypot(pts[:, 0] - c_est[0], pts[:, 1] - c_est[1])
    near = np.abs(rad - (r_est + bw)) <= 2.5 * bw
    if near.sum() < 12:
        raise EstimationError("no camera reflection found: too few edge points on the circle")
    try:
        fit = fit_rim(pts[near], threshold=max(1.0, 2 * sig), rng=rng)
    except ValueError as err:
        raise EstimationError(f"no camera reflection found: {err}") from None
    # 4. subpixel rounds along rays from the ellipse's centre, narrow window
    G1 = cv2.GaussianBlur(gray, (0, 0), 0.7)
    n_rays = int(np.clip(2 * np.pi * float(fit.axes.mean()) / 2.0, 90, 1440))
    ang = np.linspace(0, 2 * np.pi, n_rays, endpoint=False)
    for k in range(SUBPIXEL_ROUNDS):
        c, axes = np.asarray(fit.center), np.asarray(fit.axes)
        e = np.stack([np.cos(ang), np.sin(ang)], axis=1)
        # radius of the ellipse along each ray: |S^-1 e| = 1 / r
        r_ray = 1.0 / np.linalg.norm(e @ np.linalg.inv(fit.shape_matrix).T, axis=1)
        w = max(3.0, 3.0 * fit.rms + 2.0 * sig)
        tau = np.arange(-w, w + 1e-9, 0.25)
        mx = (c[0] + e[:, :1] * (r_ray[:, None] + tau)).astype(np.float32)
        my = (c[1] + e[:, 1:] * (r_ray[:, None] + tau)).astype(np.float32)
        f = cv2.remap(
            G1, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan
        )
        d = np.gradient(f, axis=1)
        rise = f[:, -1] - f[:, 0]
        dd = np.where(np.isfinite(d), d, -np.inf)
        j = _outermost_peak(dd)
        good = np.isfinite(rise) & (rise > 0.15 * contrast) & np.isfinite(dd.max(axis=1))
        # the centroid of the rise within 1.5 px of its steepest sample: the parabola through
        # the peak scatters by 0.15 px on an exact anti-aliased disk, the centroid by 0.01 px
        dn = np.nan_to_num(d, nan=0.0)
        win = (np.abs(tau[None, :] - tau[j][:, None]) <= 1.5) & (dn > 0)
        wsum = (dn * win).sum(axis=1)
        loc = (dn * win * tau[None, :]).sum(axis=1) / np.where(wsum > 0, wsum, 1.0)
        p = c + (r_ray + loc)[:, None] * e
        p, rise_k = p[good], rise[good]
        if len(p) < 12:
            raise EstimationError("no camera reflection found: its outline faded on refinement")
        try:
            # a consensus of its own: where the barrel's edge does not contrast with what is
            # behind it (a strut, a patch of the scene as dark as the ring), the ray's only
            # rise is an inner one (the glass's edge) a few px inside, which a least-squares
            # ellipse would follow
            fit = fit_rim(p, threshold=SUBPIXEL_INLIER_PX, rng=rng)
        except ValueError as err:
            raise EstimationError(f"no camera reflection found: {err}") from None
        moved = float(np.abs(np.r_[fit.center - c, fit.axes - axes]).max())
        if k >= 1 and moved < 0.05:
            break
    quality = len(fit.points) / n_rays
    radius = float(np.mean(fit.axes))
    core_level, shell_level = core_and_shell(G, fit.center, radius, ang[::4])
    edge_rise = float(np.median(rise_k))
    why = None
    if quality < 0.4:
        why = f"its outline is found on only {100 * quality:.0f} % of the rays (need 40 %)"
    elif fit.axes[0] > MAX_ASPECT * fit.axes[1]:
        why = f"the silhouette is not round (axes {fit.axes[0]:.1f} and {fit.axes[1]:.1f} px)"
    elif fit.rms > max(0.75, 0.02 * radius):
        why = f"the silhouette's edge is ragged (RMS {fit.rms:.2f} px to an ellipse)"
    elif not is_dark_inside(G, fit.center, radius, ang[::2], dark_max):
        # the vote tested its own circle; the refined one may have moved to a dark scene line
        # around the camera (a thin ring is dark only along itself)
        why = "the refined silhouette is not dark inside (a dark line, not a body)"
    if why is not None:
        raise EstimationError(f"no camera reflection found: {why}")
    if not core_level < shell_level - max(3.0, 0.05 * contrast):
        why = (
            f"the silhouette has no darker core (grey {core_level:.0f} inside, "
            f"{shell_level:.0f} near its edge): no lens glass, e.g. a dark floor"
        )
    out = ReflectionFit(
        points=fit.points,
        center=fit.center,
        radius=radius,
        rms=float(fit.rms),
        quality=float(quality),
        contrast=edge_rise,
        core=why is None,
    )
    if why is not None:
        inside = polar_samples(G, fit.center, np.linspace(0.0, 0.6, 16) * radius, ang[::2])
        interior = float(np.nanpercentile(inside, 90))
        if interior > shell_level + max(3.0, 0.05 * contrast):  # brighter things inside
            band = polar_samples(G, fit.center, np.linspace(0.85, 0.93, 4) * radius, ang)
            spread = float(np.subtract(*np.nanpercentile(band, [90, 10])))
            raise BrightInside(
                f"no camera reflection found: {why}", out, interior, shell_level, spread
            )
        raise Coreless(f"no camera reflection found: {why}", out)
    return out
