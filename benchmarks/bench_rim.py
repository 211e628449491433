"""Rim detection: time and accuracy on rendered images and on the real photograph.

Budget: calibrating a 1000x1000 image <= 0.5 s in total on 2 cores, so
``detect_rim`` should stay well under 0.3 s there. Prints the median time of ``--repeat`` runs
(after one warm-up), the RMS geometric distance of the true rim to the fitted conic (rendered
images; eqs. 20-22) and, when ``omnicam.calibration.calibrate`` exists, the whole calibration.

    python benchmarks/bench_rim.py [--repeat 7] [--real PATH]
"""

import argparse
import pathlib
import statistics
import time

import cv2
import numpy as np

from omnicam import synthetic
from omnicam.calibration.rim import conic_distance, detect_rim

REAL = (
    pathlib.Path(__file__).resolve().parents[2]
    / "shared"
    / "data"
    / "real"
    / "office_catadioptric_1920x1080.jpg"
)


def median_time(fn, repeat):
    fn()  # warm-up
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), min(times)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--real", default=str(REAL), help="real catadioptric photograph")
    args = ap.parse_args(argv)

    cases = [
        ("500x500 misaligned, environment", synthetic.misaligned_rig(), "env"),
        (
            "1000x1000 misaligned, environment",
            synthetic.misaligned_rig(image_size=(1000, 1000)),
            "env",
        ),
        ("1000x1000 misaligned, room", synthetic.misaligned_rig(image_size=(1000, 1000)), "room"),
    ]
    try:
        from omnicam import MisalignedHyperbolicCamera

        calibrate = MisalignedHyperbolicCamera.calibrate
    except ImportError:
        calibrate = None
    for name, cam, kind in cases:
        img = synthetic.render_environment(cam) if kind == "env" else synthetic.render_room(cam)
        fit = detect_rim(img)
        d = conic_distance(fit.conic, cam.rim_image_points(2000))
        med, best = median_time(lambda: detect_rim(img), args.repeat)
        line = (
            f"{name:36s} detect_rim median {1e3 * med:6.1f} ms (min {1e3 * best:6.1f})  "
            f"true rim to conic RMS {np.sqrt(np.mean(d**2)):.4f} px, max "
            f"{np.abs(d).max():.4f} px, fit RMS {fit.rms:.3f} px"
        )
        if calibrate is not None:
            med_c, _ = median_time(lambda: calibrate(cam.K, cam.mirror, image=img), args.repeat)
            line += f"  | calibrate median {1e3 * med_c:6.1f} ms"
        print(line)
    real = pathlib.Path(args.real)
    if real.exists():
        img = cv2.imread(str(real))
        fit = detect_rim(img)
        med, best = median_time(lambda: detect_rim(img), args.repeat)
        print(
            f"{'real photo ' + real.name:36s} detect_rim median {1e3 * med:6.1f} ms (min "
            f"{1e3 * best:6.1f})  centre ({fit.center[0]:.2f}, {fit.center[1]:.2f}) px, "
            f"mean diameter {fit.diameter:.2f} px, fit RMS {fit.rms:.3f} px"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
