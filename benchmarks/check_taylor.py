"""The library's Taylor (OCamCalib) fit against the team's reference tool on the same corners.

    python benchmarks/check_taylor.py FOLDER --pattern 7x11 [--glob '*.jpg'] [--square 30]
        [--reference ../shared/tools/taylor.py]
    python benchmarks/check_taylor.py --render [--reference ...]

FOLDER holds the images (e.g. OCamCalib's public KaidanOmni*.jpg or VMRImage*.jpg); nothing is
committed. Corners come from omnicam.chessboard.detect.detect_pattern, all views. --render fits
a rendered central camera instead (cv2.omnidir.projectPoints of Mei's model, xi = 1.4). Prints
both fits' training RMS (px), degree and centre, and the angle (deg) between their rays on the
corners and on a grid of pixels out to the farthest corner's radius.
"""

import argparse
import glob
import importlib.util
import os
import sys
import time

import cv2
import numpy as np

from omnicam.chessboard.board_pose import object_points
from omnicam.chessboard.detect import detect_pattern
from omnicam.chessboard.taylor import fit_taylor


def _module(path):
    spec = importlib.util.spec_from_file_location("taylor_reference", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def render_mei(xi=1.4, gamma=300.0, size=(800, 600), n_views=12, seed=0):
    """Corners of a 7x11 board (30 mm) in ``n_views`` poses around a Mei camera, px."""
    rng = np.random.default_rng(seed)
    obj = object_points((7, 11), 30.0)
    K = np.array([[gamma, 0, size[0] / 2 - 3.5], [0, gamma, size[1] / 2 + 2.5], [0, 0, 1]])
    views = []
    while len(views) < n_views:
        az = rng.uniform(0, 2 * np.pi)
        polar = np.radians(rng.uniform(45, 105))
        d = np.array([np.sin(polar) * np.cos(az), np.sin(polar) * np.sin(az), np.cos(polar)])
        z = -d  # the board faces the camera, its grid turned at random
        x = np.cross([0.3, 0.7, 0.2], z)
        x /= np.linalg.norm(x)
        R = np.c_[x, np.cross(z, x), z]
        R = R @ cv2.Rodrigues(np.r_[0, 0, rng.uniform(-np.pi, np.pi)])[0]
        R = R @ cv2.Rodrigues(rng.uniform(-0.4, 0.4, 3))[0]
        t = d * rng.uniform(400, 700) - R @ obj.mean(0)
        q, _ = cv2.omnidir.projectPoints(
            obj.reshape(-1, 1, 3), cv2.Rodrigues(R)[0], t.reshape(3, 1), K, xi, np.zeros((1, 4))
        )
        q = q.reshape(-1, 2)
        if np.isfinite(q).all() and (q > 5).all() and (q < np.array(size) - 5).all():
            views.append(q + rng.normal(0, 0.1, q.shape))
    return views, obj, size, K


def _corners(folder, pattern, pattern_glob, square):
    paths = sorted(glob.glob(os.path.join(folder, pattern_glob)))
    if not paths:
        sys.exit(f"no images matching {pattern_glob} in {folder}")
    views, size = [], None
    for p in paths:
        im = cv2.imread(p)
        size = (im.shape[1], im.shape[0])
        det = detect_pattern(im, pattern)
        if det is not None:
            views.append(det.corners.reshape(-1, 2).astype(np.float64))
    print(f"{len(views)} of {len(paths)} boards detected, image {size[0]}x{size[1]}")
    return views, object_points(pattern, square), size


def _angles(d1, d2):
    c = np.clip(np.sum(d1 * d2, axis=1), -1.0, 1.0)
    return np.degrees(np.arccos(c))


def main(argv=None):
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", nargs="?")
    ap.add_argument("--pattern", default="7x11")
    ap.add_argument("--glob", default="*.jpg")
    ap.add_argument("--square", type=float, default=30.0)
    ap.add_argument("--render", action="store_true")
    ap.add_argument(
        "--reference", default=os.path.join(here, "..", "..", "shared", "tools", "taylor.py")
    )
    a = ap.parse_args(argv)
    if a.render:
        views, obj, size, _ = render_mei()
        print(f"render: Mei xi = 1.4, {len(views)} views, image {size[0]}x{size[1]}")
    elif a.folder:
        pattern = tuple(int(v) for v in a.pattern.lower().split("x"))
        views, obj, size = _corners(a.folder, pattern, a.glob, a.square)
    else:
        sys.exit("give FOLDER or --render")
    ref = _module(a.reference)
    t = time.perf_counter()
    ours = fit_taylor(views, obj, size)
    t_ours = time.perf_counter() - t
    t = time.perf_counter()
    theirs = ref.fit(views, obj, size)
    t_theirs = time.perf_counter() - t
    print(
        f"omnicam.chessboard.taylor: RMS {ours.rms:.4f} px, degree {ours.degree}, centre "
        f"{ours.centre.round(2)}, {t_ours:.1f} s"
    )
    print(
        f"reference taylor.py      : RMS {theirs['rms']:.4f} px, degree {theirs['degree']}, "
        f"centre {np.round(theirs['centre'], 2)}, {t_theirs:.1f} s"
    )
    print(f"RMS relative difference: {abs(ours.rms - theirs['rms']) / theirs['rms'] * 100:.3f} %")
    px = np.vstack(views)
    rmax = np.max(np.linalg.norm(px - ours.centre, axis=1))
    u, v = np.meshgrid(np.linspace(-rmax, rmax, 61), np.linspace(-rmax, rmax, 61))
    grid = np.c_[u.ravel(), v.ravel()]
    grid = grid[np.linalg.norm(grid, axis=1) <= rmax] + ours.centre
    for name, p in (("corners", px), (f"grid to r = {rmax:.0f} px", grid)):
        e = _angles(ours.directions(p), theirs["directions"](p))
        print(
            f"ray difference on {name} ({len(p)}): median {np.median(e):.2e} deg, "
            f"max {e.max():.2e} deg"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
