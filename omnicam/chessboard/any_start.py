"""The start of a rig whose mirror no hyperboloid describes: the generic central start.

Where Mei's unified model (:mod:`.central`) gives ``xi >= XI_NOT_HYPERBOLIC`` or fails, the
corners' central model is Scaramuzza's Taylor polynomial (:func:`.taylor.fit_taylor`), which
holds for any mirror of revolution seen from near its viewpoint;
:func:`.central_start.central_start` turns its directions into the aligned rig with an
even-asphere mirror that sees them: the conic with the fewest polynomial terms (at most
:data:`START_TERMS`) that fits the model's profile best (:func:`.profile.fit_convex_asphere`);
the adjustment's likelihood-ratio test may add one more (:mod:`.family`).
The focal length is not determined by a central model: the start takes the one that makes the
rim subtend :data:`.central_start.RIM_HALF_ANGLE_DEG` (or the ``K`` given), and the adjustment
frees ``f`` and the mirror's shape together.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .._validate import validate_K
from ..asphere import AsphericMirror
from ..calibration.plausibility import rim_radius_px
from ..camera import MisalignedCatadioptricCamera
from .central_start import CentralStart, central_start
from .taylor import TaylorFit, fit_taylor

__all__ = ["START_TERMS", "GenericStart", "aligned_camera", "generic_start"]

#: Most polynomial terms of the start's asphere. The outer profile beyond the boards' reach is
#: the Taylor model's extrapolation, which more terms would follow, not the mirror. A conic
#: alone does not do as a start: on KaidanOmni (k -1.08 from the profile) the adjustment runs
#: along the valley to f = 6270 px (0.46 px RMS against 0.29 with the profile's one term).
START_TERMS = 2


@dataclasses.dataclass(frozen=True)
class GenericStart:
    """The start camera (an aligned rig with an :class:`~omnicam.asphere.AsphericMirror`), the
    Taylor fit it came from, the profile's start (:class:`.central_start.CentralStart`) and the
    start's warnings."""

    camera: MisalignedCatadioptricCamera
    taylor: TaylorFit
    start: CentralStart
    warnings: tuple[str, ...]


def generic_start(
    views, obj, image_size, rim_fit, rim_radius, K=None, taylor: TaylorFit | None = None
) -> GenericStart:
    """The aligned aspheric rig the corners' Taylor model implies (module docstring).

    ``views``: each view's ``(N, 2)`` corners (3 or more); ``rim_fit``: the rim's ellipse
    (its mean radius is the rim's image); ``rim_radius``: the scale; ``K``: a given camera
    matrix (its focal length fixes ``f``, its principal point is kept); ``taylor``: the
    views' Taylor model, if fitted already. ``ValueError`` when the Taylor model makes no
    mirror."""
    if taylor is None:
        taylor = fit_taylor(views, obj, image_size)
    f = None
    if K is not None:
        K = validate_K(K)
        f = math.sqrt(K[0, 0] * K[1, 1])
    rho_rim = rim_radius_px(rim_fit)
    start = central_start(
        taylor.directions, taylor.centre, rho_rim, float(rim_radius), f=f, max_terms=START_TERMS
    )
    mirror = AsphericMirror(**start.mirror_kwargs())
    K0 = start.K if K is None else K
    camera = MisalignedCatadioptricCamera(K0, mirror, start.rvec, start.tvec, image_size=image_size)
    warns = (
        f"the mirror is started as an even asphere from the corners' Taylor model (RMS "
        f"{taylor.rms:.3f} px, degree {taylor.degree}): R = {mirror.R:.3f}, k = {mirror.k:.3f}, "
        f"{len(mirror.alpha)} polynomial term(s); its profile beyond the boards' reach is the "
        f"model's extrapolation, and f ({start.f:.1f} px) is "
        + ("the K given's" if start.f_given else "assumed (the rim at 20 deg), then fitted"),
    )
    return GenericStart(camera, taylor, start, warns)


def aligned_camera(K, mirror, rim_fit, image_size) -> MisalignedCatadioptricCamera:
    """The aligned rig of a given mirror (any family) and ``K`` whose image of the rim has the
    rim ellipse's mean radius: the camera on the axis at ``z_rim - f rim_radius / rho_rim``
    in the mirror frame."""
    K = validate_K(K)
    f = math.sqrt(K[0, 0] * K[1, 1])
    z_cam = mirror.z_rim - f * mirror.rim_radius / rim_radius_px(rim_fit)
    return MisalignedCatadioptricCamera(
        K, mirror, np.zeros(3), np.array([0.0, 0.0, -z_cam]), image_size=image_size
    )
