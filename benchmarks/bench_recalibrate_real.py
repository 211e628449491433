"""After a bump, on real frames (issue 17 item 8): a chessboard calibration's posture against the
posture each of its frames gives alone (``camera.recalibrate``: the single-image method with the
chessboard fit's K, D and mirror).

    python benchmarks/bench_recalibrate_real.py FOLDER [--glob 'VMR*.jpg'] [--mirror A B R]

FOLDER holds the views (OCamCalib's VMR sample, say; not in this repository). The rig did not
move between them, so each frame should give the chessboard's posture back within its own stated
uncertainty, or say that it cannot decide. Per frame: the axis and camera-centre differences
(``omnicam.gauge.posture_error``), the frame's stated uncertainty, their ratio, the confidence of
the choice of posture and the warnings the frame's report gives (shortened).
"""

import argparse
import glob
import os
import sys
import warnings

import cv2

import omnicam
from omnicam.gauge import posture_error


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder")
    ap.add_argument("--pattern", default="6x7")
    ap.add_argument("--square", type=float, default=30.0)
    ap.add_argument("--glob", default="*.jpg")
    ap.add_argument("--mirror", type=float, nargs=3, default=None, help="a start (data sheet)")
    ap.add_argument("--refine-shape", action="store_true", help="refine_mirror_shape=True")
    a = ap.parse_args(argv)
    paths = sorted(glob.glob(os.path.join(a.folder, a.glob)))
    if not paths:
        sys.exit(f"no images matching {a.glob} in {a.folder}")
    images = [cv2.imread(p) for p in paths]
    pattern = tuple(int(v) for v in a.pattern.lower().split("x"))
    mirror = omnicam.HyperbolicMirror(*a.mirror) if a.mirror else None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (the report holds them)
        rig, report = omnicam.calibrate_pattern(
            images, pattern, a.square, mirror, refine_mirror_shape=a.refine_shape or None
        )
    print(f"chessboards: {len(report.view_rms)} views, RMS {report.rms:.3f} px, {rig.mirror}")
    print(
        "| frame | axis diff deg | stated deg | ratio | centre diff | stated | ratio | "
        "confidence | warnings |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    within, said, silent, failed = 0, 0, 0, 0
    for path, image in zip(paths, images):
        name = os.path.basename(path)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                cam, rep = rig.recalibrate(image)
        except ValueError as e:
            failed += 1
            print(f"| {name} | | | | | | | | refused: {str(e)[:70]} |")
            continue
        axis, origin = posture_error(cam, rig)
        ra, ro = axis / rep.axis_std_deg, origin / rep.origin_std_mm
        warned = list(rep.warnings) + (["ambiguous"] if rep.ambiguous else [])
        if max(ra, ro) <= 3.0:
            within += 1
        elif warned:
            said += 1
        else:
            silent += 1
        text = "; ".join(w[:50] for w in warned) or "-"
        print(
            f"| {name} | {axis:.3f} | {rep.axis_std_deg:.3f} | {ra:.1f} | {origin:.2f} | "
            f"{rep.origin_std_mm:.2f} | {ro:.1f} | {rep.confidence:.3f} | {text} |",
            flush=True,
        )
    print(
        f"within 3x their stated uncertainty: {within}; beyond it but warned: {said}; "
        f"beyond it silently: {silent}; refused: {failed} (of {len(paths)})"
    )
    return 0 if silent == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
