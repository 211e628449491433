"""Detection of the camera's reflection in an image: :func:`detect_reflection`.

Radial profiles from the image of the camera centre, a vote over circles for the round dark
silhouettes their dark-to-bright rises support, the outermost refined and checked
(:mod:`.reflection_silhouette`); inside a dark surround (a dark floor holding the body) the
search runs again.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from ..images import to_gray
from .errors import EstimationError
from .reflection_silhouette import (
    BrightInside,
    Coreless,
    ReflectionFit,
    core_and_shell,
    is_dark_inside,
    polar_samples,
    refine_silhouette,
)
from .rim import RimFit, fit_rim
from .robust import mad_sigma

__all__ = ["detect_reflection"]


#: A dark-to-bright rise votes for a silhouette when it exceeds this fraction of the contrast
#: between the dark centre and the mirror's scene: a fifth first; when that finds nothing, or
#: only a silhouette without a core, a tenth (kept if it finds one with a core around the
#: coreless one, else the coreless one stands): the barrel's front ring against a dark box
#: behind it may rise by a fifth of the contrast or less. A tenth at once would let the glass's
#: inner rings vote and win over a uniformly dark barrel.
RISE_FRACTIONS = (0.2, 0.1)


def detect_reflection(
    image,
    rim,
    *,
    center=None,
    center_search=0.08,
    max_radius=0.6,
    min_radius=0.03,
    rng=0,
    allow_coreless=False,
) -> ReflectionFit:
    """Find the outermost round dark silhouette around the image of the camera centre.

    1. Radial profiles from ``center`` (default the rim centre) out to ``max_radius`` times the
       rim's minor semi-axis, of the image smoothed in proportion to the rim's size.
    2. Per ray, every strong dark-to-bright rise (local maximum of the radial derivative whose
       rise exceeds a fraction of the contrast between the dark centre and the mirror's
       scene, with a dark inner side): a fifth first, a tenth when that finds nothing or only
       a silhouette without a core (:data:`RISE_FRACTIONS`; a barrel on a dark box rises
       little); highlights and inner rings of the glass give inner rises, struts and scene
       edges give rises off the common circle.
    3. A vote over circle centres near ``center`` and radii (one vote per ray and radius bin)
       finds the round silhouettes that are dark inside; the **outermost** one supported by at
       least 40 % of the rays is kept (the lens barrel or body, not the glass's inner rings;
       bins within two of a group's outermost are one circle).
    4. The rises near that circle, then a robust ellipse (RANSAC, :func:`.rim.fit_rim`) rejects
       struts and highlights (first on the rises at least ``min_radius`` from ``center``, then, if
       that declines, on those from 3 px: a small lens off ``center`` has its near side there); then
       rounds (2 to :data:`~.reflection_silhouette.SUBPIXEL_ROUNDS`, until the ellipse stops moving)
       along rays from the ellipse's centre in a narrow window, unsmoothed but for 0.7 px: per ray
       the outermost separate rise (a narrow front ring's inner rise may be the steeper), at the
       centroid of the radial derivative within 1.5 px of its peak; a consensus ellipse through them
       (RANSAC, :data:`~.reflection_silhouette.SUBPIXEL_INLIER_PX`) leaves out the rays where the
       edge does not contrast and an inner rise stands in.
    5. Declines (:class:`~.errors.EstimationError`) when the centre is not darker than the scene, no
       round silhouette has enough support, the refined one is not round
       (:data:`~.reflection_silhouette.MAX_ASPECT`), ragged or not dark inside, or the silhouette
       has no darker core (the lens glass; a uniformly dark floor or clutter has none). A silhouette
       inside a declined dark one must lie within it (and, if that one is uniformly dark, be
       concentric with it: its own glass's rings).
    6. A silhouette brighter inside than near its edge (90th percentile of its inner 60 %) is
       a dark surround, e.g. a dark floor, holding the body: when no silhouette is accepted,
       steps 1-5 run once more inside it (to 85 % of its radius), with its interior's level
       as the scene's (the body's edges rise against the body, not against the mirror's
       scene).
    7. If that finds nothing and the surround is uniform, the body's edge may fall to the
       surround's level (a grey front ring on a black floor): per ray the outermost crossing
       from above to below the level halfway between the surround's and its interior's,
       then steps 4-5 on the negated image (:func:`_body_in_surround`).

    Parameters
    ----------
    image : (H, W) or (H, W, 3|4) ndarray
        Grey or BGR(A) image, uint8, uint16 or float.
    rim : RimFit
        The rim (its centre and size bound the search).
    center : (2,) array_like, optional
        Where to look (e.g. the mean of the candidates' self-reflection pixels); default the rim
        centre.
    center_search : float
        The silhouette's centre is sought within this many rim semi-axes of ``center``.
    max_radius, min_radius : float
        Search radii in units of the rim's minor semi-axis.
    rng : int or numpy.random.Generator
        Seed of the RANSAC sampling.
    allow_coreless : bool
        Instead of declining, return the first round dark silhouette that only lacked a darker
        core (``ReflectionFit.core`` False): the calibration keeps it only if its circle is
        camera-sized (:func:`omnicam.calibration.steps.reflection_step`).

    Returns
    -------
    ReflectionFit

    Raises
    ------
    EstimationError
        No camera reflection found (the message says why); the calibration then goes on
        without it.
    ValueError
        Bad arguments.
    """
    coreless, found = None, None
    for k, fraction in enumerate(RISE_FRACTIONS):
        try:
            fit = _detect(
                image, rim, center, center_search, max_radius, min_radius, rng, None, fraction
            )
        except Coreless as err:
            coreless = coreless or err
            continue
        except EstimationError:
            if k == len(RISE_FRACTIONS) - 1 and coreless is None and found is None:
                raise
            continue
        # the weaker rises may find a silhouette with a core around the one found (or the one
        # without a core): the outermost is the body's (a knurled front ring around dark glass
        # taken for a dark surround, or around its own inner rings)
        inner = found or (coreless.fit if coreless is not None else None)
        if inner is None or (fit.radius > inner.radius + 1.0 and _inside(inner, fit, 1.0)):
            found = fit
    if found is not None:
        return found
    assert coreless is not None  # nothing found and nothing raised: a coreless one was
    if allow_coreless:
        return coreless.fit
    raise EstimationError(str(coreless)) from None


def _detect(image, rim, center, center_search, max_radius, min_radius, rng, scene_level, fraction):
    """:func:`detect_reflection`; ``scene_level`` (grey) replaces the mirror scene's level when
    looking inside a dark surround."""
    if not isinstance(rim, RimFit):
        raise ValueError(
            f"rim must be a RimFit (from detect_rim or fit_rim), got {type(rim).__name__}"
        )
    if not (0 < min_radius < max_radius <= 1.0) or not (0 <= center_search <= 0.5):
        raise ValueError(
            "need 0 < min_radius < max_radius <= 1 and 0 <= center_search <= 0.5 (units of "
            "the rim's semi-axis)"
        )
    gray = to_gray(image)
    r_rim = float(min(rim.axes))
    c0 = np.asarray(rim.center if center is None else center, np.float64).reshape(2)
    if not np.isfinite(c0).all():
        raise ValueError("center must be a finite pixel")
    R_max, R_min = max_radius * r_rim, max(3.0, min_radius * r_rim)
    sig = max(0.7, r_rim / 300.0)
    G = cv2.GaussianBlur(gray, (0, 0), sig)
    n_rays = int(np.clip(2 * np.pi * R_max / 6.0, 180, 720))
    ang = np.linspace(0, 2 * np.pi, n_rays, endpoint=False)
    dr = max(0.5, sig / 2)
    radii = np.arange(0.0, R_max, dr)
    prof = polar_samples(G, c0, radii, ang)
    # levels: the dark centre and the mirror's scene (a ring well inside the rim)
    centre = prof[:, radii < max(R_min, 0.05 * r_rim)]
    ring = polar_samples(G, c0, np.linspace(0.7, 0.9, 16) * r_rim, ang)
    near = np.abs(np.diff(polar_samples(gray, c0, radii[:40], ang), axis=1))
    if min(np.isfinite(a).sum() for a in (centre, ring, near)) < 16:
        raise EstimationError(
            f"no camera reflection found: the place to look, ({c0[0]:.0f}, {c0[1]:.0f}), is "
            f"not in the image"
        )
    dark, scene = float(np.nanmedian(centre)), float(np.nanmedian(ring))
    if scene_level is not None:  # inside a dark surround: its interior is the scene
        scene = float(scene_level)
    contrast = scene - dark
    noise = mad_sigma(near)
    if not (np.isfinite(contrast) and contrast > max(10.0, 4.0 * noise)):
        raise EstimationError(
            f"no camera reflection found: the centre (grey {dark:.0f}) is not clearly darker "
            f"than the mirror's scene (grey {scene:.0f})"
        )
    ri, rj = _rises(prof, dr, fraction * contrast, dark + 0.6 * contrast)
    # rises from 3 px of c0 on: a small lens off c0 has its near side nearer than R_min; they
    # vote, and step 4 tries the rises beyond R_min first (highlights lie near c0), then all
    keep = radii[rj] >= (3.0 if scene_level is None else R_min)  # (not inside a surround)
    ri, rj = ri[keep], rj[keep]
    if len(ri) < 0.3 * n_rays:
        raise EstimationError(
            f"no camera reflection found: too few dark-to-bright edges around ({c0[0]:.0f}, "
            f"{c0[1]:.0f})"
        )
    pts = c0 + radii[rj, None] * np.stack([np.cos(ang[ri]), np.sin(ang[ri])], axis=1)
    far_pts = pts[radii[rj] >= R_min]
    dark_max = dark + 0.6 * contrast

    def dark_inside(rho, c):
        return is_dark_inside(G, c, rho, ang[::2], dark_max)

    # 3. vote over centres within center_search of c0 (steps of 1 % of the rim) and radii
    half = float(center_search) * r_rim
    offs = np.linspace(-half, half, int(np.clip(np.ceil(half / (0.01 * r_rim)) + 1, 9, 31)))
    bw = max(2.0, 0.025 * R_max)
    seeds = _vote_circles(pts, ri, c0, offs, bw, R_max, R_min, n_rays, dark_inside)
    fit, first_why, surround, coreless = _try_silhouettes(
        gray,
        G,
        seeds,
        (far_pts, pts) if len(pts) > len(far_pts) else (pts,),
        bw,
        sig,
        (contrast, dark_max),
        rng,
    )
    if fit is not None:
        return fit
    if scene_level is None and surround is not None:
        try:
            return _inside_surround(
                image,
                rim,
                c0,
                center_search,
                min_radius,
                rng,
                fraction,
                (gray, G, surround, bw, sig),
            )
        except Coreless as err:  # a uniformly dark body in the surround, rather than it
            coreless = err
        except EstimationError:
            pass
    raise coreless or first_why


def _inside_surround(image, rim, c0, center_search, min_radius, rng, fraction, found):
    """Steps 6-7 of :func:`detect_reflection`: the body inside the dark surround of ``found``
    (``gray, G, surround, bw, sig`` of the search that found it), or
    :class:`~.errors.EstimationError` (a :class:`Coreless` for a uniformly dark body)."""
    gray, G, surround, bw, sig = found
    inner = 0.85 * surround.radius / float(min(rim.axes))
    if not inner > 2.0 * min_radius:
        raise EstimationError("no camera reflection found: the dark surround is too small")
    # 6. the body's edges rise against the surround's interior, not against the mirror's
    # scene; look again inside, once per rise fraction (the body may contrast little with
    # what is around it inside the surround)
    for f in RISE_FRACTIONS[RISE_FRACTIONS.index(fraction) :]:
        try:
            return _detect(
                image, rim, c0, center_search, inner, min_radius, rng, surround.interior, f
            )
        except Coreless:
            break
        except EstimationError:
            pass
    # 7. a body brighter than the surround at its edge (a grey front ring on a dark floor)
    return _body_in_surround(gray, G, surround, bw, sig, rng)


def _rises(prof, dr, min_rise, dark_max, k=3):
    """Per ray, radii of strong dark-to-bright rises: local maxima of the radial derivative
    whose rise over +-k samples exceeds ``min_rise`` with the inner side below ``dark_max``.

    Returns (ray index, radius index) arrays."""
    d = np.gradient(prof, axis=1) / dr
    inner = np.full_like(prof, np.nan)
    outer = np.full_like(prof, np.nan)
    inner[:, k:] = prof[:, :-k]
    outer[:, :-k] = prof[:, k:]
    with np.errstate(invalid="ignore"):
        peak = (d > 0) & (d >= np.roll(d, 1, axis=1)) & (d > np.roll(d, -1, axis=1))
        strong = (outer - inner > min_rise) & (inner < dark_max)
    peak[:, :k] = False
    peak[:, -k:] = False
    return np.nonzero(peak & strong)


def _vote_circles(pts, ri, c0, offs, bw, R_max, R_min, n_rays, dark_inside):
    """Step 3 of :func:`detect_reflection`: the round dark silhouettes the rises ``pts`` (on
    rays ``ri`` of ``n_rays`` from ``c0``) support, outermost first, as up to four ``(centre,
    radius)`` seeds.

    One vote per (ray, radius bin of ``bw`` px, two bins overlapping) for each centre
    ``c0 + (ox, oy)`` (``ox``, ``oy`` in ``offs``); a radius counts where at least 40 % of
    the rays vote and ``dark_inside(radius, centre)``.
    """
    nb = int(R_max / bw) + 2
    found = {}  # radius bin -> (support, centre): the best centre for each supported radius
    for ox in offs:
        for oy in offs:
            c = c0 + (ox, oy)
            rad = np.hypot(pts[:, 0] - c[0], pts[:, 1] - c[1])
            b = np.clip((rad / bw).astype(int), 0, nb - 1)
            hist = np.zeros(nb)
            for shift in (0, 1):  # bins of 2 bw, overlapping
                key = np.unique(ri * nb + np.clip(b - shift, 0, nb - 1))
                h = np.bincount(key % nb, minlength=nb)
                hist = np.maximum(hist, np.r_[h[shift:], np.zeros(shift)] if shift else h)
            for j in np.flatnonzero((hist >= 0.4 * n_rays) & (np.arange(nb) * bw >= R_min)):
                if int(j) not in found or hist[j] > found[int(j)][0]:
                    found[int(j)] = (hist[j], c)
    # circles dark inside, outermost first; bins within 2 of a group's outermost are one circle
    # (its best centre); a chain of neighbours is not: a knurled front ring a few bins wide
    # would otherwise merge the barrel's edge with the glass's
    order = [j for j in sorted(found, reverse=True) if dark_inside((j + 1) * bw, found[j][1])]
    circles = []
    for j in order:
        if circles and circles[-1][1] - j <= 2:
            if found[j][0] > found[circles[-1][0]][0]:
                circles[-1] = (j, circles[-1][1])
            continue
        circles.append((j, j))
    if not circles:
        raise EstimationError(
            "no camera reflection found: no round dark silhouette around the image centre "
            "(edges on fewer than 40 % of the rays share a circle that is dark inside)"
        )
    return [(found[j][1], j * bw) for j, _ in circles[:4]]


def _body_in_surround(gray, G, surround, bw, sig, rng):
    """Step 7 of :func:`detect_reflection`: the body inside the dark surround ``surround`` (a
    :class:`BrightInside`) where its edge falls to the surround's level.

    Only in a uniform surround (the 10-90 % spread of its grey at 0.85-0.93 of its radius
    within half the contrast). Per ray from the surround's centre (within 90 % of its
    radius) the outermost crossing, going out, from above to below the level halfway between
    the surround's and its interior's; a robust ellipse through them; then steps 4-5 on the
    negated image (the fall is a rise there), the core tested on the image itself.
    """
    c, floor, interior = surround.fit.center, surround.shell, surround.interior
    contrast = interior - floor
    if not (contrast > 10.0 and surround.spread < 0.5 * contrast):
        # a textured band is no dark floor or holder: a checkered ground spreads by more than
        # the contrast, a dark floor with planks, noise and blur by a small part of it
        raise EstimationError(
            "no camera reflection found: no uniformly dark surround with something brighter inside"
        )
    r_max = 0.9 * surround.radius
    n_rays = int(np.clip(2 * np.pi * r_max / 3.0, 90, 720))
    ang = np.linspace(0, 2 * np.pi, n_rays, endpoint=False)
    dr = max(0.5, sig / 2)
    radii = np.arange(2 * dr, r_max, dr)
    prof = polar_samples(G, c, radii, ang)
    above = np.nan_to_num(prof, nan=-np.inf) > floor + 0.5 * contrast
    seen = above.any(axis=1)
    last = len(radii) - 1 - np.argmax(above[:, ::-1], axis=1)
    ok = seen & (last < len(radii) - 1)
    if ok.sum() < 0.4 * n_rays:
        raise EstimationError("no camera reflection found: no body's edge inside the surround")
    e = np.stack([np.cos(ang[ok]), np.sin(ang[ok])], axis=1)
    pts = c + radii[last[ok], None] * e
    try:
        fit0 = fit_rim(pts, threshold=max(1.0, 2 * sig), rng=rng)
    except ValueError as err:
        raise EstimationError(f"no camera reflection found: {err}") from None
    r0 = float(np.mean(fit0.axes))
    neg = 255.0 - gray
    try:  # on the negated image the surround is bright and nothing needs to be dark inside
        fit = refine_silhouette(
            neg, 255.0 - G, pts, fit0.center, r0 - bw, bw, sig, (contrast, np.inf), rng
        )
    except Coreless as err:
        fit = err.fit
    if not fit.radius < r_max:
        raise EstimationError("no camera reflection found: the body fills the surround")
    core_level, shell_level = core_and_shell(G, fit.center, fit.radius, ang[::4])
    margin = max(3.0, 0.05 * contrast)
    if core_level < shell_level - margin:
        return dataclasses.replace(fit, core=True)
    if core_level > shell_level + margin:  # a highlight on dark glass: the surround stands
        raise EstimationError(
            f"no camera reflection found: the spot inside the dark surround is brighter inside "
            f"(grey {core_level:.0f}) than near its edge ({shell_level:.0f}): a highlight"
        )
    raise Coreless(  # a uniformly dark body: the caller decides, as for any such silhouette
        f"no camera reflection found: the body inside the dark surround has no darker core "
        f"(grey {core_level:.0f} inside, {shell_level:.0f} near its edge)",
        dataclasses.replace(fit, core=False),
    )


def _try_silhouettes(gray, G, seeds, point_sets, bw, sig, levels, rng):
    """Steps 4-5 on the voted circles ``seeds`` (centre, radius), outermost first.

    Returns ``(fit, first_why, surround, coreless)``: the first silhouette accepted (else
    None), the first reason one was declined, the first dark surround holding something
    brighter (:class:`BrightInside`) and the first silhouette without a darker core
    (:class:`Coreless`).
    """
    first_why, surround, coreless = None, None, None
    for c_est, r_est in seeds:
        for p in point_sets:
            try:
                fit = refine_silhouette(gray, G, p, c_est, r_est, bw, sig, levels, rng)
                if coreless is None or _within(fit, coreless, max(1.0, 2.0 * sig)):
                    return fit, first_why, surround, coreless
                # not a body inside the dark silhouette but an ellipse that wandered off an
                # inner ring (struts, highlights)
                break
            except BrightInside as err:  # a dark surround (e.g. a dark floor) holding the body
                first_why, surround = first_why or err, surround or err
                coreless = coreless or err
                break
            except Coreless as err:  # dark glass or a dark floor: the caller decides
                first_why, coreless = first_why or err, coreless or err
                break
            except EstimationError as err:  # e.g. a square box behind the barrel: try inside it
                first_why = first_why or err
    return None, first_why, surround, coreless


def _within(fit, outer, tol):
    """Whether ``fit`` may be what the declined dark silhouette ``outer`` (a :class:`Coreless`)
    holds: inside it (:func:`_inside`) and, unless ``outer`` is brighter inside (a dark
    surround holding a body, :class:`BrightInside`), concentric with it to a tenth of its
    radius: a uniformly dark silhouette holds only its own glass's rings."""
    if not isinstance(outer, BrightInside):
        off = float(np.linalg.norm(fit.center - outer.fit.center))
        if off > max(tol, 0.1 * outer.fit.radius):
            return False
    return _inside(fit, outer.fit, tol)


def _inside(fit, outer, tol):
    """Whether the whole ellipse through ``fit``'s outline points lies within ``tol`` px outside
    ``outer``'s outline (radii about ``outer``'s centre, interpolated over the angle)."""
    try:
        ell = fit_rim(fit.points, robust=False)
    except ValueError:
        return False
    ang = np.linspace(0.0, 2.0 * np.pi, 72, endpoint=False)
    e = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    r_ray = 1.0 / np.linalg.norm(e @ np.linalg.inv(ell.shape_matrix).T, axis=1)
    curve = np.asarray(ell.center) + r_ray[:, None] * e

    def polar(p):
        d = np.asarray(p) - outer.center
        return np.arctan2(d[:, 1], d[:, 0]), np.hypot(d[:, 0], d[:, 1])

    ta, ra = polar(outer.points)
    order = np.argsort(ta)
    tb, rb = polar(curve)
    limit = np.interp(tb, ta[order], ra[order], period=2.0 * np.pi)
    return bool(np.all(rb <= limit + tol))
