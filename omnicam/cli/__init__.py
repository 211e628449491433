"""The ``omnicam`` console script: calibrate, unwarp, maps, export, info, report and demo.

::

    omnicam calibrate IMAGE --mirror A B RIM (--intrinsics K.yaml | --fx F --fy F --cx X --cy Y
                      [--dist D ...]) [--far-lines LINES.json] [--rim-hint CX,CY,R]
                      [--boundary-points FILE] [--max-tilt DEG] [--max-offset MM] [--force]
                      [--candidates DIR] [--choose N]
                      -o CALIB [--no-refine] [--overlay PATH] [--report PAGE.html] [--overwrite]
        (or any other mirror of revolution instead of --mirror: --sphere RADIUS RIM |
         --paraboloid R RIM | --asphere R K RIM [--alpha A ...], each [--vertex-z Z] |
         --equiangular GAIN R0 RIM | --mirror-file MIRROR.yaml)
    omnicam calibrate --chessboard CxR --square S IMAGES... --mirror A B RIM [--intrinsics K]
                      -o CALIB [--report PAGE.html]
    omnicam unwarp INPUT -c CALIB VIEW [VIEW ...] [--overwrite] [--max-frames N]
                   [--fourcc CODE] [--preview N] [--quiet]
        VIEW: (--panorama WxH [--elevation LO HI] [--projection P]
               | --perspective WxH --fov DEG [--yaw Y] [--pitch P] [--roll R]
               | --equirect WxH) [--depth MM] -o OUTPUT
    omnicam maps CALIB VIEW [VIEW ...] (--ffmpeg [--supersample K] | --npy | --filestorage EXT)
    omnicam export CALIB --to omnidir|kalibr|camodocal|ocamcalib -o FILE [--depth MM]
    omnicam info CALIB
    omnicam report CALIB IMAGES... -o PAGE.html [--chessboard CxR --square S]
                   [--far-lines LINES.json] [--overwrite]
    omnicam demo [-o OUTDIR]

Contract (py360convert style): :func:`main` takes ``argv`` and returns the exit status, so tests
call ``main([...])`` directly. Every failure the user can cause is one line on stderr,
``omnicam: error: ...``, with exit status 2 for a malformed command line and 1 for the rest
(130 after Ctrl-C). Nothing existing is overwritten unless ``--overwrite`` says so, and outputs
are written to a temporary file in the destination folder (same extension, so the same format)
that is renamed into place, so a good file is never replaced by a half-written one. A video
output is read back before it is renamed into place; when the input ends early (a truncated
file) or on Ctrl-C the frames written so far are kept in a valid, finalised file (beside an
earlier output, as ``NAME.partial.EXT``, never over it). Set ``OMNICAM_DEBUG=1`` to get the
traceback of an unexpected error instead of its one-line summary.
"""

from __future__ import annotations

import contextlib
import os
import sys

from .. import __version__
from .._quiet import opencv_silenced
from . import calibrate, demo, export, info, maps, report, unwarp
from ._common import (
    EXIT_FAILURE,
    EXIT_INTERRUPTED,
    EXIT_OK,
    PROG,
    CliError,
    _Parser,
    one_line,
    print_error,
)
from .unwarp import Progress  # noqa: F401 (public for tests that patch it)

__all__ = ["main", "build_parser"]


# -- the parser -------------------------------------------------------------------------------
def build_parser():
    """The ``argparse`` parser of the ``omnicam`` command (one sub-parser per command)."""
    parser = _Parser(
        prog=PROG,
        description="Calibrate and unwarp misaligned hyperbolic-mirror catadioptric cameras.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    for module in (calibrate, unwarp, maps, export, info, report, demo):
        module.add_parser(sub)
    return parser


#: Exit status when the reader of stdout went away (128 + SIGPIPE, as the shell reports it).
EXIT_BROKEN_PIPE = 141


def main(argv=None) -> int:
    """Run the ``omnicam`` command line; return the exit status."""
    try:
        with opencv_silenced(keep_messages=True, ffmpeg=True):
            args = build_parser().parse_args(argv)
            return args.func(args) or EXIT_OK
    except CliError as e:
        print_error(str(e))
        return e.status
    except SystemExit as e:  # --help, --version
        return e.code if isinstance(e.code, int) else EXIT_OK
    except KeyboardInterrupt:
        print_error("interrupted")
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # the reader went away (``omnicam info x.yaml | head -1``)
        with contextlib.suppress(OSError):  # no second error when Python flushes stdout
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except MemoryError:
        print_error(
            "out of memory: the outputs asked for are too large for this machine; ask for "
            "smaller ones (--panorama / --perspective WxH, fewer views at once)"
        )
        return EXIT_FAILURE
    except Exception as e:  # a bug: still one line, unless asked for the traceback
        if os.environ.get("OMNICAM_DEBUG"):
            raise
        print_error(
            f"unexpected {type(e).__name__}: {one_line(e, 300)} "
            f"(set OMNICAM_DEBUG=1 for the traceback)"
        )
        return EXIT_FAILURE


if __name__ == "__main__":
    sys.exit(main())
