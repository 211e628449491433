"""Remap-table build time against cv2.omnidir.initUndistortRectifyMap, accuracy, first-table time.

Run: ``python benchmarks/bench_views.py [--repeat N]``

* The output sizes users ask for: a 1024x768 perspective view and a 2048x512 panorama, our exact
  non-central tables (misaligned 500x500 rig) against OpenCV's closed-form central model
  (``cv2.omnidir``, xi = 1, a 500x500 camera), interleaved in one process; medians and ratios.
  Also perspective views that straddle an edge of the visible band (1024x768,
  f = 400, looking horizontally, 20 deg up and 10 deg down), where cells near the edge are
  refined and some pixels solved exactly.
* Accuracy: the float tables against the exact projection at 200 000 random output pixels.
* Fresh process with numba's cache warm: ``import omnicam`` + ``MisalignedHyperbolicCamera.load``
  + the first 2048x512 panorama table (time inside the process, and the whole process).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

import cv2
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from omnicam import K_from_fov, rotation_from_ypr, synthetic, views

PERSP = (1024, 768)
PANO = (2048, 512)


def omnidir_params():
    """A 500x500 omnidir camera (xi = 1, unified model) of a similar field of view."""
    K = np.array([[300.0, 0.0, 249.5], [0.0, 300.0, 249.5], [0.0, 0.0, 1.0]])
    return K, np.zeros((1, 4)), np.array([[1.0]])


def cases(cam):
    Ko, Do, xi = omnidir_params()
    Kp = K_from_fov(100.0, PERSP)
    R = rotation_from_ypr(20.0, -15.0, 0.0)
    # omnidir's cylindrical / longitude-latitude rectification: columns over 2 pi, rows over pi
    Kc = np.array([[PANO[0] / (2 * np.pi), 0.0, 0.0], [0.0, PANO[1] / np.pi, 0.0], [0, 0, 1.0]])
    return {
        "perspective 1024x768": (
            lambda t: views.init_perspective_maps(cam, Kp, PERSP, R=R, m1type=t),
            lambda t: cv2.omnidir.initUndistortRectifyMap(
                Ko, Do, xi, R, Kp, PERSP, t, cv2.omnidir.RECTIFY_PERSPECTIVE
            ),
        ),
        "panorama 2048x512 cylindrical": (
            lambda t: views.init_panorama_maps(cam, PANO, m1type=t),
            lambda t: cv2.omnidir.initUndistortRectifyMap(
                Ko, Do, xi, np.eye(3), Kc, PANO, t, cv2.omnidir.RECTIFY_CYLINDRICAL
            ),
        ),
        "panorama 2048x512 equirectangular": (
            lambda t: views.init_panorama_maps(cam, PANO, projection="equirectangular", m1type=t),
            lambda t: cv2.omnidir.initUndistortRectifyMap(
                Ko, Do, xi, np.eye(3), Kc, PANO, t, cv2.omnidir.RECTIFY_LONGLATI
            ),
        ),
        "perspective 1024x768, depth 2 m": (
            lambda t: views.init_perspective_maps(cam, Kp, PERSP, R=R, m1type=t, depth=2000.0),
            lambda t: cv2.omnidir.initUndistortRectifyMap(
                Ko, Do, xi, R, Kp, PERSP, t, cv2.omnidir.RECTIFY_PERSPECTIVE
            ),
        ),
        **straddling_cases(cam),
    }


def straddling_cases(cam):
    """Perspective views (1024x768, f = 400) across which an edge of the visible band runs."""
    Ko, Do, xi = omnidir_params()
    K = np.array([[400.0, 0.0, 511.5], [0.0, 400.0, 383.5], [0.0, 0.0, 1.0]])
    out = {}
    for name, ypr, depth in (
        ("horizontal", (0.0, 0.0, 0.0), None),
        ("horizontal, depth 2 m", (0.0, 0.0, 0.0), 2000.0),
        ("up 20 deg", (30.0, 20.0, 0.0), None),
        ("yaw -60, down 10 deg", (-60.0, -10.0, 0.0), None),
    ):
        R = rotation_from_ypr(*ypr)
        out[f"straddling {name}"] = (
            lambda t, R=R, depth=depth: views.init_perspective_maps(
                cam, K, PERSP, R=R, m1type=t, depth=depth
            ),
            lambda t, R=R: cv2.omnidir.initUndistortRectifyMap(
                Ko, Do, xi, R, K, PERSP, t, cv2.omnidir.RECTIFY_PERSPECTIVE
            ),
        )
    return out


def timing(cam, repeat, only=None, clock=time.perf_counter):
    what = "wall" if clock is time.perf_counter else "CPU (all threads)"
    print(
        f"== build time ({what}), median of {repeat} interleaved runs (ms); "
        f"ratio = ours / cv2.omnidir"
    )
    for name, (ours, omni) in cases(cam).items():
        if only and only not in name:
            continue
        for t, tname in ((cv2.CV_32FC1, "CV_32FC1"), (cv2.CV_16SC2, "CV_16SC2")):
            ours(t), omni(t)  # warm up (numba compile / load from cache)
            a, b = [], []
            for _ in range(repeat):
                t0 = clock()
                ours(t)
                t1 = clock()
                omni(t)
                t2 = clock()
                a.append(t1 - t0)
                b.append(t2 - t1)
            ma, mb = np.median(a) * 1e3, np.median(b) * 1e3
            print(
                f"{name:36s} {tname}: ours {ma:7.2f}  omnidir {mb:7.2f}  ratio {ma / mb:5.2f}"
                f"   (min {min(a) * 1e3:.2f} / {min(b) * 1e3:.2f})"
            )


def accuracy(cam, n=200_000):
    print("== accuracy of the float tables: max |table - exact projection| over random pixels")
    rng = np.random.default_rng(0)
    Kp = K_from_fov(100.0, PERSP)
    R = rotation_from_ypr(20.0, -15.0, 0.0)
    M = R.T @ np.linalg.inv(Kp)
    vp = None
    for depth in (None, 2000.0):
        if depth is not None:
            vp = cam.best_fit_viewpoint()[0]
        for name in ("perspective", "cylindrical", "equirectangular"):
            if name == "perspective":
                mx, my = views.init_perspective_maps(
                    cam, Kp, PERSP, R=R, m1type=cv2.CV_32FC1, depth=depth
                )
                h, w = mx.shape
                ii, jj = rng.integers(0, h, n), rng.integers(0, w, n)
                d = np.stack([jj, ii, np.ones(n)], axis=1) @ M.T
            else:
                mx, my = views.init_panorama_maps(
                    cam, PANO, projection=name, m1type=cv2.CV_32FC1, depth=depth
                )
                lo, hi = views.visible_elevation_range(cam)
                lo = max(lo, views.CYLINDRICAL_MIN_ELEVATION)  # the default of both projections
                if name == "cylindrical":
                    hi = min(hi, 89.0)
                h, w = mx.shape
                ii, jj = rng.integers(0, h, n), rng.integers(0, w, n)
                # column j at azimuth -yaw - 360 (j - (w - 1) / 2) / w, the camera's forward
                # direction at the centre (the default yaw)
                yaw = views.camera_forward_yaw(cam)
                az = np.radians(-yaw - 360.0 * (jj - (w - 1) / 2.0) / w)
                if name == "cylindrical":
                    tz = np.tan(np.radians(hi)) + (
                        np.tan(np.radians(lo)) - np.tan(np.radians(hi))
                    ) * ii / (h - 1)
                    d = np.stack([np.cos(az), np.sin(az), tz], axis=1)
                else:
                    el = np.radians(hi + (lo - hi) * ii / (h - 1))
                    d = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], 1)
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            ref = cam.project_directions(d) if depth is None else cam.project(vp + depth * d)
            got = np.stack([mx[ii, jj], my[ii, jj]], axis=1).astype(np.float64)
            seen = got[:, 0] != views.UNSEEN
            fin = np.isfinite(ref).all(axis=1)
            err = np.linalg.norm(got - ref, axis=1)[seen & fin]
            print(
                f"{name:16s} depth={depth}: max error {err.max():.2e} px, "
                f"99.9% {np.quantile(err, 0.999):.1e} px, visibility disagreements "
                f"{int((seen != fin).sum())} of {n}"
            )


FIRST = r"""
import time
t0 = time.perf_counter()
import sys
sys.path.insert(0, {root!r})
import omnicam
cam = omnicam.MisalignedHyperbolicCamera.load({path!r})
m1, m2 = cam.init_panorama_maps((2048, 512))
print(time.perf_counter() - t0)
"""


def first_table(n=5):
    print("== fresh process, numba cache warm: import + load + first 2048x512 panorama")
    root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "calib.yaml")
        synthetic.misaligned_rig().save(path)
        code = FIRST.format(root=root, path=path)
        subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)  # warm
        inside, whole = [], []
        for _ in range(n):
            t0 = time.perf_counter()
            out = subprocess.run(
                [sys.executable, "-c", code], check=True, capture_output=True, text=True
            )
            whole.append(time.perf_counter() - t0)
            inside.append(float(out.stdout.strip().splitlines()[-1]))
    print(
        f"in-process (import .. table) median {np.median(inside):.3f} s, min {min(inside):.3f} s;"
        f" whole process median {np.median(whole):.3f} s"
    )
    trivial = (
        "import time; t0=time.perf_counter()\nfrom numba import njit\n"
        "@njit(cache=True)\ndef f(x):\n    return x + 1\nf(1)\nprint(time.perf_counter()-t0)"
    )
    with tempfile.TemporaryDirectory() as tmp:
        p = os.path.join(tmp, "triv.py")
        with open(p, "w") as fh:
            fh.write(trivial)
        subprocess.run([sys.executable, p], check=True, capture_output=True)
        t = []
        for _ in range(n):
            t0 = time.perf_counter()
            subprocess.run([sys.executable, p], check=True, capture_output=True)
            t.append(time.perf_counter() - t0)
    print(f"numba floor (trivial cached kernel, whole process) median {np.median(t):.3f} s")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=15)
    ap.add_argument("--skip-accuracy", action="store_true")
    ap.add_argument("--skip-first-table", action="store_true")
    ap.add_argument("--only", help="time only the cases whose name contains this")
    ap.add_argument(
        "--cpu",
        action="store_true",
        help="also time in process CPU time (less sensitive to other load on the machine)",
    )
    args = ap.parse_args(argv)
    cam = synthetic.misaligned_rig()
    print(
        f"cv2 {cv2.__version__}, {os.cpu_count()} cpus, cv2 threads {cv2.getNumThreads()}, "
        f"load average {os.getloadavg()[0]:.2f}"
    )
    timing(cam, args.repeat, args.only)
    if args.cpu:
        timing(cam, args.repeat, args.only, clock=time.process_time)
    if not args.skip_accuracy:
        accuracy(cam)
    if not args.skip_first_table:
        first_table()
    return 0


if __name__ == "__main__":
    sys.exit(main())
