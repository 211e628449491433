"""The rim on renders that look real: unguided vs guided by K and the mirror.

For each stress render of :mod:`omnicam.synthetic.realistic` (holders white, black or metal,
struts, dark floor, clipped rims, blur, JPEG, ...; the renderer shares nothing with the
estimator), the rim is detected twice, ``detect_rim(image)`` and ``detect_rim(image,
expected=expected_rim(K, mirror, D).radius_range)`` as ``calibrate`` does, and compared with
the true rim (RMS distance of the true rim's in-frame points to the fitted conic). Then
``calibrate`` runs and the table says whether each posture off by more than 1 deg came with a
plausibility warning (or an error), and whether a good one was wrongly flagged.

    python benchmarks/bench_rim_holder.py [--cases 100] [--seed 0]

Needs ``omnicam.synthetic.realistic`` (branch ``realistic``).
"""

import argparse
import math

import numpy as np

from omnicam import MisalignedHyperbolicCamera
from omnicam.calibration.ellipse import conic_distance
from omnicam.calibration.plausibility import expected_rim
from omnicam.calibration.rim import detect_rim

calibrate = MisalignedHyperbolicCamera.calibrate


def rim_rms(truth, conic):
    w, h = truth.image_size
    pts = truth.rim_image_points(1440)
    pts = pts[(pts[:, 0] > 2) & (pts[:, 0] < w - 3) & (pts[:, 1] > 2) & (pts[:, 1] < h - 3)]
    return float(np.sqrt(np.mean(conic_distance(conic, pts) ** 2)))


def main():
    from omnicam.synthetic import realistic

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    rows = []
    for case in realistic.stress_cases(args.cases, seed=args.seed):
        r = realistic.render_case(case)
        truth = r.camera
        row = {"i": case.index, "holder": "holder" in r.flags}
        for key, kw in (
            ("unguided", {}),
            ("guided", {"expected": expected_rim(truth.K, truth.mirror, truth.D).radius_range}),
        ):
            try:
                row[key] = rim_rms(truth, detect_rim(r.image, **kw).conic)
            except ValueError:
                row[key] = math.inf
        try:
            cam, rep = calibrate(truth.K, truth.mirror, image=r.image, D=truth.D)
            row["axis"] = math.degrees(math.acos(np.clip(cam.R[:, 2] @ truth.R[:, 2], -1, 1)))
            row["flagged"] = bool(rep.plausibility)
        except ValueError:
            row["axis"], row["flagged"] = math.nan, True
        rows.append(row)
        print(
            f"{case.index:3d} {','.join(sorted(r.flags)):60s} rim unguided "
            f"{row['unguided']:8.3f} guided {row['guided']:8.3f} px  axis {row['axis']:7.3f} "
            f"deg {'FLAGGED' if row['flagged'] else ''}",
            flush=True,
        )
    n = len(rows)
    hold = [r for r in rows if r["holder"]]
    for key in ("unguided", "guided"):
        print(
            f"rim {key:9s}: RMS > 1 px in {sum(not r[key] < 1 for r in rows)}/{n} renders "
            f"({sum(not r[key] < 1 for r in hold)}/{len(hold)} with a holder); median "
            f"{np.median([r[key] for r in rows]):.3f} px"
        )
    off = [r for r in rows if not r["axis"] < 1.0]
    print(
        f"calibrate: axis off by > 1 deg (or failed) in {len(off)}/{n}, of which "
        f"{sum(r['flagged'] for r in off)} flagged implausible; > 10 deg and silent: "
        f"{sum(r['axis'] > 10 and not r['flagged'] for r in rows)}; flagged with axis < 0.5 deg: "
        f"{sum(r['flagged'] and r['axis'] < 0.5 for r in rows)}"
    )


if __name__ == "__main__":
    main()
