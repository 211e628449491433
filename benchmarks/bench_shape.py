"""Far lines under a wrong mirror shape: the residual after refinement against the pixels' scatter.

Renders by tests/quadric_rig.py (an independent tracer of mirrors of revolution): a hyperboloid,
a paraboloid and a sphere, each calibrated from one image as the data sheet's hyperboloid
(28.095, 23.4125, rim 30) with three far lines (40 pixels each, Gaussian clicks of --click px)
and the rim (0.1 px). Prints, per shape and seed, the far lines' RMS residual, their scatter
about smooth curves (omnicam.calibration.shape.far_line_scatter) and whether calibrate warned
that they do not come out straight.

    python benchmarks/bench_shape.py [--click 0.3] [--seeds 5]
"""

from __future__ import annotations

import argparse
import math
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))
import quadric_rig as q

import omnicam
from omnicam.calibration.shape import far_line_scatter
from omnicam.mirror import HyperbolicMirror

A, B, RIM = 28.095, 23.4125, 30.0
C = math.hypot(A, B)
SHAPES = {
    "hyperboloid": q.hyperboloid(A, B, RIM),
    "paraboloid": q.paraboloid(20.0, 8.0, RIM),
    "sphere": q.sphere(60.0, 70.0, RIM),
}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--click", type=float, default=0.3, help="click noise, px")
    ap.add_argument("--seeds", type=int, default=5)
    args = ap.parse_args()
    print(f"{'mirror':<12} {'seed':>4} {'line RMS':>9} {'scatter':>8} {'ratio':>6}  warned")
    for name, mirror in SHAPES.items():
        for seed in range(args.seeds):
            rng = np.random.default_rng(seed)
            R, t = q.posture(1.0, 30.0 + 60 * seed, [0.5, -0.3, 0.0], C)
            rig = q.rig_filling(mirror, (640, 480), -C, R=R, t=t)
            rim = rig.rim_pixels(360) + rng.normal(0.0, 0.1, (360, 2))
            lines = [x + rng.normal(0.0, args.click, x.shape) for x in q.far_line_pixels(rig)]
            _, rep = omnicam.MisalignedHyperbolicCamera.calibrate(
                boundary_points=rim,
                K=rig.K,
                mirror=HyperbolicMirror(A, B, RIM),
                far_lines=lines,
                image_size=(640, 480),
            )
            rms, sc = rep.refinement.line_rms, far_line_scatter(lines)
            warned = any("do not come out straight" in w for w in rep.warnings)
            print(f"{name:<12} {seed:>4} {rms:>9.3f} {sc:>8.3f} {rms / sc:>6.2f}  {warned}")


if __name__ == "__main__":
    main()
