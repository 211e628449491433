"""omnicam: calibrate and unwarp misaligned hyperbolic-mirror catadioptric cameras.

Public names only; the contract is README.md and ``docs/conventions.md``.
Modules that pull in scikit-image or build views load on first use, so ``import omnicam``
stays fast.
"""

import os
import sys
from importlib import import_module

if os.path.basename(sys.argv[0] if sys.argv else "") in ("omnicam", "omnicam.exe"):
    # the console script: Ctrl-C while the libraries load is one line and exit 130 (not a
    # KeyboardInterrupt traceback); omnicam.cli.main puts Python's own handler back
    import signal

    def _interrupted_while_loading(signum, frame):
        os.write(2, b"omnicam: error: interrupted\n")
        os._exit(130)

    signal.signal(signal.SIGINT, _interrupted_while_loading)

from .camera import MisalignedHyperbolicCamera
from .mirror import HyperbolicMirror

__version__ = "0.3.0"

# public name -> module that defines it (loaded lazily, PEP 562)
_LAZY = {
    "detect_rim": "omnicam.calibration.rim",
    "RimFit": "omnicam.calibration.rim",
    "CalibrationReport": "omnicam.calibration",
    "EstimationError": "omnicam.calibration.errors",
    "calibrate_intrinsics": "omnicam.chessboard.intrinsics",
    "find_pattern": "omnicam.chessboard.detect",
    "detect_pattern": "omnicam.chessboard.detect",
    "PatternReport": "omnicam.chessboard.report",
    "Unwarper": "omnicam.stream",
    "rotation_from_ypr": "omnicam.views",
    "K_from_fov": "omnicam.views",
    "PanoramaView": "omnicam.views",
    "PerspectiveView": "omnicam.views",
    "visible_elevation_range": "omnicam.views",
    "synthetic": "omnicam.synthetic",
    "samples": "omnicam.samples",
    "read_intrinsics": "omnicam.io",
    "write_intrinsics": "omnicam.io",
    "read_far_lines": "omnicam.io",
    "write_far_lines": "omnicam.io",
}

# K, D and the posture from chessboards seen through the mirror (builds this camera class)
calibrate_pattern = MisalignedHyperbolicCamera.calibrate_pattern

__all__ = ["HyperbolicMirror", "MisalignedHyperbolicCamera", "calibrate_pattern", *_LAZY]


def __getattr__(name):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'omnicam' has no attribute {name!r}")
    mod = import_module(module)
    value = mod if name == module.rsplit(".", 1)[-1] else getattr(mod, name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(__all__)
