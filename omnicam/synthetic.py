"""Synthetic rigs and ground-truth renders for tests, examples and benchmarks (paper Fig. 6).

The rigs here are the canonical ones every test, example and benchmark uses: a HyperOmni-style
mirror seen by a 500x500 camera (the paper's synthetic image size), aligned or misaligned.
"""
from __future__ import annotations

import numpy as np

from .camera import MisalignedHyperbolicCamera
from .mirror import HyperbolicMirror

__all__ = ["default_mirror", "aligned_rig", "misaligned_rig", "random_misaligned_rig"]


def default_mirror():
    """A HyperOmni-style mirror: ``a = 23.4``, ``b = 28.1``, rim radius 30 mm.

    Seen from the lower focus it shows elevations from -90 deg up to about +17 deg.
    """
    return HyperbolicMirror(23.4, 28.1, 30.0)


def _default_K(image_size, mirror, fill):
    """Pinhole whose aligned rim image spans ``fill`` of the shorter image side."""
    w, h = image_size
    # aligned rim: radius r at depth z_rim + c from the camera
    f = 0.5 * fill * min(w, h) * (mirror.z_rim + mirror.c) / mirror.rim_radius
    return np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])


def aligned_rig(image_size=(500, 500), mirror=None, fill=0.85):
    """The aligned HyperOmni rig (eqs. 2-5): camera at the lower focus, axes parallel."""
    mirror = mirror or default_mirror()
    K = _default_K(image_size, mirror, fill)
    return MisalignedHyperbolicCamera.aligned(mirror, K[0, 0], K[0, 2], K[1, 2], image_size)


def misaligned_rig(tilt_deg=3.0, tilt_azimuth_deg=30.0, offset_mm=(1.5, -1.0, 1.0),
                   image_size=(500, 500), mirror=None, fill=0.85, D=None):
    """A misaligned rig: the mirror axis tilted by ``tilt_deg`` towards ``tilt_azimuth_deg``
    (in the camera's x-y plane) and its origin moved by ``offset_mm`` (camera frame) from the
    aligned position ``(0, 0, c)``.
    """
    mirror = mirror or default_mirror()
    K = _default_K(image_size, mirror, fill)
    phi = np.deg2rad(tilt_azimuth_deg)
    rvec = np.deg2rad(tilt_deg) * np.array([-np.sin(phi), np.cos(phi), 0.0])
    tvec = np.array([0.0, 0.0, mirror.c]) + np.asarray(offset_mm, dtype=np.float64)
    return MisalignedHyperbolicCamera(K, mirror, rvec, tvec, D=D, image_size=image_size)


def random_misaligned_rig(rng, max_tilt_deg=5.0, max_offset_mm=5.0, image_size=(500, 500),
                          mirror=None, fill=0.85):
    """A random rig with tilt up to ``max_tilt_deg`` and offset norm up to ``max_offset_mm``."""
    tilt = rng.uniform(0.0, max_tilt_deg)
    az = rng.uniform(0.0, 360.0)
    v = rng.normal(size=3)
    offset = v / np.linalg.norm(v) * rng.uniform(0.0, max_offset_mm)
    return misaligned_rig(tilt, az, offset, image_size=image_size, mirror=mirror, fill=fill)
