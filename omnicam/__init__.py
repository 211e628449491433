"""omnicam: calibrate and unwarp misaligned hyperbolic-mirror catadioptric cameras.

Public names only; the contract is README.md and ``shared/reference/conventions.md``.
Modules that pull in scikit-image or build views load on first use, so ``import omnicam``
stays fast.
"""
from importlib import import_module

from .camera import MisalignedHyperbolicCamera
from .mirror import HyperbolicMirror

__version__ = "0.1.0"

# public name -> module that defines it (loaded lazily, PEP 562)
_LAZY = {
    "detect_rim": "omnicam.calibration.rim",
    "RimFit": "omnicam.calibration.rim",
    "CalibrationReport": "omnicam.calibration",
    "calibrate_intrinsics": "omnicam.calibration.intrinsics",
    "Unwarper": "omnicam.stream",
    "rotation_from_ypr": "omnicam.views",
    "K_from_fov": "omnicam.views",
    "synthetic": "omnicam.synthetic",
    "samples": "omnicam.samples",
}

__all__ = ["HyperbolicMirror", "MisalignedHyperbolicCamera", *_LAZY]


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
