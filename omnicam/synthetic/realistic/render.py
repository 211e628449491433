"""Images: :func:`render_rig` (supersampled near edges, area-true) and :func:`degrade` (blur,
vignetting, sensor noise, JPEG)."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from .optics import CameraNumbers
from .scene import Photometric, Rig
from .tracer import trace_many


@dataclasses.dataclass(frozen=True)
class Rendering:
    """A clean render (before :func:`degrade`).

    Attributes
    ----------
    image : (h, w, 3) float32 ndarray
        Linear BGR, 0..255.
    labels : (h, w) int8 ndarray
        :data:`LABELS` of each pixel centre.
    coverage : (h, w) float32 ndarray
        Fraction of each pixel's samples whose primary ray meets the mirror inside the rim
        (struts in front of it not counted).
    side_seen : bool
        Whether any sample hit the barrel's side (then its back edge joins the circles).
    """

    image: np.ndarray
    labels: np.ndarray
    coverage: np.ndarray
    side_seen: bool


def rim_box(num):
    """Integer pixel bounds that can see the mirror (rim circle projected, plus margin)."""
    phi = np.linspace(0.0, 2.0 * np.pi, 721)
    rim = np.stack(
        [num.rim * np.cos(phi), num.rim * np.sin(phi), np.full_like(phi, num.z_rim)], axis=1
    )
    xc = rim @ num.R.T + num.t
    xn = xc[:, :2] / xc[:, 2:3]
    if num.D is None:
        px = xn @ num.K[:2, :2].T + num.K[:2, 2]
    else:
        obj = np.concatenate([xn, np.ones((len(xn), 1))], axis=1)
        p, _ = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), np.eye(3), num.D)
        px = p.reshape(-1, 2) @ num.K[:2, :2].T + num.K[:2, 2]
    lo = np.floor(px.min(axis=0)) - 3
    hi = np.ceil(px.max(axis=0)) + 3
    return lo, hi


def render_rig(camera, rig=None, supersample=3):
    """Render what the truth camera sees of the rig (no photometric degradation).

    Parameters
    ----------
    camera : MisalignedHyperbolicCamera
        With ``image_size``.
    rig : Rig or None
    supersample : int
        ``s``: ``s x s`` samples per pixel (1..8), taken where the pixel centres of a 3x3
        neighbourhood differ in label or by more than 4 grey levels (every edge); elsewhere the
        pixel centre alone (the image is smooth there).

    Returns
    -------
    Rendering
    """
    num = CameraNumbers(camera)
    rig = Rig() if rig is None else rig
    if isinstance(supersample, bool) or not isinstance(supersample, (int, np.integer)):
        raise ValueError(f"supersample must be an integer from 1 to 8, got {supersample!r}")
    s = int(supersample)
    if not 1 <= s <= 8:
        raise ValueError(f"supersample must be an integer from 1 to 8, got {supersample!r}")
    w, h = num.size
    if rig.background is None:
        bg = np.full((h, w, 3), 14.0, np.float32)
    else:
        bg = np.asarray(rig.background, np.float32)
        if bg.shape != (h, w, 3):
            raise ValueError(f"rig.background must be ({h}, {w}, 3), got {bg.shape}")
    img = bg.copy()
    labels = np.zeros((h, w), np.int8)
    coverage = np.zeros((h, w), np.float32)
    lo, hi = rim_box(num)
    if rig.holder is not None:  # the holder's outer edge reaches farther
        scale = max(rig.holder.outer_axes) / num.rim
        mid = 0.5 * (lo + hi)
        lo, hi = mid - (mid - lo) * scale * 1.05, mid + (hi - mid) * scale * 1.05
    x0, y0 = max(0, int(lo[0])), max(0, int(lo[1]))
    x1, y1 = min(w - 1, int(hi[0])), min(h - 1, int(hi[1]))
    side_seen = False
    if x0 <= x1 and y0 <= y1:
        nx, ny = x1 - x0 + 1, y1 - y0 + 1
        gx, gy = np.meshgrid(np.arange(x0, x1 + 1), np.arange(y0, y1 + 1))
        centres = np.stack([gx.ravel(), gy.ravel()], axis=1).astype(np.float64)
        block_bg = bg[y0 : y1 + 1, x0 : x1 + 1].reshape(-1, 3)
        # pass 1: pixel centres
        lab, col, on = trace_many(num, rig, centres)
        side_seen |= bool((lab == 7).any())
        col = np.where((lab == 0)[:, None], block_bg, col).astype(np.float32)
        cov = on.astype(np.float32)
        if s > 1:
            # pass 2: s x s samples where the centres of a 3x3 neighbourhood disagree (an
            # edge of any kind: rim, body, struts, scene), so every edge is area-true
            k = np.ones((3, 3), np.uint8)
            lab2 = lab.reshape(ny, nx).astype(np.uint8)
            need = cv2.dilate(lab2, k) != cv2.erode(lab2, k)
            col2 = col.reshape(ny, nx, 3)
            spread = (cv2.dilate(col2, k) - cv2.erode(col2, k)).max(axis=2)
            need |= spread > 4.0
            idx = np.flatnonzero(need.ravel())
            if len(idx):
                off = (np.arange(s) + 0.5) / s - 0.5
                ox, oy = np.meshgrid(off, off)
                offs = np.stack([ox.ravel(), oy.ravel()], axis=1)
                sub = (centres[idx][:, None, :] + offs[None, :, :]).reshape(-1, 2)
                lab_s, col_s, on_s = trace_many(num, rig, sub)
                side_seen |= bool((lab_s == 7).any())
                bg_s = np.repeat(block_bg[idx], s * s, axis=0)
                col_s = np.where((lab_s == 0)[:, None], bg_s, col_s)
                col[idx] = col_s.reshape(len(idx), s * s, 3).mean(axis=1)
                cov[idx] = on_s.reshape(len(idx), s * s).mean(axis=1)
        img[y0 : y1 + 1, x0 : x1 + 1] = col.reshape(ny, nx, 3)
        labels[y0 : y1 + 1, x0 : x1 + 1] = lab.reshape(ny, nx)
        coverage[y0 : y1 + 1, x0 : x1 + 1] = cov.reshape(ny, nx)
    return Rendering(image=img, labels=labels, coverage=coverage, side_seen=side_seen)


def degrade(image, photometric, seed=0):
    """Vignetting, blur, sensor noise, rounding to uint8 and JPEG, as :class:`Photometric` says.

    Returns
    -------
    (h, w, 3) uint8 ndarray
    """
    img = np.array(image, np.float32)
    h, w = img.shape[:2]
    p = photometric or Photometric()
    if p.vignette > 0:
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        r2 = ((xx - (w - 1) / 2) ** 2 + (yy - (h - 1) / 2) ** 2) / (
            ((w - 1) / 2) ** 2 + ((h - 1) / 2) ** 2
        )
        img *= (1.0 - p.vignette * r2)[..., None]
    if p.blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), p.blur_sigma)
    if p.noise_sigma > 0:
        rng = np.random.default_rng(seed)
        sd = np.sqrt(p.noise_sigma**2 + 0.05 * np.clip(img, 0, None))
        img = img + rng.standard_normal(img.shape, dtype=np.float32) * sd
    out = np.clip(np.round(img), 0, 255).astype(np.uint8)
    if p.jpeg_quality is not None:
        ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(p.jpeg_quality)])
        if not ok:
            raise ValueError("JPEG encoding failed")
        out = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    return out
