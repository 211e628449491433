"""Several views from one decode cost no more than the decode plus the sum of the remaps.

Run: ``python benchmarks/bench_multiview.py [--frames N] [--size WxH]``

A synthetic MJPG video is decoded (a) alone, ``cv2.VideoCapture.read`` of every frame;
(b) each view's ``cv2.remap`` alone, on the decoded frames in memory; (c) what ``omnicam
unwarp`` does with several views, one ``read`` and one :meth:`Unwarper.unwarp` (all views) per
frame; and (d) one run per view, each decoding the video again (what several ``omnicam
unwarp`` calls would cost). Encoding is left out of all four (it is the same work in (c) and
(d)). Each figure is the best of ``--rounds`` runs, in ms per frame.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import cv2
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from omnicam import Unwarper, synthetic
from omnicam.spherical import equirect_view
from omnicam.views import PanoramaView, PerspectiveView

VIEWS = {
    "panorama": PanoramaView((2048, 512)),
    "front": PerspectiveView((960, 720), fov=90.0),
    "back": PerspectiveView((960, 720), fov=90.0, yaw=180.0),
    "equirect": equirect_view((2048, 1024)),
}


def make_video(path, n, size):
    rng = np.random.default_rng(0)
    w, h = size
    base = cv2.resize(rng.integers(0, 256, (h // 8, w // 8, 3), dtype=np.uint8), (w, h))
    wr = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 30.0, size)
    for i in range(n):
        wr.write(np.roll(base, 5 * i, axis=1))
    wr.release()


def decode_all(path):
    cap = cv2.VideoCapture(path)
    frames = []
    while True:
        ok, f = cap.read()
        if not ok:
            break
        frames.append(f)
    cap.release()
    return frames


def timed(fn, rounds):
    best = float("inf")
    for _ in range(rounds):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--size", default="1280x960")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.lower().split("x"))
    cam = synthetic.misaligned_rig(image_size=(w, h))
    unwarper = Unwarper.from_camera(cam, VIEWS)
    singles = {name: Unwarper.from_camera(cam, {name: v}) for name, v in VIEWS.items()}
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "in.avi")
        make_video(path, args.frames, (w, h))
        frames = decode_all(path)
        n = len(frames)

        t_decode = timed(lambda: decode_all(path) and None, args.rounds)

        t_remap = {}
        for name, u in singles.items():
            t_remap[name] = timed(lambda u=u: [u.unwarp(f) for f in frames], args.rounds)

        def one_decode():
            cap = cv2.VideoCapture(path)
            while True:
                ok, f = cap.read()
                if not ok:
                    break
                unwarper.unwarp(f)
            cap.release()

        t_multi = timed(one_decode, args.rounds)

        def one_run_per_view():
            for u in singles.values():
                cap = cv2.VideoCapture(path)
                while True:
                    ok, f = cap.read()
                    if not ok:
                        break
                    u.unwarp(f)
                cap.release()

        t_separate = timed(one_run_per_view, args.rounds)

    ms = 1000.0 / n
    print(
        f"{n} frames of {w}x{h} MJPG, views: "
        + ", ".join(f"{k} {v.size[0]}x{v.size[1]}" for k, v in VIEWS.items())
    )
    print(f"  decode alone                      {t_decode * ms:8.2f} ms/frame")
    for name, t in t_remap.items():
        print(f"  remap {name:<27} {t * ms:8.2f} ms/frame")
    budget = t_decode + sum(t_remap.values())
    print(f"  decode + sum of remaps            {budget * ms:8.2f} ms/frame")
    print(
        f"  one decode, all views (omnicam)   {t_multi * ms:8.2f} ms/frame "
        f"({100 * (t_multi / budget - 1):+.1f}% vs decode + sum of remaps)"
    )
    print(f"  one run per view (decode {len(VIEWS)}x)     {t_separate * ms:8.2f} ms/frame")
    return 0


if __name__ == "__main__":
    sys.exit(main())
