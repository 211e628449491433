"""A camera body seen in the mirror as real rigs show it: a lens barrel in front of a wider box.

Independent of the estimator (:mod:`omnicam.calibration.reflection`): rays are traced with
``camera.unproject`` and tested against the solids directly. The barrel is a cylinder of radius
``r`` coaxial with the optical axis from ``z_box`` to ``z`` (camera frame), its front face dark
glass inside ``glass * r``; behind it a square box of half-width ``box`` whose front face is at
``z_box``. The scene comes from :func:`omnicam.synthetic.render_environment` without the ball.
"""

import numpy as np

from omnicam import synthetic

GLASS, BARREL, BOX = 8.0, 48.0, 105.0


def hits(camera, pixels, r, z, glass=0.7, box=None, z_box=None):
    """Grey level of the body for each pixel's reflected ray, NaN where it sees the scene."""
    P, V = camera.unproject(pixels)
    R, t = camera.R, camera.tvec
    Pc, Vc = P @ R.T + t, V @ R.T
    out = np.full(len(pixels), np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = (z - Pc[:, 2]) / Vc[:, 2]
        X = Pc + s[:, None] * Vc
        rho = np.hypot(X[:, 0], X[:, 1])
        front = (s > 0) & (rho <= r)
        out[front] = np.where(rho[front] <= glass * r, GLASS, BARREL)
        if box is not None:
            s2 = (z_box - Pc[:, 2]) / Vc[:, 2]
            X2 = Pc + s2[:, None] * Vc
            side = (s2 > 0) & ~front & (np.hypot(X2[:, 0], X2[:, 1]) <= r)
            out[side] = BARREL
            face = (s2 > 0) & ~front & ~side & (np.abs(X2[:, 0]) <= box) & (np.abs(X2[:, 1]) <= box)
            out[face] = BOX
    return out


def render(
    camera, r=9.0, z=12.0, glass=0.7, box=16.0, z_box=2.0, supersample=3, scene=None, window=0.6
):
    """Grey-scale render (uint8) of the scene with the barrel and box blended in per subpixel."""
    if scene is None:
        scene = synthetic.render_environment(camera, supersample=2, body_radius=None)
    img = scene.astype(np.float32)
    if img.ndim == 3:
        img = img @ np.float32([0.114, 0.587, 0.299])
    rim = camera.rim_image_points(360)
    c = rim.mean(axis=0)
    half = window * 0.5 * (rim.max(axis=0) - rim.min(axis=0)).min()
    x0, x1 = int(c[0] - half), int(c[0] + half)
    y0, y1 = int(c[1] - half), int(c[1] + half)
    s = supersample
    off = (np.arange(s) + 0.5) / s - 0.5
    xs = (np.arange(x0, x1)[:, None] + off).ravel()
    ys = (np.arange(y0, y1)[:, None] + off).ravel()
    gx, gy = np.meshgrid(xs, ys)
    g = hits(camera, np.stack([gx.ravel(), gy.ravel()], 1), r, z, glass, box, z_box)
    g = g.reshape(y1 - y0, s, x1 - x0, s)
    cov = np.isfinite(g).mean(axis=(1, 3))
    body = np.nansum(g, axis=(1, 3)) / (s * s)
    block = img[y0:y1, x0:x1]
    img[y0:y1, x0:x1] = block * (1 - cov) + body
    return np.clip(np.round(img), 0, 255).astype(np.uint8)
