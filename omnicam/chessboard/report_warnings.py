"""What a chessboard calibration's report warns of: one policy per function, each readable alone.

Every policy takes the facts of the fit (:class:`FitFacts`) and returns its warning (a
sentence that says what to do) or None; :func:`report_warnings` asks them in the report's
order.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, cast

import numpy as np

from ..asphere import AsphericMirror
from ..calibration.chen import rim_conic
from ..calibration.plausibility import check_plausibility
from ..camera import MisalignedCatadioptricCamera
from ..mirror import HyperbolicMirror
from .report import (
    ONE_SIDED,  # the warning that views cannot tell the principal point from the tilt
)
from .shape_params import family
from .steps import XI_NOT_HYPERBOLIC

__all__ = ["ONE_SIDED", "POLICIES", "SHAPE_WEAK", "FitFacts", "report_warnings"]

#: A relative standard deviation of ``a``, ``b`` (or of ``fx``) above this: not determined.
SHAPE_WEAK = 0.01
#: Fewer views than this: too few for a reliable ``K`` and posture.
FEW_VIEWS = 6
#: A standard deviation of the principal point above this (px): weakly determined.
PRINCIPAL_POINT_WEAK_PX = 1.0


@dataclasses.dataclass(frozen=True)
class FitFacts:
    """What the policies look at: the calibrated ``camera``, the a posteriori ``std`` of its
    parameters, the rays' uncertainty ``ray_deg`` (median, worst; deg), the corners' ``rms``
    (px), the number of views used, the boards' centres (mirror frame), whether the solver
    converged (and its message), whether the shape was held unknown or estimated, the
    central fit (or None), the image size and the plausibility findings (:func:`implausible`)."""

    camera: MisalignedCatadioptricCamera
    std: dict
    ray_deg: tuple[float, float]
    rms: float
    n_views: int
    board_centres: np.ndarray
    converged: bool
    solver_message: str
    held_shape: bool
    estimated_shape: bool
    central: Any
    image_size: tuple[int, int] | None
    plausibility: tuple = ()

    @property
    def rays(self) -> str:
        """How well the viewing directions are known, as the warnings say it."""
        median, worst = self.ray_deg
        return (
            f"the viewing directions are known to {median:.3f} deg (median over the mirror's "
            f"image, worst {worst:.3f} deg)"
        )


def few_views(f: FitFacts) -> str | None:
    if f.n_views < FEW_VIEWS:
        return (
            f"only {f.n_views} views: take 10 or more, spread around the mirror, for a "
            f"reliable K and posture"
        )
    return None


def _azimuth_gap_deg(centres):
    az = np.sort(np.degrees(np.arctan2(centres[:, 1], centres[:, 0])))
    gaps = np.diff(np.append(az, az[0] + 360.0))
    return float(gaps.max())


def one_sided(f: FitFacts) -> str | None:
    """Boards on one side only: a turn of the camera and a shift of the principal point look
    alike from one side."""
    if _azimuth_gap_deg(f.board_centres) > 180.0:
        return (
            f"{ONE_SIDED}: add views on the other side, or the principal point and the tilt "
            "are poorly separated"
        )
    return None


def principal_point_weak(f: FitFacts) -> str | None:
    std = f.std
    if max(std["cx"], std["cy"]) > PRINCIPAL_POINT_WEAK_PX:
        return (
            f"the principal point is weakly determined (std {std['cx']:.2f}, "
            f"{std['cy']:.2f} px): add views at other azimuths and elevations"
        )
    return None


def not_converged(f: FitFacts) -> str | None:
    if not f.converged:
        return f"the adjustment did not converge: {f.solver_message}"
    return None


def _hyperboloid(f: FitFacts) -> HyperbolicMirror:
    """The fitted mirror, a hyperboloid: the shape's policies speak of its ``a, b``."""
    return cast(HyperbolicMirror, f.camera.mirror)


def held_shape(f: FitFacts) -> str | None:
    """The mirror unknown and its shape held from the central fit: its uncertainty is in the
    stated ones."""
    if not f.held_shape or not isinstance(f.camera.mirror, HyperbolicMirror):
        return None
    m, std = _hyperboloid(f), f.std
    return (
        f"the mirror's shape is the central fit's (a = {m.a:.3f} +- {std['a']:.3f}, "
        f"b = {m.b:.3f} +- {std['b']:.3f}), held, and its uncertainty is in the stated ones of "
        f"K and of the rays; refine_mirror_shape=True (--refine-mirror-shape) estimates it, at "
        f"several times the cost"
    )


