"""omnicam: calibrate and unwarp misaligned hyperbolic-mirror catadioptric cameras.

Public names only; the contract is README.md and ``docs/conventions.md``.
Every name loads its module on first use, so ``import omnicam`` stays fast and has no side
effect.
"""

from importlib import import_module

__version__ = "0.3.0"

# public name -> module that defines it (loaded lazily, PEP 562)
_LAZY = {
    "MisalignedHyperbolicCamera": "omnicam.camera",
    "HyperbolicMirror": "omnicam.mirror",
    "AsphericMirror": "omnicam.asphere",
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
    "default_elevation_range": "omnicam.views",
    "synthetic": "omnicam.synthetic",
    "samples": "omnicam.samples",
    "read_intrinsics": "omnicam.formats.omnicam_files",
    "read_central_model": "omnicam.formats.omnicam_files",
    "read_verdict": "omnicam.formats.omnicam_files",
    "Verdict": "omnicam.formats.omnicam_files",
    "write_intrinsics": "omnicam.formats.omnicam_files",
    "read_far_lines": "omnicam.formats.omnicam_files",
    "write_far_lines": "omnicam.formats.omnicam_files",
}

__all__ = ["calibrate_pattern", *_LAZY]


def __getattr__(name):
    if name == "calibrate_pattern":  # chessboards through the mirror (builds the camera class)
        value = __getattr__("MisalignedHyperbolicCamera").calibrate_pattern
    else:
        module = _LAZY.get(name)
        if module is None:
            raise AttributeError(f"module 'omnicam' has no attribute {name!r}")
        mod = import_module(module)
        value = mod if name == module.rsplit(".", 1)[-1] else getattr(mod, name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(__all__)
