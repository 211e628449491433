"""``omnicam maps``: remap tables as files, for ffmpeg's ``remap`` filter, numpy or OpenCV.

::

    omnicam maps CALIB --panorama 2048x512 [--elevation LO HI] --ffmpeg -o PREFIX
    omnicam maps CALIB --perspective 640x480 --fov 90 --npy -o PREFIX

``--ffmpeg`` writes ``PREFIX_x.pgm`` and ``PREFIX_y.pgm`` (16-bit PGM, integer source pixels,
65535 where the mirror sees nothing) and prints the ffmpeg command that applies them;
``--npy`` writes ``PREFIX_x.npy`` and ``PREFIX_y.npy`` (float32); ``--filestorage EXT`` writes
``PREFIX.EXT`` with ``map_x`` and ``map_y``. Views are given as for ``omnicam unwarp`` (several
views, each with its own ``-o PREFIX``).
"""

from __future__ import annotations

import math

import cv2

from .._atomic import OutputError
from ..camera import scale_K
from ..formats.maps import (
    ffmpeg_command,
    float_maps,
    write_ffmpeg_maps,
    write_filestorage_maps,
    write_npy_maps,
)
from ..spherical import equirect_view
from ..views import PanoramaView, visible_elevation_range
from ._common import (
    EXIT_OK,
    EXIT_USAGE,
    CliError,
    check_output,
    count_arg,
    load_calibration,
    size_arg,
)
from .unwarp import add_view_arguments, view_specs


def _scaled_view(spec, camera, k):
    """The view of ``spec`` with ``k x k`` output pixels in place of each pixel: the fine pixel
    centres are those of the ``k x k`` blocks of each coarse pixel (same field of view), so
    scaling the result down by ``k`` with area averaging gives the coarse view."""
    view = spec.view
    if k == 1:
        return view
    w, h = view.size
    size = (w * k, h * k)
    if spec.kind == "equirect":
        return equirect_view(size, depth=view.depth, yaw=view.yaw)
    if spec.kind == "perspective":
        return type(view)(
            size,
            K_new=scale_K(view.K_new, view.size, size),
            R=view.R,
            depth=view.depth,
            viewpoint=view.viewpoint,
        )
    if view.elevation_range is None and view.projection == "cylindrical":
        lo, hi, _ = view.default_range(camera)  # above the camera's reflection, or -60 deg
    elif view.elevation_range is None:
        lo, hi = visible_elevation_range(camera)
    else:
        lo, hi = view.elevation_range
    to_p, from_p = (
        (lambda d: math.tan(math.radians(d)), lambda p: math.degrees(math.atan(p)))
        if view.projection == "cylindrical"
        else (math.radians, math.degrees)
    )
    step = (to_p(lo) - to_p(hi)) / (h - 1)
    shift = 0.5 - 0.5 / k
    limit = 89.999 if view.projection == "cylindrical" else 90.0
    hi2 = min(from_p(to_p(hi) - step * shift), limit)
    lo2 = max(from_p(to_p(lo) + step * shift), -limit)
    # columns need no turn: the centre is column (W - 1) / 2 of both, so sub-column m of
    # column j (fine column j k + m) looks at -yaw - 360 (j - 0.5 + (m + 0.5) / k - (W - 1) / 2) / W
    return PanoramaView(
        size,
        elevation_range=(lo2, hi2),
        projection=view.projection,
        R=view.R,
        depth=view.depth,
        viewpoint=view.viewpoint,
        yaw=view.yaw,
    )


def cmd_maps(args):
    """``omnicam maps``: the module docstring."""
    if not (args.ffmpeg or args.npy or args.filestorage):
        raise CliError("choose what to write: --ffmpeg, --npy and/or --filestorage EXT", EXIT_USAGE)
    specs = view_specs(args)
    camera = load_calibration(args.calibration, say_doubt=True)  # one line on a doubtful file
    if args.frame_size is not None:
        if camera.image_size is None:
            raise CliError(f"--frame-size: the calibration {args.calibration} has no image size")
        camera = camera.scaled(args.frame_size)
    source = camera.image_size
    if source is None:
        raise CliError(f"the calibration {args.calibration} has no image size; give --frame-size")
    k = args.supersample or 1
    for spec in specs:
        prefix = spec.output
        targets = []
        if args.ffmpeg:
            targets += [f"{prefix}_x.pgm", f"{prefix}_y.pgm"]
        if args.npy:
            targets += [f"{prefix}_x.npy", f"{prefix}_y.npy"]
        if args.filestorage:
            targets.append(f"{prefix}.{args.filestorage}")
        for t in targets:
            check_output(t, args.overwrite)
        try:
            view = _scaled_view(spec, camera, k) if args.ffmpeg else spec.view
            mx, my = float_maps(*view.maps(camera, cv2.CV_32FC1))
            if args.ffmpeg:
                px, py = write_ffmpeg_maps(prefix, mx, my, source, overwrite=args.overwrite)
                if not args.quiet:
                    print(
                        f"wrote {px} and {py} ({mx.shape[1]}x{mx.shape[0]}, for "
                        f"{source[0]}x{source[1]} frames)"
                    )
                print(ffmpeg_command(px, py, spec.size, k))
                if k > 1 and (args.npy or args.filestorage):
                    mx, my = float_maps(*spec.view.maps(camera, cv2.CV_32FC1))
            if args.npy:
                px, py = write_npy_maps(prefix, mx, my, overwrite=args.overwrite)
                if not args.quiet:
                    print(f"wrote {px} and {py}")
            if args.filestorage:
                path = write_filestorage_maps(
                    f"{prefix}.{args.filestorage}", mx, my, overwrite=args.overwrite
                )
                if not args.quiet:
                    print(f"wrote {path}")
        except OutputError as e:
            raise CliError(str(e)) from None
        except ValueError as e:
            raise CliError(f"cannot build the maps: {e}") from None
    return EXIT_OK


def add_parser(sub):
    """Register the ``maps`` subcommand on ``sub`` (argparse sub-parsers)."""
    p = sub.add_parser(
        "maps",
        help="remap tables as files: PGM for ffmpeg's remap filter, .npy, FileStorage",
        description="Write a view's remap tables for other tools. --ffmpeg: PREFIX_x.pgm and "
        "PREFIX_y.pgm for ffmpeg's remap filter (and the command line to use them).",
    )
    p.add_argument("calibration", metavar="CALIB", help="calibration file")
    add_view_arguments(p, output_help="prefix of the files written for the view")
    p.add_argument(
        "--ffmpeg", action="store_true", help="16-bit PGM maps for ffmpeg's remap filter"
    )
    p.add_argument("--npy", action="store_true", help="float32 maps as PREFIX_x/_y.npy")
    p.add_argument(
        "--filestorage",
        choices=("yaml", "yml", "xml", "json"),
        metavar="EXT",
        help="float32 maps map_x, map_y in PREFIX.EXT (yaml, yml, xml, json)",
    )
    p.add_argument(
        "--supersample",
        type=count_arg,
        metavar="K",
        help="--ffmpeg: maps at K times the size; ffmpeg scales the result down",
    )
    p.add_argument(
        "--frame-size",
        type=size_arg,
        metavar="WxH",
        help="size of the frames to unwarp (default: the calibration's)",
    )
    p.add_argument("--overwrite", action="store_true", help="replace files that exist")
    p.add_argument("-q", "--quiet", action="store_true", help="print only the ffmpeg command")
    p.set_defaults(func=cmd_maps, ordered=None)
    return p


__all__ = ["add_parser", "cmd_maps"]