def estimated_shape(f: FitFacts) -> str | None:
    """The mirror's shape estimated: how well, and that the data sheet's is better."""
    if not f.estimated_shape:
        return None
    if not isinstance(f.camera.mirror, HyperbolicMirror):
        return _estimated_asphere(f)
    m, std = _hyperboloid(f), f.std
    ra, rb = std["a"] / m.a, std["b"] / m.b
    weak = max(ra, rb) > SHAPE_WEAK
    return (
        f"the mirror's a, b were estimated (a = {m.a:.3f} +- {std['a']:.3f} "
        f"({100 * ra:.1f} %), b = {m.b:.3f} +- {std['b']:.3f} ({100 * rb:.1f} %))"
        + (
            ": NOT determined by these data (they trade against the focal length and the "
            "camera's distance to the mirror, which only the rig's small non-centrality "
            f"tells apart), but {f.rays}; use the data sheet's values for distances"
            if weak
            else "; they trade against the focal length and the camera's distance to the "
            "mirror: prefer the data sheet's values when there is one"
        )
    )


def _estimated_asphere(f: FitFacts) -> str:
    """An even asphere's shape estimated: its parameters and what the data determine."""
    m, std = cast(AsphericMirror, f.camera.mirror), f.std
    terms = ", ".join(
        f"alpha{2 * j + 4} = {a:.4f} +- {std.get(f'alpha{2 * j + 4}', float('nan')):.4f}"
        for j, a in enumerate(m.alpha)
    )
    rR = std["R"] / m.R
    return (
        f"the mirror's shape was estimated as an even asphere ({family(m)}: R = {m.R:.3f} +- "
        f"{std['R']:.3f} ({100 * rR:.1f} %), k = {m.k:.3f} +- {std['k']:.3f}"
        + (f", {terms}" if terms else "")
        + f"); the shape relative to the rim (k and the terms, R / rim_radius) is what the "
        f"boards determine, the focal length and the mirror's size only as their ratio "
        f"without rim_radius (--rim-radius) and the camera's distance with the focal length; "
        f"{f.rays} (the single-image route's plausibility checks, a hyperboloid's, are not run)"
    )


def focal_length_weak(f: FitFacts) -> str | None:
    fx = f.camera.K[0, 0]
    if f.std["fx"] > SHAPE_WEAK * fx:
        return (
            f"the focal length is weakly determined (fx = {fx:.1f} +- {f.std['fx']:.1f} px: it "
            f"trades against the mirror's shape and distance), but {f.rays}"
        )
    return None


def not_a_hyperboloid(f: FitFacts) -> str | None:
    """The central fit says the mirror is no hyperboloid, or fits the corners far better than
    this rig does."""
    central = f.central
    if central is None or not isinstance(f.camera.mirror, HyperbolicMirror):
        return None  # (an asphere: the start's warning says why Mei's model was set aside)
    if central.xi >= XI_NOT_HYPERBOLIC:
        return (
            f"the central fit of the corners gives xi = {central.xi:.2f}, which no hyperboloid "
            f"gives (xi < 1; a paraboloid 1, a sphere more): the mirror may not be a "
            f"hyperboloid, which omnicam does not model"
        )
    if f.rms > 2.0 * central.rms + 0.1:
        return (
            f"the corners fit this rig to {f.rms:.3f} px RMS, far above the central fit's "
            f"{central.rms:.3f} px: the mirror may not be a hyperboloid (a sphere, a "
            f"paraboloid, a cone), or the start was far off"
        )
    return None


def implausible(camera: MisalignedCatadioptricCamera, image_size: Any) -> tuple:
    """The single-image route's plausibility checks of the camera, with the same limits
    (:func:`omnicam.calibration.plausibility.check_plausibility`): the findings."""
    conic = rim_conic(camera.K, camera.R, camera.tvec, camera.mirror)
    return tuple(check_plausibility(camera, conic, image_size))


def _implausible(f: FitFacts) -> list[str]:
    """The plausibility findings' warnings (:func:`implausible`, found once by the report
    step)."""
    return [str(w) for w in f.plausibility]


#: The policies, in the order the report gives their warnings.
POLICIES: tuple[Callable[[FitFacts], str | None], ...] = (
    few_views,
    one_sided,
    principal_point_weak,
    not_converged,
    held_shape,
    estimated_shape,
    focal_length_weak,
    not_a_hyperboloid,
)


def report_warnings(facts: FitFacts) -> list[str]:
    """Every policy's warning, in order, then the plausibility checks'."""
    found = (policy(facts) for policy in POLICIES)
    return [w for w in found if w is not None] + _implausible(facts)
