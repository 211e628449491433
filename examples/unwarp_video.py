"""Unwarp a video into a panorama video (and a perspective view) with ``omnicam.Unwarper``.

1. makes a short synthetic video: the misaligned sample rig (``omnicam.samples``) watching a
   scene at infinity that turns about the vertical (a camera on a turntable);
2. builds the remap tables of a panorama and a perspective view once, for the sample
   calibration (``Unwarper.from_camera`` with ``omnicam.PanoramaView``/``PerspectiveView``);
3. ``Unwarper.stream`` reads the video with ``cv2.VideoCapture``, unwarps every frame with
   ``cv2.remap`` into preallocated outputs and writes both views with ``cv2.VideoWriter``.

Run::

    python examples/unwarp_video.py --out examples/out/video
    python examples/unwarp_video.py --out out --input my_mirror_video.mp4 --calib my_rig.yaml

With ``--input`` the video is yours and ``--calib`` its calibration (``calibrate_own_image.py``);
a video of another resolution than the calibration uses ``camera.scaled`` (same sensor).
"""

from __future__ import annotations

import argparse
import os
import time

import cv2
import numpy as np

import omnicam
from omnicam import synthetic

#: Default output folder: examples/out/ (git-ignored), wherever the script is run from.
OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "out")


def make_video(path, camera, frames, fps=15.0, degrees_per_frame=4.0, supersample=2):
    """Write a video of ``camera`` watching the synthetic environment turn about the vertical."""
    env = synthetic.make_environment((1024, 512))
    w, h = camera.image_size
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), fps, (w, h))
    if not writer.isOpened():
        raise RuntimeError(f"cv2.VideoWriter cannot write {path}")
    try:
        for i in range(frames):
            shift = int(round(i * degrees_per_frame / 360.0 * env.shape[1]))
            turned = np.roll(env, shift, axis=1)  # azimuth turns with the column
            writer.write(synthetic.render_environment(camera, turned, supersample=supersample))
    finally:
        writer.release()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--out", default=os.path.join(OUT, "video"), help="output folder (default %(default)s)"
    )
    parser.add_argument("--input", help="your mirror video (default: make a synthetic one)")
    parser.add_argument(
        "--calib", help="calibration file of --input (default: the misaligned sample calibration)"
    )
    parser.add_argument("--frames", type=int, default=48, help="frames of the synthetic video")
    parser.add_argument("--small", action="store_true", help="a 6-frame 250 px video (fast)")
    args = parser.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)

    camera = (
        omnicam.MisalignedHyperbolicCamera.load(args.calib)
        if args.calib
        else omnicam.samples.load("hyperomni_misaligned")
    )
    source = args.input
    if source is None:
        size = (250, 250) if args.small else camera.image_size
        frames = 6 if args.small else args.frames
        source = os.path.join(args.out, "mirror.avi")
        t = time.perf_counter()
        make_video(source, camera.scaled(size), frames)
        print(
            f"made {source}: {frames} frames of {size[0]}x{size[1]} "
            f"({time.perf_counter() - t:.1f} s)"
        )

    cap = cv2.VideoCapture(source)
    if not cap.isOpened():
        raise SystemExit(f"cannot open {source}")
    frame_size = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
    cap.release()

    # the tables, built once for the video's frame size (camera.scaled if it differs from the
    # calibration's): a panorama and a perspective view looking 30 deg down. Even sizes: some
    # codecs, MJPG among them, silently drop an odd last row or column.
    width, height = frame_size[0] // 2 * 2, frame_size[0] * 3 // 8 * 2
    specs = {
        "panorama": omnicam.PanoramaView((2 * width, width // 4 * 2)),
        "perspective": omnicam.PerspectiveView((width, height), fov=80.0, pitch=-30.0),
    }
    unwarper = omnicam.Unwarper.from_camera(camera, specs, frame_size=frame_size)
    outputs = {name: os.path.join(args.out, f"{name}.avi") for name in unwarper.names}
    t = time.perf_counter()
    n = 0
    for i, views in unwarper.stream(source, outputs, fourcc="MJPG"):
        if i == 0:  # keep the first frame's views as pictures
            for name, img in views.items():
                cv2.imwrite(os.path.join(args.out, f"{name}_first.png"), img)
        n = i + 1
    dt = time.perf_counter() - t
    print(
        f"unwarped {n} frames in {dt:.2f} s ({n / dt:.1f} fps, decode and encode included) "
        f"into {', '.join(outputs.values())}"
    )
    return {"frames": n, "outputs": outputs, "frame_size": frame_size}


if __name__ == "__main__":
    main()
