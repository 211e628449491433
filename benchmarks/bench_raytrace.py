"""Throughput of unproject / project next to cv2.omnidir on the same million points, one run.

Targets: unproject >= 3x cv2.omnidir.undistortPoints; the exact non-central project
>= 0.5x cv2.omnidir.projectPoints (a closed-form central model). Prints medians and ratios.

    python benchmarks/bench_raytrace.py [--n 1000000] [--repeat 7]
"""

import argparse
import statistics
import time

import cv2
import numpy as np

from omnicam import synthetic


def median_time(fn, repeat):
    fn()  # warm-up (numba compile or cache load)
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args(argv)

    cam = synthetic.misaligned_rig()
    rng = np.random.default_rng(0)
    # n random sub-pixel positions inside the rim ellipse
    rim = cam.rim_image_points(720)
    lo, hi = rim.min(0), rim.max(0)
    pts = rng.uniform(lo, hi, size=(int(args.n * 1.6), 2))
    P, d = cam.unproject(pts)
    pix = np.ascontiguousarray(pts[np.isfinite(d[:, 0])][: args.n])
    n = len(pix)
    P, d = cam.unproject(pix)
    X = np.ascontiguousarray(P + 1000.0 * d)  # scene points 1 m out along the rays

    # a central omnidir camera of similar size (Mei model, xi ~ 1)
    K = cam.K.copy()
    D = np.zeros((1, 4))
    xi = np.array([[0.9]])
    pix_cv = pix.reshape(-1, 1, 2)
    X_cv = X.reshape(-1, 1, 3)
    rvec, tvec = np.zeros((3, 1)), np.zeros((3, 1))

    rows = [
        (
            "cv2.omnidir.undistortPoints",
            median_time(
                lambda: cv2.omnidir.undistortPoints(pix_cv, K, D, xi, np.eye(3)), args.repeat
            ),
        ),
        ("omnicam unproject", median_time(lambda: cam.unproject(pix), args.repeat)),
        (
            "cv2.omnidir.projectPoints",
            median_time(
                lambda: cv2.omnidir.projectPoints(X_cv, rvec, tvec, K, float(xi[0, 0]), D),
                args.repeat,
            ),
        ),
        ("omnicam project (exact)", median_time(lambda: cam.project(X), args.repeat)),
    ]
    print(
        f"{n} points, median of {args.repeat} runs, numba threads: "
        f"{__import__('numba').get_num_threads()}"
    )
    for name, t in rows:
        print(f"  {name:30s} {t * 1e3:8.1f} ms  {n / t / 1e6:7.2f} Mpts/s")
    t = dict(rows)
    print(
        f"unproject / omnidir.undistortPoints throughput ratio: "
        f"{t['cv2.omnidir.undistortPoints'] / t['omnicam unproject']:.2f}x (target >= 3)"
    )
    print(
        f"project / omnidir.projectPoints throughput ratio:     "
        f"{t['cv2.omnidir.projectPoints'] / t['omnicam project (exact)']:.2f}x (target >= 0.5)"
    )
    err = np.linalg.norm(cam.project(X) - pix, axis=1)
    print(
        f"round trip project(unproject(x)) - x: max {np.nanmax(err):.2e} px, "
        f"NaN {int(np.isnan(err).sum())}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
