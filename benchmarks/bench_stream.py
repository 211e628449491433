"""Per-frame overhead of Unwarper.unwarp over bare cv2.remap with the same tables.

Run: ``python benchmarks/bench_stream.py [--frames N]``

Decode and encode are excluded: frames are in memory. For each configuration the same frames
go through (a) bare ``cv2.remap(frame, map1, map2, INTER_LINEAR, dst=out, borderMode=...)`` for
every view and (b) ``Unwarper.unwarp(frame)``, interleaved frame by frame; the overhead is
``median(b) - median(a)`` as a fraction of ``median(a)``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import cv2
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from omnicam import Unwarper, synthetic
from omnicam.views import PanoramaView, PerspectiveView


def measure(unwarper, frames, rounds):
    plan = [
        (m1, m2, unwarper.unwarp(frames[0])[name].copy())
        for name, (m1, m2) in unwarper.maps.items()
    ]
    bare, ours = [], []

    def run_bare(f):
        t0 = time.perf_counter()
        for m1, m2, dst in plan:
            cv2.remap(
                f,
                m1,
                m2,
                cv2.INTER_LINEAR,
                dst=dst,
                borderMode=cv2.BORDER_CONSTANT,
                borderValue=(0.0, 0.0, 0.0, 0.0),
            )
        bare.append(time.perf_counter() - t0)

    def run_ours(f):
        t0 = time.perf_counter()
        unwarper.unwarp(f)
        ours.append(time.perf_counter() - t0)

    for r in range(rounds):
        for k, f in enumerate(frames):
            # alternate which goes first, so neither gets the other's warm caches
            first, second = (run_bare, run_ours) if (r + k) % 2 == 0 else (run_ours, run_bare)
            first(f)
            second(f)
    return np.median(bare), np.median(ours), min(bare), min(ours)


def python_overhead(n_views, repeat=20000):
    """Absolute cost of the Unwarper's Python around cv2.remap: tables of 1x1 pixel."""
    m = np.zeros((1, 1), np.float32)
    u = Unwarper({f"v{i}": (m, m.copy()) for i in range(n_views)})
    f = np.zeros((4, 4, 3), np.uint8)
    dsts = [np.empty((1, 1, 3), np.uint8) for _ in range(n_views)]
    u.unwarp(f)
    t0 = time.perf_counter()
    for _ in range(repeat):
        for d in dsts:
            cv2.remap(
                f,
                m,
                m,
                cv2.INTER_LINEAR,
                dst=d,
                borderMode=cv2.BORDER_CONSTANT,
                borderValue=(0.0, 0.0, 0.0, 0.0),
            )
    t1 = time.perf_counter()
    for _ in range(repeat):
        u.unwarp(f)
    t2 = time.perf_counter()
    return ((t2 - t1) - (t1 - t0)) / repeat


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--rounds", type=int, default=10)
    args = ap.parse_args(argv)
    print(
        f"cv2 {cv2.__version__}, cv2 threads {cv2.getNumThreads()}, "
        f"load average {os.getloadavg()[0]:.2f}"
    )
    configs = {
        "500x500 -> panorama 2048x512": ((500, 500), {"pano": PanoramaView((2048, 512))}),
        "500x500 -> perspective 1024x768": (
            (500, 500),
            {"front": PerspectiveView((1024, 768), fov=100.0)},
        ),
        "500x500 -> panorama 1024x256 + 2 perspective 320x240": (
            (500, 500),
            {
                "pano": PanoramaView((1024, 256)),
                "left": PerspectiveView((320, 240), fov=90.0, yaw=-90.0),
                "right": PerspectiveView((320, 240), fov=90.0, yaw=90.0),
            },
        ),
        "1000x1000 -> panorama 2048x512": ((1000, 1000), {"pano": PanoramaView((2048, 512))}),
    }
    for n in (1, 3):
        print(
            f"Unwarper's own cost around cv2.remap, {n} view(s): "
            f"{python_overhead(n) * 1e6:.1f} us/frame (1x1 tables)"
        )
    rng = np.random.default_rng(0)
    for name, (size, specs) in configs.items():
        cam = synthetic.misaligned_rig(image_size=size)
        for m1type, tname in ((cv2.CV_16SC2, "CV_16SC2"), (cv2.CV_32FC1, "CV_32FC1")):
            u = Unwarper.from_camera(cam, specs, m1type=m1type)
            w, h = size
            frames = [
                cv2.GaussianBlur(rng.integers(0, 256, (h, w, 3), dtype=np.uint8), (5, 5), 0)
                for _ in range(args.frames)
            ]
            mb, mo, nb, no = measure(u, frames, args.rounds)
            over, over_min = (mo - mb) / mb * 100, (no - nb) / nb * 100
            print(
                f"{name:55s} {tname}: bare remap {mb * 1e3:6.2f} ms, Unwarper {mo * 1e3:6.2f} ms,"
                f" overhead {over:+5.1f}% (min-based {over_min:+5.1f}%,"
                f" {(mo - mb) * 1e6:+.0f} us/frame)"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
