"""The first step of :func:`omnicam.calibration.calibrate`: its options validated, as one
record (:class:`ImageOptions`; a re-run is ``dataclasses.replace(options, ...)``), and the
image made grey once for the edge detectors (:func:`edge_image`)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from .._typing import ArrayLike
from .._validate import float_array, validate_D, validate_image_size, validate_K
from ..asphere import AsphericMirror
from ..images import check_image, to_gray
from ..mirror import HyperbolicMirror, Mirror
from . import selection

__all__ = ["ImageOptions", "as_pixels", "edge_image"]


def edge_image(image):
    """``image`` as the rim's and the reflection's edge detectors take it, made grey once.

    An 8-bit image's float grey on the 0-255 scale (:func:`omnicam.images.to_gray`): both
    detectors' scales follow from it exactly (its values are the colour conversion's own, and
    the contrast stretch of the rim starts from them). Anything else is returned as it is: an
    image of more bits (or of floats), whose two scales part before the colour conversion; an
    8-bit one so dark that its grey lies within 0..1 (which the 0-255 scale would read as a
    float image's 0..1); None, and what is not an image (the detectors say why).
    """
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8:
        return image
    try:
        image = check_image(image)
    except ValueError:
        return image
    grey = to_gray(image)
    return grey if float(grey.max()) > 1.0 else image


@dataclasses.dataclass(frozen=True)
class ImageOptions:
    """The arguments of one :func:`omnicam.calibration.calibrate` but the image, validated
    (:meth:`validated`): ``K`` and ``D`` as arrays, ``far_lines`` a list of ``(N_i, 2)``
    pixel arrays, ``image_size`` the image's when not given."""

    K: ArrayLike
    mirror: Mirror
    boundary_points: Any = None
    far_lines: Any = None
    D: ArrayLike | None = None
    image_size: tuple[int, int] | None = None
    refine: bool = True
    lens: Any = "auto"
    lens_r: float | None = None
    lens_z: float | None = None
    rim_hint: tuple[float, float, float] | None = None
    max_tilt_deg: float = 10.0
    max_offset_mm: float = 10.0
    check_plausibility: bool = True
    choose: int | None = None

    def validated(self, image) -> ImageOptions:
        """These options checked against ``image`` (``ValueError`` naming what to change)."""
        K = validate_K(self.K)
        D = validate_D(self.D)
        mirror = self.mirror
        if not isinstance(mirror, HyperbolicMirror | AsphericMirror):
            raise ValueError(
                "mirror must be a HyperbolicMirror or an AsphericMirror, got "
                f"{type(mirror).__name__}"
            )
        if image is None and self.boundary_points is None:
            raise ValueError(
                "give the image (the rim is detected) or boundary_points (pixels on the mirror rim)"
            )
        image_size = self.image_size
        if image_size is None and image is not None:
            shape = np.shape(image)
            if len(shape) >= 2:
                image_size = (int(shape[1]), int(shape[0]))
        image_size = validate_image_size(image_size)
        lines = selection.validate_far_lines(self.far_lines)
        return dataclasses.replace(self, K=K, D=D, image_size=image_size, far_lines=lines)


def as_pixels(points, name):
    """``(N, 2)`` float64 pixels from ``(N, 2)`` / ``(N, 1, 2)``; ``ValueError`` naming ``name``."""
    arr = float_array(points, name, "an (N, 2) or (N, 1, 2) array of pixels")
    if arr.ndim == 3 and arr.shape[1:] == (1, 2):
        arr = arr.reshape(-1, 2)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(
            f"{name} must be an (N, 2) or (N, 1, 2) array of pixels, got shape {arr.shape}"
        )
    return arr
