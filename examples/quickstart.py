"""Quick start: render what a misaligned rig sees, calibrate it from that one image, unwarp.

1. a HyperOmni-style rig whose mirror is tilted by 3 deg and shifted by ~2 mm
   (``omnicam.synthetic.misaligned_rig``) renders a scene at infinity;
2. ``MisalignedHyperbolicCamera.calibrate`` finds the mirror posture from that image: the rim
   ellipse, Chen's four candidate postures, and far straight lines (here: pixels along three
   far vertical poles) to choose the right one;
3. the calibrated camera unwarps the image into a panorama and a perspective view.

Run::

    python examples/quickstart.py --out examples/out/quickstart

With your own camera, replace step 1 by ``cv2.imread`` and the rig's ``K`` by your camera matrix
(see ``calibrate_own_image.py``).
"""

from __future__ import annotations

import argparse
import math
import os

import cv2
import numpy as np

import omnicam
from omnicam import synthetic

#: Default output folder: examples/out/ (git-ignored), wherever the script is run from.
OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "out")


def far_vertical_lines(camera, azimuths_deg=(0.0, 120.0, 240.0), n=30):
    """Pixels along the images of far vertical lines (the poles of the synthetic scene).

    With a real image you click these (see ``calibrate_own_image.py``); here they are the exact
    projections of directions along the poles at infinity.
    """
    el = np.radians(np.linspace(-70.0, 5.0, n))
    lines = []
    for az in np.radians(azimuths_deg):
        d = np.stack([np.cos(el) * math.cos(az), np.cos(el) * math.sin(az), np.sin(el)], axis=1)
        px = camera.project_directions(d)
        lines.append(px[np.isfinite(px).all(axis=1)])
    return lines


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--out", default=os.path.join(OUT, "quickstart"), help="output folder (default %(default)s)"
    )
    parser.add_argument(
        "--size",
        type=int,
        default=800,
        help="mirror image width = height in px (default %(default)s)",
    )
    parser.add_argument("--small", action="store_true", help="a 400 px image (fast)")
    args = parser.parse_args(argv)
    size = 400 if args.small else args.size
    os.makedirs(args.out, exist_ok=True)

    # 1. what the rig sees
    truth = synthetic.misaligned_rig(image_size=(size, size))
    image = synthetic.render_environment(truth)
    cv2.imwrite(os.path.join(args.out, "mirror.png"), image)

    # 2. calibrate from the image: K and the mirror are known, the posture is found
    camera, report = omnicam.MisalignedHyperbolicCamera.calibrate(
        truth.K, truth.mirror, image=image, far_lines=far_vertical_lines(truth)
    )
    print(report.summary())
    camera.save(os.path.join(args.out, "calibration.yaml"))
    cv2.imwrite(os.path.join(args.out, "overlay.png"), report.draw(image))
    axis_error = math.degrees(math.acos(min(1.0, float(camera.R[:, 2] @ truth.R[:, 2]))))
    print(f"mirror axis off by {axis_error:.3f} deg from the truth")

    # 3. unwarp: a panorama and a perspective view (cv2.remap tables, built once)
    pano_w = 2 * size
    map1, map2 = camera.init_panorama_maps((pano_w, pano_w // 4))
    cv2.imwrite(
        os.path.join(args.out, "panorama.png"), cv2.remap(image, map1, map2, cv2.INTER_LINEAR)
    )
    view_size = (size, size * 3 // 4)
    K_new = omnicam.K_from_fov(90.0, view_size)
    R = omnicam.rotation_from_ypr(yaw=30.0, pitch=-25.0)
    map1, map2 = camera.init_perspective_maps(K_new, view_size, R=R)
    cv2.imwrite(
        os.path.join(args.out, "perspective.png"), cv2.remap(image, map1, map2, cv2.INTER_LINEAR)
    )
    print(
        f"wrote mirror.png, overlay.png, calibration.yaml, panorama.png, perspective.png "
        f"in {args.out}"
    )
    return {"camera": camera, "report": report, "axis_error_deg": axis_error}


if __name__ == "__main__":
    main()
