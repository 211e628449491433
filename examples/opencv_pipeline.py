"""omnicam as a drop-in in front of an OpenCV pipeline: unwarp, then detect lines and features.

A perspective view made with ``cv2.remap`` and omnicam's tables is an ordinary pinhole image,
so ``cv2.Canny``/``cv2.HoughLinesP``, ``cv2.goodFeaturesToTrack``, ``cv2.ORB`` and friends
work on it unchanged, and straight scene edges are straight. This script shows it on a room
seen by the misaligned sample rig, with the sample calibration
(``omnicam.samples.load("hyperomni_misaligned")``) and, for comparison, the uncalibrated aligned
model (eqs. 2-5) with the same ``K``:

1. four perspective views of each, looking 25 deg down at the walls all around (the cube in
   front of one of them);
2. ``cv2.Canny`` + ``cv2.HoughLinesP``; for every long segment, a parabola fitted to the edge
   pixels along it gives its **bow** (the sagitta over the segment, px): ~0 for a straight
   edge, larger for a curved one. The room's edges are all straight in 3-D;
3. ``cv2.goodFeaturesToTrack`` and ``cv2.ORB`` keypoints, drawn on the views.

Run::

    python examples/opencv_pipeline.py --out examples/out/opencv
"""

from __future__ import annotations

import argparse
import os

import cv2
import numpy as np

import omnicam
from omnicam import synthetic

#: Default output folder: examples/out/ (git-ignored), wherever the script is run from.
OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "out")


def segment_bows(gray, min_length):
    """Long straight-edge candidates and their bow.

    Returns a list of ``(x1, y1, x2, y2, bow_px)``: ``cv2.HoughLinesP`` segments at least
    ``min_length`` long; the Canny pixels within 3 px of each are fitted with
    ``v = a + b u + c u^2`` in the segment's frame (``u`` along it) and the bow is the fitted
    curve's sagitta over the segment, ``|c| (L/2)^2``.
    """
    edges = cv2.Canny(gray, 50, 150)
    segments = cv2.HoughLinesP(
        edges, 1, np.pi / 720, threshold=60, minLineLength=min_length, maxLineGap=3
    )
    if segments is None:
        return []
    ys, xs = np.nonzero(edges)
    pts = np.stack([xs, ys], axis=1).astype(np.float64)
    out = []
    for x1, y1, x2, y2 in segments.reshape(-1, 4):
        p0, p1 = np.array([x1, y1], float), np.array([x2, y2], float)
        length = float(np.linalg.norm(p1 - p0))
        t = (p1 - p0) / length
        n = np.array([-t[1], t[0]])
        u = (pts - (p0 + p1) / 2) @ t
        v = (pts - (p0 + p1) / 2) @ n
        near = (np.abs(u) <= length / 2) & (np.abs(v) <= 3.0)
        if near.sum() < 0.8 * length:
            continue
        c = np.polyfit(u[near], v[near], 2)[0]
        out.append((int(x1), int(y1), int(x2), int(y2), abs(c) * (length / 2) ** 2))
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--out", default=os.path.join(OUT, "opencv"), help="output folder (default %(default)s)"
    )
    parser.add_argument(
        "--size",
        type=int,
        default=1000,
        help="mirror image width = height in px (default %(default)s)",
    )
    parser.add_argument("--small", action="store_true", help="a 500 px image (fast)")
    args = parser.parse_args(argv)
    size = 500 if args.small else args.size
    os.makedirs(args.out, exist_ok=True)

    calibrated = omnicam.samples.load("hyperomni_misaligned").scaled((size, size))
    image = synthetic.render_room(calibrated)  # what this rig sees of the room
    m, K = calibrated.mirror, calibrated.K
    models = {
        "calibrated": calibrated,
        "uncalibrated": omnicam.MisalignedHyperbolicCamera.aligned(
            m, K[0, 0], K[0, 2], K[1, 2], calibrated.image_size
        ),
    }

    view_size = (size * 4 // 5, size * 3 // 5)
    K_new = omnicam.K_from_fov(90.0, view_size)
    yaws = (0.0, 90.0, 180.0, 270.0)  # four views around the room, 25 deg down
    results = {}
    for name, cam in models.items():
        panels, bows, n_corners, n_orb = [], [], 0, 0
        for yaw in yaws:
            R = omnicam.rotation_from_ypr(yaw=yaw, pitch=-25.0)
            # the walls are 2.5 m away: depth=2500 (mm) makes the view exact there
            map1, map2 = cam.init_perspective_maps(K_new, view_size, R=R, depth=2500.0)
            view = cv2.remap(image, map1, map2, cv2.INTER_LINEAR)
            gray = cv2.cvtColor(view, cv2.COLOR_BGR2GRAY)

            # the OpenCV pipeline, unchanged: lines, corners, ORB
            segments = segment_bows(gray, min_length=view_size[0] // 6)
            corners = cv2.goodFeaturesToTrack(
                gray, maxCorners=200, qualityLevel=0.05, minDistance=8
            )
            keypoints = cv2.ORB_create(nfeatures=500).detect(gray, None)

            bows += [seg[4] for seg in segments]
            n_corners += 0 if corners is None else len(corners)
            n_orb += len(keypoints)
            drawn = cv2.drawKeypoints(view, keypoints, None, (255, 160, 0))
            for x1, y1, x2, y2, bow in segments:
                colour = (0, 200, 0) if bow < 0.5 else (0, 0, 255)
                cv2.line(drawn, (x1, y1), (x2, y2), colour, 2, cv2.LINE_AA)
            for x, y in corners.reshape(-1, 2) if corners is not None else []:
                cv2.circle(drawn, (int(x), int(y)), 3, (255, 0, 255), -1, cv2.LINE_AA)
            cv2.putText(
                drawn,
                f"{name}, yaw {yaw:g}",
                (10, 30),
                cv2.FONT_HERSHEY_SIMPLEX,
                0.8,
                (255, 255, 255),
                2,
                cv2.LINE_AA,
            )
            panels.append(drawn)
            if yaw == yaws[0]:
                cv2.imwrite(os.path.join(args.out, f"view_{name}.png"), view)
        grid = np.vstack([np.hstack(panels[:2]), np.hstack(panels[2:])])
        cv2.imwrite(os.path.join(args.out, f"features_{name}.png"), grid)
        b = np.array(bows)
        results[name] = {
            "segments": len(b),
            "median_bow_px": float(np.median(b)) if len(b) else float("nan"),
            "p90_bow_px": float(np.percentile(b, 90)) if len(b) else float("nan"),
            "corners": n_corners,
            "orb": n_orb,
        }
        r = results[name]
        print(
            f"{name:12s}: {r['segments']:3d} long Hough segments in 4 views, bow median "
            f"{r['median_bow_px']:.2f} px, 90th percentile {r['p90_bow_px']:.2f} px; "
            f"{r['corners']} corners, {r['orb']} ORB keypoints"
        )
    print(
        f"wrote view_*.png (yaw 0) and features_*.png (the four views; segments green: bow "
        f"< 0.5 px, red: curved; magenta: corners; blue: ORB) in {args.out}"
    )
    return results


if __name__ == "__main__":
    main()
