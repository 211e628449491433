"""The demo's scene: far straight lines drawn into the environment, and the pixels clicked."""

from __future__ import annotations

import math

import cv2
import numpy as np

# -- demo -------------------------------------------------------------------------------------
#: Far straight lines of the demo scene: lines at infinity, i.e. great circles of directions,
#: each given by its plane's normal as (tilt from the mirror axis, azimuth) in degrees. Tilted
#: circles separate Chen's two physical postures far better than the vertical poles do.
DEMO_FAR_LINES = ((30.0, 0.0), (30.0, 120.0), (30.0, 240.0))

DEMO_CLICK_NOISE_PX = 0.2  # as if a user had clicked along them


DEMO_LINE_COLOR = (0, 160, 255)  # BGR orange


def great_circle(tilt_deg, azimuth_deg, n=720):
    """``(n, 3)`` unit directions of the line at infinity whose plane has the given normal."""
    t, a = math.radians(tilt_deg), math.radians(azimuth_deg)
    normal = np.array([math.sin(t) * math.cos(a), math.sin(t) * math.sin(a), math.cos(t)])
    u = np.cross(normal, (0.0, 0.0, 1.0)) if t > 1e-9 else np.array([1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    th = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.outer(np.cos(th), u) + np.outer(np.sin(th), v)


def demo_environment(lines=DEMO_FAR_LINES):
    """:func:`omnicam.synthetic.make_environment` with the demo's far lines drawn in."""
    from . import equirect_coords, make_environment

    env = make_environment()
    h, w = env.shape[:2]
    radius = max(1, int(round(0.3 * w / 360.0)))  # lines 0.6 deg wide, as the environment's
    for tilt, az in lines:
        x, y = equirect_coords(great_circle(tilt, az, 8 * w), (w, h))
        for xi, yi in zip(np.round(x).astype(int), np.round(y).astype(int)):
            cv2.circle(env, (int(xi) % w, int(yi)), radius, DEMO_LINE_COLOR, -1)
    return env


def demo_far_lines(
    camera,
    lines=DEMO_FAR_LINES,
    max_elevation_deg=10.0,
    n=60,
    noise_px=DEMO_CLICK_NOISE_PX,
    seed=0,
):
    """Pixels along the images of the demo's far lines, as a user would click them.

    The directions of each great circle up to ``max_elevation_deg`` (well inside the rim),
    projected exactly by ``camera`` (points at infinity), ``n`` per line, plus seeded Gaussian
    click noise of ``noise_px``.
    """
    rng = np.random.default_rng(seed)
    out = []
    for tilt, az in lines:
        d = great_circle(tilt, az, 16 * n)
        d = d[d[:, 2] <= math.sin(math.radians(max_elevation_deg))]
        px = camera.project_directions(d)
        px = px[np.isfinite(px).all(axis=1)]
        px = px[np.linspace(0, len(px) - 1, min(n, len(px))).astype(int)]
        out.append(px + rng.normal(scale=noise_px, size=px.shape))
    return out
