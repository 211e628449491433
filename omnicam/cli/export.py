"""``omnicam export``: the calibration as a central model for other tools, with its cost.

::

    omnicam export CALIB --to omnidir|kalibr|camodocal|ocamcalib -o FILE [--depth MM]

A misaligned rig has no single viewpoint; each format gets the central model closest to the
exact rig over the pixels that see the mirror (:mod:`omnicam.formats.central_fit`), and the
command prints (and the file records) its RMS and maximum error in pixels.
"""

from __future__ import annotations

import os
import sys
import warnings

from .._atomic import OutputError
from ..formats.central_export import export
from ._common import (
    EXIT_OK,
    PROG,
    CliError,
    check_output,
    load_calibration,
    one_line,
    positive_arg,
    warn_user,
)


def cmd_export(args):
    """``omnicam export``: the module docstring."""
    check_output(args.output, args.overwrite)
    camera = load_calibration(args.calibration, say_doubt=True)  # one line on a doubtful file
    if args.to in ("kalibr", "camodocal", "ocamcalib") and camera.image_size is None:
        raise CliError(f"{args.to} files need the image size; {args.calibration} has none")
    ext = os.path.splitext(args.output)[1].lower()
    if args.to == "omnidir" and ext not in (".yaml", ".yml", ".xml", ".json"):
        raise CliError(
            f"output {args.output}: an omnidir file is a cv2.FileStorage file "
            f"(.yaml, .yml, .xml or .json)"
        )
    if not args.quiet:  # the fit takes seconds: say what is being done
        print(
            f"{PROG}: fitting the central model closest to {args.calibration} for {args.to} "
            f"(over the pixels that see the mirror)",
            file=sys.stderr,
            flush=True,
        )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        try:
            fit = export(camera, args.to, args.output, depth=args.depth, overwrite=args.overwrite)
        except OutputError as e:
            raise CliError(str(e)) from None
        except ValueError as e:
            raise CliError(f"cannot export {args.calibration}: {e}") from None
    print(f"wrote {args.output} ({args.to}): {fit.summary()}")
    for w in caught:  # the export's own error is large: one line each, naming the better format
        warn_user(one_line(w.message))
    return EXIT_OK


def add_parser(sub):
    """Register the ``export`` subcommand on ``sub`` (argparse sub-parsers)."""
    p = sub.add_parser(
        "export",
        help="the calibration as a central model: cv2.omnidir, Kalibr, camodocal, OCamCalib",
        description="Fit the central model closest to the exact non-central rig and write it "
        "for another tool, with its RMS and maximum error in pixels.",
    )
    p.add_argument("calibration", metavar="CALIB", help="calibration file")
    p.add_argument(
        "--to",
        required=True,
        choices=("omnidir", "kalibr", "camodocal", "ocamcalib"),
        help="target: omnidir (cv2.omnidir FileStorage), kalibr (camchain yaml), "
        "camodocal (MEI yaml), ocamcalib (calib_results.txt)",
    )
    p.add_argument("-o", "--output", required=True, metavar="FILE", help="file to write")
    p.add_argument(
        "--depth",
        type=positive_arg,
        metavar="MM",
        help="fit for a scene at this distance from the best-fit viewpoint "
        "(default: at infinity; not for ocamcalib)",
    )
    p.add_argument("--overwrite", action="store_true", help="replace FILE if it exists")
    p.add_argument(
        "-q", "--quiet", action="store_true", help="no progress line (the fit takes seconds)"
    )
    p.set_defaults(func=cmd_export)
    return p


__all__ = ["add_parser", "cmd_export"]
