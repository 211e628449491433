"""The camera's reflection as a calibration cue: barrel renders, the office photo, timing.

Renders random rigs (tilt <= 5 deg, offset <= 5 mm) with a camera body as real rigs show it
(``tests/barrel.py``: a lens barrel of radius 9 mm whose front edge is 12 mm in front of the
camera centre, dark glass, a wider square box behind it, the procedural scene around) and
calibrates each from the image alone, without far lines, with the circle's ``z`` unknown
(default) and known. Prints per configuration: how often the reflection was found, the right
candidate chosen, the axis error (median, 95th percentile, worst), the ratio of the error to
the reported RMS uncertainty (median), silent failures (wrong candidate, or an axis error
above 0.1 deg and above 3x the reported uncertainty, with no warning), and the time per
calibration. Then the office photograph (K guessed from the rim: principal point at the rim
centre, f from the rim's size for the default mirror), and the time of calibrate() on it.

    python benchmarks/bench_reflection.py [--rigs 20] [--size 500] [--seed 1]
"""

import argparse
import math
import os
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from barrel import render

from omnicam import (
    MisalignedHyperbolicCamera,
    synthetic,
)

calibrate = MisalignedHyperbolicCamera.calibrate
from omnicam.calibration.rim import detect_rim  # noqa: E402

OFFICE = Path("/work/shared/data/real/office_catadioptric_1920x1080.jpg")


def axis_error(cam, truth):
    return math.degrees(math.acos(min(1.0, float(cam.R[:, 2] @ truth.R[:, 2]))))


def run(rigs, kw):
    rows = []
    for truth, image in rigs:
        t0 = time.perf_counter()
        cam, rep = calibrate(truth.K, truth.mirror, image=image, **kw)
        dt = time.perf_counter() - t0
        best = min(rep.physical, key=lambda i: np.linalg.norm(rep.candidates[i].tvec - truth.tvec))
        err = axis_error(cam, truth)
        right = best == rep.chosen
        silent = not rep.warnings and (not right or (err > 0.1 and err > 3 * rep.axis_std_deg))
        rows.append((rep.lens_used, right, err, err / rep.axis_std_deg, silent, dt))
    return rows


def show(name, rows):
    found = sum(r[0] for r in rows)
    right = sum(r[1] for r in rows)
    err = np.array([r[2] for r in rows])
    ratio = np.array([r[3] for r in rows])
    print(
        f"{name:<28} found {found}/{len(rows)}  right {right}/{len(rows)}  axis err median "
        f"{np.median(err):.3f} p95 {np.percentile(err, 95):.3f} max {err.max():.3f} deg  "
        f"err/std median {np.median(ratio):.2f}  silent {sum(r[4] for r in rows)}  "
        f"time median {np.median([r[5] for r in rows]) * 1e3:.0f} ms"
    )


def office():
    if not OFFICE.exists():
        print("office photo not available")
        return
    image = cv2.imread(str(OFFICE))
    rim = detect_rim(image)
    m = synthetic.default_mirror()
    f = float(np.mean(rim.axes)) * (m.z_rim + m.c) / m.rim_radius  # aligned rig: r = f R / (z + c)
    K = np.array([[f, 0, rim.center[0]], [0, f, rim.center[1]], [0, 0, 1.0]])
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        cam, rep = calibrate(K, m, image=image)
        times.append(time.perf_counter() - t0)
    print(
        f"office photo (K guessed: f {f:.0f} px, principal point at the rim centre, default "
        f"mirror): calibrate() median {np.median(times) * 1e3:.0f} ms of 3"
    )
    print(rep.summary())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rigs", type=int, default=20)
    ap.add_argument("--size", type=int, default=500)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    print(f"OMP/threads: {os.cpu_count()} cores visible")
    rng = np.random.default_rng(args.seed)
    rigs = []
    t0 = time.perf_counter()
    while len(rigs) < args.rigs:
        truth = synthetic.random_misaligned_rig(rng, 5.0, 5.0, image_size=(args.size,) * 2)
        rigs.append((truth, render(truth, supersample=3 if args.size <= 500 else 2)))
    print(f"{args.rigs} barrel renders {args.size}x{args.size} ({time.perf_counter() - t0:.0f} s)")
    show("no far lines, z unknown", run(rigs, {}))
    show("no far lines, z known", run(rigs, dict(lens_z=12.0)))
    show("lens=None (rim only)", run(rigs, dict(lens=None)))
    office()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
