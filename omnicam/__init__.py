"""omnicam: calibrate and unwarp misaligned hyperbolic-mirror catadioptric cameras.

Public names only; the contract is README.md and ``docs/conventions.md``.
Every name loads its module on first use, so ``import omnicam`` stays fast and has no side
effect.
"""

from importlib import import_module

__version__ = "0.3.0"

# public name -> module that defines it (loaded lazily, PEP 562)
_LAZY = {
    "MisalignedHyperbolicCamera": "omnicam.hyperbolic_camera",
    "MisalignedCatadioptricCamera": "omnicam.camera",
    "calibrate": "omnicam.calibration",
    "recalibrate": "omnicam.calibration",
    "calibrate_pattern": "omnicam.chessboard.calibrate",
    "load_camera": "omnicam.formats.calibration_file",
    "save_camera": "omnicam.formats.calibration_file",
    "HyperbolicMirror": "omnicam.mirror",
    "AsphericMirror": "omnicam.asphere",
    "detect_rim": "omnicam.calibration.rim",
    "RimFit": "omnicam.calibration.rim",
    "CalibrationReport": "omnicam.calibration",
    "EstimationError": "omnicam.calibration.errors",
    "calibrate_intrinsics": "omnicam.chessboard.intrinsics",
    "find_pattern": "omnicam.chessboard.detect",
    "detect_pattern": "omnicam.chessboard.detect",
    "board_size_in": "omnicam.chessboard.board_size",
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
    "read_intrinsics": "omnicam.formats.intrinsics",
    "read_central_model": "omnicam.formats.intrinsics",
    "read_verdict": "omnicam.formats.calibration_file",
    "Verdict": "omnicam.formats.verdict",
    "write_intrinsics": "omnicam.formats.intrinsics",
    "read_far_lines": "omnicam.formats.point_files",
    "write_far_lines": "omnicam.formats.point_files",
}

__all__ = list(_LAZY)


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
