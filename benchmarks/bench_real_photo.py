"""The shared real photograph: the rim, the camera's reflection, the choice, and the time.

Its rig's K and mirror are not published: K is guessed from the rim (principal point at the rim
centre, f = r (z_rim + c) / rim_radius for the default HyperOmni-style mirror), so the posture
is only as right as that guess; the report says how well the reflection fits. Writes the
panorama of the result to ``--out`` (default benchmarks/out/office_panorama.png).

    python benchmarks/bench_real_photo.py [--photo PATH] [--repeat 3]
"""

import argparse
import math
import os
import time

import cv2
import numpy as np

import omnicam
from omnicam import synthetic

HERE = os.path.dirname(os.path.abspath(__file__))
PHOTO = os.path.join(
    HERE, "..", "..", "shared", "data", "real", "office_catadioptric_1920x1080.jpg"
)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photo", default=PHOTO)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default=os.path.join(HERE, "out", "office_panorama.png"))
    args = ap.parse_args()
    img = cv2.imread(args.photo)
    if img is None:
        raise SystemExit(f"cannot read {args.photo}")
    rim = omnicam.detect_rim(img)
    mirror = synthetic.default_mirror()
    r = math.sqrt(rim.axes[0] * rim.axes[1])
    f = r * (mirror.z_rim + mirror.c) / mirror.rim_radius
    K = np.array([[f, 0, rim.center[0]], [0, f, rim.center[1]], [0, 0, 1.0]])
    print(f"rim centre {np.round(rim.center, 1)}, axes {np.round(rim.axes, 1)}, guessed f {f:.1f}")
    times = []
    for _ in range(args.repeat):
        t = time.perf_counter()
        cam, report = omnicam.MisalignedHyperbolicCamera.calibrate(K, mirror, image=img)
        times.append(time.perf_counter() - t)
    print(f"calibrate: median {np.median(times):.3f} s over {args.repeat} runs")
    print(report.summary())
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    pano = cv2.remap(img, *cam.init_panorama_maps((2048, 512)), cv2.INTER_LINEAR)
    cv2.imwrite(args.out, pano)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
