"""Render the HTML report of a calibration of the project's own renders, and screenshot it in
headless Chromium (a real browser: the page must open offline, every image embedded).

::

    python benchmarks/render_report_screenshot.py [--route chessboard|image] [-o OUT.html]
        [--png OUT.png] [--scale 0.5] [--height 9000] [--chromium chromium]

The chessboard route renders 8 board views of a misaligned rig (omnicam.synthetic.boards),
calibrates them (4-fold held-out check) and writes the page; the image route renders the demo
scene with its far lines and calibrates from that one image. The screenshot is taken with
Chromium at 1280 px wide and ``--height`` tall, the page's empty tail trimmed, scaled by
``--scale`` and posterized to ``--levels`` per channel (so that it stays small as a PNG);
docs/report_example.png is
``python benchmarks/render_report_screenshot.py --png docs/report_example.png``.
Install Chromium with ``apt-get install -y chromium``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time

import cv2
import numpy as np

import omnicam
from omnicam import synthetic
from omnicam.calibration import calibrate
from omnicam.html_report import image_report_html, pattern_report_html, write_report
from omnicam.synthetic import boards
from omnicam.synthetic.demo import demo_environment, demo_far_lines

PATTERN, SQUARE = (7, 5), 60.0


def chessboard_page():
    rig = synthetic.misaligned_rig(3.0, 30.0, (1.5, -2.0, 1.9), image_size=(640, 640))
    poses = boards.random_board_poses(
        rig, 8, PATTERN, SQUARE, distance=(350.0, 800.0), max_tilt_deg=40.0, rng=5
    )
    images = [boards.render_board(rig, PATTERN, SQUARE, *p, supersample=2) for p in poses]
    camera, report = omnicam.MisalignedHyperbolicCamera.calibrate_pattern(
        images, PATTERN, SQUARE, rig.mirror, dist_model="none", heldout=4
    )
    names = [f"board{i}.png" for i in range(len(images))]
    return pattern_report_html(
        camera,
        report,
        images,
        names=names,
        pattern_size=PATTERN,
        notes=["8 renders of a misaligned rig (omnicam.synthetic.boards), 7x5 corners, 60 mm."],
    )


def image_page():
    truth = synthetic.misaligned_rig(3.0, 30.0, (1.5, -1.0, 1.0), image_size=(640, 640))
    image = synthetic.render_environment(truth, demo_environment(), supersample=2, seed=1)
    lines = demo_far_lines(truth)
    camera, report = calibrate(
        truth.K,
        truth.mirror,
        image=image,
        far_lines=lines,
        camera_cls=omnicam.MisalignedHyperbolicCamera,
    )
    return image_report_html(
        camera, report, image, notes=["The demo scene (omnicam demo) with its three far lines."]
    )


def screenshot(html_path, png_path, height, chromium):
    """Chromium's screenshot of the page, 1280 px wide; returns the BGR image."""
    profile = tempfile.mkdtemp(prefix="omnicam-chromium-")
    try:
        subprocess.run(
            [
                chromium,
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                f"--user-data-dir={profile}",
                f"--screenshot={png_path}",
                f"--window-size=1280,{height}",
                "file://" + os.path.abspath(html_path),
            ],
            check=True,
            capture_output=True,
            timeout=180,
        )
    finally:
        shutil.rmtree(profile, ignore_errors=True)
    shot = cv2.imread(png_path)
    if shot is None:
        raise RuntimeError(f"chromium wrote no readable screenshot {png_path}")
    return shot


def trim(shot):
    """The screenshot without its empty tail (rows of the page's background only)."""
    bg = shot[-1, 5].astype(int)
    busy = np.flatnonzero((np.abs(shot.astype(int) - bg).max(axis=2) > 8).any(axis=1))
    return shot[: busy[-1] + 16] if len(busy) else shot


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--route", choices=("chessboard", "image"), default="chessboard")
    p.add_argument("-o", "--output", default=None, help="the page (default: a temporary file)")
    p.add_argument("--png", default="report_screenshot.png", help="the screenshot to write")
    p.add_argument("--height", type=int, default=9000, help="the browser window's height")
    p.add_argument("--scale", type=float, default=0.5, help="scale of the PNG written")
    p.add_argument(
        "--levels",
        type=int,
        default=32,
        help="grey levels per channel of the PNG (fewer: a smaller file; 256 keeps them all)",
    )
    p.add_argument("--chromium", default="chromium")
    args = p.parse_args(argv)
    if shutil.which(args.chromium) is None:
        sys.exit(f"{args.chromium} not found: apt-get install -y chromium")
    t = time.perf_counter()
    page = chessboard_page() if args.route == "chessboard" else image_page()
    print(f"page built in {time.perf_counter() - t:.1f} s, {len(page) / 1e6:.2f} MB")
    out = args.output or os.path.join(tempfile.mkdtemp(), "report.html")
    write_report(out, page)
    shot = trim(screenshot(out, args.png, args.height, args.chromium))
    if args.scale != 1.0:
        shot = cv2.resize(shot, None, fx=args.scale, fy=args.scale, interpolation=cv2.INTER_AREA)
    if args.levels < 256:  # posterized: a screenshot of photographs compresses badly as PNG
        q = 256 // max(args.levels, 2)
        shot = (shot // q * q + q // 2).astype(np.uint8)
    cv2.imwrite(args.png, shot, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(
        f"wrote {out} and {args.png} ({shot.shape[1]}x{shot.shape[0]}, "
        f"{os.path.getsize(args.png) / 1e3:.0f} kB)"
    )


if __name__ == "__main__":
    main()
