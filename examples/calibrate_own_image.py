"""Calibrate your own mirror image: the mirror posture from one image and a few far-line points.

What you need:

* the image of the mirror (the whole rim in view, or most of it);
* the camera's intrinsics ``K`` (and ``D``), from ``omnicam.calibrate_intrinsics`` on chessboard
  images of the camera without the mirror, in a YAML file written by ``cv2.FileStorage`` with
  ``K`` (3x3), optionally ``D`` and ``image_size``;
* the mirror's ``a``, ``b`` and rim radius from its data sheet;
* **far lines**: pixels along the images of two or more long straight lines far from the camera
  (a building edge, a wall corner, the horizon, a pole), used to pick the right one of the
  postures the rim allows (paper section 3.2). How to pick them: open the image in any viewer
  that shows pixel coordinates (GIMP, ImageJ, ``python -m matplotlib`` ...), and for each line
  note 10-30 points along its whole visible length (at least 3), as far from the image
  centre as the line goes; lines in different directions help. Write them as JSON, a list of
  lines, each a list of ``[x, y]`` pixels::

      [[[612.5, 388.0], [640.1, 371.2], ...], [[301.0, 655.4], ...]]

  Accuracy matters when the far lines have to choose on their own: for a small misalignment
  the two physically possible postures bend a far line by only a few hundredths of a pixel
  differently, so points clicked to the nearest pixel may not tell them apart. By default
  (``lens="auto"``) ``calibrate`` also fits the outline of the camera's own reflection in the
  mirror, which separates them robustly when it is found. Read the report: a low
  ``confidence`` comes with a warning; then add lines, or place the points on the line's edge
  to subpixel precision (zoom in, or refine them with an edge or ridge detector).

Run on your image::

    python examples/calibrate_own_image.py --image mirror.png --intrinsics camera.yaml \\
        --mirror 23.4 28.1 30 --far-lines lines.json --out calib_out

Without ``--image`` it runs on a rendered room (the misaligned sample rig), with far lines
written to ``lines.json`` from the exact projections of the room's four vertical corner edges
(3-D lines 3.5 m away), then read back from that file as yours would be.

Writes ``calibration.yaml`` (``MisalignedHyperbolicCamera.load`` reads it; so does
``omnicam unwarp -c``) and ``overlay.png`` (fitted rim, far lines, the candidates' line
predictions) into ``--out``, and prints the report.
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


def room_example(out):
    """A rendered room seen by the misaligned sample rig, its intrinsics and far lines."""
    truth = omnicam.samples.load("hyperomni_misaligned")
    room = synthetic.Room()
    image = synthetic.render_room(truth, room)
    image_path = os.path.join(out, "mirror.png")
    cv2.imwrite(image_path, image)
    intrinsics = os.path.join(out, "camera.yaml")
    omnicam.write_intrinsics(intrinsics, truth.K, image_size=truth.image_size)
    # the room's vertical corner edges, 3.5 m away: 3-D straight lines projected exactly
    lo, hi = np.asarray(room.box_min), np.asarray(room.box_max)
    lines = [
        np.round(synthetic.line_pixels(truth, (x, y, lo[2] + 50.0), (x, y, hi[2] - 50.0), 25), 2)
        for x in (lo[0], hi[0])
        for y in (lo[1], hi[1])
    ]
    lines_path = os.path.join(out, "lines.json")
    omnicam.write_far_lines(lines_path, lines)
    m = truth.mirror
    return image_path, intrinsics, (m.a, m.b, m.rim_radius), lines_path, truth


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--out", default=os.path.join(OUT, "own_image"), help="output folder (default %(default)s)"
    )
    parser.add_argument("--image", help="your mirror image (default: a rendered room)")
    parser.add_argument("--intrinsics", help="YAML with K (and D, image_size) of your camera")
    parser.add_argument(
        "--mirror",
        type=float,
        nargs=3,
        metavar=("A", "B", "RIM"),
        help="mirror a, b and rim radius (mm)",
    )
    parser.add_argument("--far-lines", help="JSON file of far-line pixels (see above)")
    parser.add_argument(
        "--small",
        action="store_true",
        help="accepted for symmetry with the other examples (the rendered room is already 500 px)",
    )
    args = parser.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)

    truth = None
    if args.image is None:
        args.image, args.intrinsics, args.mirror, args.far_lines, truth = room_example(args.out)
    elif not (args.intrinsics and args.mirror):
        parser.error("--image needs --intrinsics and --mirror")
    image = cv2.imread(args.image, cv2.IMREAD_COLOR)
    if image is None:
        raise SystemExit(f"cannot read {args.image}")
    K, D, size = omnicam.read_intrinsics(args.intrinsics)
    if size is not None and tuple(size) != (image.shape[1], image.shape[0]):
        raise SystemExit(
            f"intrinsics are for {size}, the image is "
            f"{image.shape[1]}x{image.shape[0]}; scale K or recalibrate"
        )
    far_lines = omnicam.read_far_lines(args.far_lines) if args.far_lines else None
    mirror = omnicam.HyperbolicMirror(*args.mirror)

    camera, report = omnicam.MisalignedHyperbolicCamera.calibrate(
        K, mirror, image=image, far_lines=far_lines, D=D
    )
    print(report.summary())
    calib = os.path.join(args.out, "calibration.yaml")
    camera.save(calib)
    cv2.imwrite(os.path.join(args.out, "overlay.png"), report.draw(image))
    print(f"wrote {calib} and {os.path.join(args.out, 'overlay.png')}")
    result = {"camera": camera, "report": report}
    if truth is not None:
        cosang = float(np.clip(camera.R[:, 2] @ truth.R[:, 2], -1.0, 1.0))
        result["axis_error_deg"] = float(np.degrees(np.arccos(cosang)))
        result["centre_error_mm"] = float(
            np.linalg.norm(camera.camera_center - truth.camera_center)
        )
        print(
            f"against the rendered truth: mirror axis off by {result['axis_error_deg']:.3f} "
            f"deg, camera centre off by {result['centre_error_mm']:.3f} mm"
        )
    return result


if __name__ == "__main__":
    main()
