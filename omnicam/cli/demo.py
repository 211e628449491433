"""``omnicam demo``: the whole pipeline on the built-in synthetic scene."""

from __future__ import annotations

import math
import os
import time

import cv2
import numpy as np

from .. import synthetic
from ..formats.intrinsics import write_intrinsics
from ..formats.point_files import write_far_lines
from ..hyperbolic_camera import MisalignedHyperbolicCamera
from ..synthetic.demo import DEMO_CLICK_NOISE_PX, demo_environment, demo_far_lines
from ..views import UNSEEN, K_from_fov, camera_forward_yaw, rotation_from_ypr
from ._common import (
    EXIT_OK,
    CliError,
    indent_lines,
    one_line,
    report_text,
    save_calibration,
    user_terms,
    write_image_file,
)
from .info import posture, vector_text


def _table_rms(cam_a, cam_b, size):
    """RMS distance (px) between two cameras' float panorama tables where both see the mirror."""
    # one yaw for both: by default each panorama centres its own camera's forward direction
    a = cam_a.init_panorama_maps(size, m1type=cv2.CV_32FC2, yaw=0.0)[0]
    b = cam_b.init_panorama_maps(size, m1type=cv2.CV_32FC2, yaw=0.0)[0]
    ok = (a[..., 0] != UNSEEN) & (b[..., 0] != UNSEEN)
    d = (a - b)[ok]
    return float(np.sqrt(np.mean(np.sum(d * d, axis=-1)))) if d.size else float("nan")


def cmd_demo(args):
    """``omnicam demo``: the module docstring."""
    t_start = time.perf_counter()
    out = args.output
    if os.path.exists(out) and not os.path.isdir(out):
        raise CliError(f"output folder {out} is a file")
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as e:
        raise CliError(f"cannot create output folder {out}: {e.strerror or e}") from None
    if not os.access(out, os.W_OK | os.X_OK):
        raise CliError(f"output folder {out} is not writable")

    def path(name):
        return os.path.join(out, name)

    truth = synthetic.misaligned_rig()
    m = truth.mirror
    print(
        f"1. a misaligned rig: mirror a = {m.a:g}, b = {m.b:g}, rim {m.rim_radius:g} mm, "
        f"{truth.image_size[0]}x{truth.image_size[1]} camera; the truth:"
    )
    tilt, az, offset = posture(truth)
    print(
        f"   axis tilt {tilt:.3f} deg towards {az:.1f} deg, camera offset "
        f"{vector_text(offset, '{:.3f}')} mm from the lower focus"
    )
    image = synthetic.render_environment(truth, demo_environment(), supersample=2)
    write_image_file(path("mirror.png"), image)
    write_intrinsics(path("intrinsics.yaml"), truth.K, image_size=truth.image_size)
    lines = demo_far_lines(truth)
    write_far_lines(path("far_lines.json"), [np.round(line, 2) for line in lines])
    print(
        f"2. rendered what it sees of a scene at infinity ({path('mirror.png')}); "
        f"{sum(map(len, lines))} pixels 'clicked' (+-{DEMO_CLICK_NOISE_PX} px) along its "
        f"{len(lines)} orange far straight lines ({path('far_lines.json')})"
    )

    print("3. calibration from that image (rim ellipse, Chen's method, far-line selection):")
    try:
        camera, report = MisalignedHyperbolicCamera.calibrate(
            truth.K, m, image=image, far_lines=lines, image_size=truth.image_size
        )
    except (ValueError, RuntimeError, NotImplementedError, np.linalg.LinAlgError) as e:
        raise CliError(f"demo: calibration failed: {one_line(e)}") from None
    print(indent_lines(user_terms(report_text(report))))
    write_image_file(path("overlay.png"), report.draw(image))
    save_calibration(camera, path("calibration.yaml"), overwrite=True)  # with its verdict

    e_tilt, e_az, e_offset = posture(camera)
    axis_error = math.degrees(math.acos(float(np.clip(camera.R[:, 2] @ truth.R[:, 2], -1, 1))))
    baseline = MisalignedHyperbolicCamera.aligned(
        m, truth.K[0, 0], truth.K[0, 2], truth.K[1, 2], truth.image_size
    )
    pano_size = (1024, 256)
    print("4. posture error vs the truth:")
    print(
        f"   axis tilt      {e_tilt:.3f} deg (true {tilt:.3f}); axis direction off by "
        f"{axis_error:.3f} deg (stated uncertainty {report.axis_std_deg:.3f} deg RMS)"
    )
    print(
        f"   camera offset  {vector_text(e_offset, '{:.3f}')} mm "
        f"(true {vector_text(offset, '{:.3f}')}); "
        f"off by {np.linalg.norm(e_offset - offset):.3f} mm"
    )
    print(
        f"   panorama tables vs the true rig's, RMS: calibrated "
        f"{_table_rms(camera, truth, (256, 64)):.2f} px, uncalibrated aligned model (eqs. 2-5) "
        f"{_table_rms(baseline, truth, (256, 64)):.2f} px"
    )

    forward = camera_forward_yaw(camera)  # both panoramas centred alike, to compare them
    views = {
        "panorama.png": camera.init_panorama_maps(pano_size, yaw=forward),
        "panorama_uncalibrated.png": baseline.init_panorama_maps(pano_size, yaw=forward),
        "perspective.png": camera.init_perspective_maps(
            K_from_fov(90.0, (640, 480)),
            (640, 480),
            R=rotation_from_ypr(0.0, -20.0, 0.0),
        ),
    }
    for name, (map1, map2) in views.items():
        write_image_file(path(name), cv2.remap(image, map1, map2, cv2.INTER_LINEAR))
    print(f"5. wrote {', '.join(['calibration.yaml', 'overlay.png', *views])} in {out}")
    print(f"   try: omnicam info {path('calibration.yaml')}")
    print(
        f"        omnicam calibrate {path('mirror.png')} --mirror {m.a:g} {m.b:g} "
        f"{m.rim_radius:g} --intrinsics {path('intrinsics.yaml')} --far-lines "
        f"{path('far_lines.json')} -o my_calibration.yaml"
    )
    print(
        f"        omnicam unwarp {path('mirror.png')} -c {path('calibration.yaml')} "
        f"--perspective 640x480 --fov 70 --yaw 45 -o view.png"
    )
    print(f"done in {time.perf_counter() - t_start:.1f} s")
    return EXIT_OK


def add_parser(sub):
    """Register the ``demo`` subcommand on ``sub`` (argparse sub-parsers)."""
    p = sub.add_parser(
        "demo",
        help="the whole pipeline on built-in synthetic data",
        description="Render a misaligned rig, calibrate it from the rendered "
        "image, compare with the truth, and write the calibration, the mirror "
        "image, the overlay, a panorama and a perspective view. The demo's own "
        "files in OUTDIR are replaced.",
    )
    p.add_argument(
        "-o",
        "--output",
        default="omnicam-demo",
        metavar="OUTDIR",
        help="folder for the results (default ./omnicam-demo)",
    )
    p.set_defaults(func=cmd_demo)
    return p
