"""Remap-table build time per mirror family against cv2.omnidir.initUndistortRectifyMap.

Run: ``python benchmarks/bench_mirrors.py [--repeat N]``

For each mirror (the library's misaligned hyperboloid rig, the same hyperboloid written as an
even asphere, and the misaligned asphere rigs of ``tests/asphere_rigs.py``: sphere, paraboloid,
prolate ellipsoid, equiangular mirrors of gain 3, 5, 7, 11), our exact non-central tables of
a 2048x512 cylindrical panorama and a 1024x768 perspective view (100 deg, looking 15 deg
down) against OpenCV's closed-form central model of the same output size (``cv2.omnidir``,
xi = 1, a 500x500 camera), interleaved in one process; medians of ``--repeat`` runs and the
ratio ours / omnidir. CV_16SC2 (the default map type).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import cv2
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))

from asphere_rigs import MIRRORS, rig  # noqa: E402

from omnicam import (  # noqa: E402
    K_from_fov,
    MisalignedCatadioptricCamera,
    rotation_from_ypr,
    synthetic,
    views,
)

PERSP = (1024, 768)
PANO = (2048, 512)


def omnidir_params():
    """A 500x500 omnidir camera (xi = 1, unified model), as benchmarks/bench_views.py."""
    K = np.array([[300.0, 0.0, 249.5], [0.0, 300.0, 249.5], [0.0, 0.0, 1.0]])
    return K, np.zeros((1, 4)), np.array([[1.0]])


def rigs():
    hyperbolic = synthetic.misaligned_rig()
    h = hyperbolic  # the same surface written as an even asphere: the general camera's class
    as_asphere = MisalignedCatadioptricCamera(
        h.K, h.mirror.as_asphere(), h.rvec, h.tvec, D=h.D, image_size=h.image_size
    )
    out = {
        "hyperboloid (HyperbolicMirror)": hyperbolic,
        "hyperboloid as asphere": as_asphere,
    }
    for name in MIRRORS:
        out[name] = rig(name)
    return out


def cases(cam):
    Ko, Do, xi = omnidir_params()
    Kp = K_from_fov(100.0, PERSP)
    R = rotation_from_ypr(20.0, -15.0, 0.0)
    Kc = np.array([[PANO[0] / (2 * np.pi), 0.0, 0.0], [0.0, PANO[1] / np.pi, 0.0], [0, 0, 1.0]])
    t = cv2.CV_16SC2
    return {
        "panorama 2048x512": (
            lambda: views.init_panorama_maps(cam, PANO, m1type=t),
            lambda: cv2.omnidir.initUndistortRectifyMap(
                Ko, Do, xi, np.eye(3), Kc, PANO, t, cv2.omnidir.RECTIFY_CYLINDRICAL
            ),
        ),
        "perspective 1024x768": (
            lambda: views.init_perspective_maps(cam, Kp, PERSP, R=R, m1type=t),
            lambda: cv2.omnidir.initUndistortRectifyMap(
                Ko, Do, xi, R, Kp, PERSP, t, cv2.omnidir.RECTIFY_PERSPECTIVE
            ),
        ),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=9)
    args = ap.parse_args(argv)
    print(
        f"cv2 {cv2.__version__}, {os.cpu_count()} cpus, load average "
        f"{os.getloadavg()[0]:.2f}; CV_16SC2, median of {args.repeat} interleaved runs (ms)"
    )
    print(f"{'mirror':32s} {'view':22s} {'ours':>8s} {'omnidir':>8s} {'ratio':>6s}")
    for mirror_name, cam in rigs().items():
        for view_name, (ours, omni) in cases(cam).items():
            ours(), omni()  # warm up: numba compile or cache load
            a, b = [], []
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                ours()
                t1 = time.perf_counter()
                omni()
                t2 = time.perf_counter()
                a.append(t1 - t0)
                b.append(t2 - t1)
            ma, mb = np.median(a) * 1e3, np.median(b) * 1e3
            print(f"{mirror_name:32s} {view_name:22s} {ma:8.2f} {mb:8.2f} {ma / mb:6.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
