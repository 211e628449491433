"""Exact both ways on every mirror of revolution (issue 28, item 2): round trip and tables.

    python benchmarks/bench_mirrors_exact.py [--step PX]

For each misaligned rig of ``tests/asphere_rigs.py`` (sphere, paraboloid, prolate ellipsoid,
equiangular mirrors of gain 3, 5, 7, 11): the round trip, pixel -> ray (``unproject``) -> a
point 600 mm along it, or its direction (``project``, ``project_directions``) -> pixel, worst
over the mirror's annulus sampled every ``--step`` px; and the remap tables (a 384x96
cylindrical panorama, a 240x180 perspective view of 100 deg, float maps) against exact
projection of each entry's direction (or point at 600 mm), worst over the entries both see.
The tests (``tests/test_asphere.py``) hold these to 1e-6 px and 0.01 px.
"""

import argparse
import os
import sys

import cv2
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))

from asphere_rigs import MIRRORS, rig  # noqa: E402
from conftest import annulus_pixels  # noqa: E402
from test_views import exact, panorama_dirs, perspective_dirs  # noqa: E402

from omnicam import K_from_fov, rotation_from_ypr, views  # noqa: E402

DEPTH_MM = 600.0


def round_trip_px(cam, step):
    """Worst pixel error of pixel -> ray -> pixel: ``(point at DEPTH_MM, direction, pixels)``."""
    pix = annulus_pixels(cam, step=step)
    o, d = cam.unproject(pix)
    on = np.isfinite(o[:, 0])
    near = np.linalg.norm(cam.project(o[on] + DEPTH_MM * d[on]) - pix[on], axis=1)
    far = np.linalg.norm(cam.project_directions(d[on]) - pix[on], axis=1)
    return float(near.max()), float(far.max()), int(on.sum())


def table_error_px(mapx, mapy, ref):
    """Worst distance between a float table's entries and the exact pixels, where both see."""
    got = np.stack([mapx, mapy], axis=-1).astype(np.float64)
    seen = ~((mapx == views.UNSEEN) & (mapy == views.UNSEEN))
    both = seen & np.isfinite(ref).all(axis=-1)
    return float(np.linalg.norm(got[both] - ref[both], axis=1).max())


def tables_px(cam, depth):
    """Worst error of the panorama's and the perspective view's tables at ``depth``."""
    size = (384, 96)
    mapx, mapy = views.init_panorama_maps(
        cam, size, projection="cylindrical", m1type=cv2.CV_32FC1, depth=depth, yaw=0.0
    )
    lo, hi = views.visible_elevation_range(cam)
    lo = max(lo, views.CYLINDRICAL_MIN_ELEVATION)
    pano = table_error_px(mapx, mapy, exact(cam, panorama_dirs(size, lo, hi, "cylindrical"), depth))
    size = (240, 180)
    K, R = K_from_fov(100.0, size), rotation_from_ypr(25.0, -20.0, 10.0)
    mapx, mapy = views.init_perspective_maps(cam, K, size, R=R, m1type=cv2.CV_32FC1, depth=depth)
    persp = table_error_px(mapx, mapy, exact(cam, perspective_dirs(K, size, R), depth))
    return pano, persp


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--step", type=float, default=4.0, help="the round trip's pixel spacing")
    args = ap.parse_args(argv)
    print(
        f"| mirror | pixels | round trip px ({DEPTH_MM:g} mm / direction) | "
        f"panorama px (inf / {DEPTH_MM:g} mm) | perspective px (inf / {DEPTH_MM:g} mm) |"
    )
    print("|---|---|---|---|---|")
    for name in MIRRORS:
        cam = rig(name)
        near, far, n = round_trip_px(cam, args.step)
        (p_inf, q_inf), (p_mm, q_mm) = tables_px(cam, None), tables_px(cam, DEPTH_MM)
        print(
            f"| {name} | {n} | {near:.1e} / {far:.1e} | {p_inf:.4f} / {p_mm:.4f} | "
            f"{q_inf:.4f} / {q_mm:.4f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
