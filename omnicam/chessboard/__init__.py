"""Calibration from chessboards: the camera alone, and the whole rig through the mirror.

- :mod:`.intrinsics`: ``calibrate_intrinsics``, the pinhole ``K, D`` from boards seen without
  the mirror (``cv2.calibrateCamera``);
- :mod:`.detect`: ``detect_pattern`` / ``find_pattern``, a board's corners in an image of the
  mirror (OpenCV's detectors on the raw image, then unwarped views);
- :mod:`.board_size`: ``board_size_in``, the inner corners of the whole board in an image, and
  the size to give when the one given is a sub-board of it or counts its squares;
- :mod:`.central`: the central start, ``cv2.omnidir.calibrate`` and the hyperbolic rig it
  describes;
- :mod:`.board_pose`: a board's object points and its pose from its corners' rays;
- :mod:`.adjustment`: the non-central bundle adjustment, its solver and uncertainty;
- :mod:`.calibrate`: ``calibrate_pattern``, the pipeline as a composition of named steps:
  :mod:`.steps` (options, images, boards, rim, reflection, start) and :mod:`.fit_steps`
  (corners, adjustment, detection rounds, the held shape, the report), whose warnings are
  :mod:`.report_warnings`' policies;
- :mod:`.report`: ``PatternReport``;
- :mod:`.heldout`: what a calibration predicts on views it did not fit.

It builds on the single-image route (:mod:`omnicam.calibration`: the rim, the camera's
reflection, Chen's posture, the plausibility checks), never the other way round.
"""

from .adjustment import DIST_MODELS, pattern_uncertainty
from .board_size import board_size_in
from .calibrate import calibrate_pattern
from .detect import detect_pattern, find_pattern
from .heldout import HeldOut
from .intrinsics import calibrate_intrinsics
from .report import PatternReport

__all__ = [
    "DIST_MODELS",
    "HeldOut",
    "PatternReport",
    "board_size_in",
    "calibrate_intrinsics",
    "calibrate_pattern",
    "detect_pattern",
    "find_pattern",
    "pattern_uncertainty",
]
