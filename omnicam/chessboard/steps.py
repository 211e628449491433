"""The first steps of :func:`.calibrate.calibrate_pattern`, each returning a typed result.

options (:class:`PatternOptions`, validated) -> images (:func:`load_step` -> :class:`Inputs`,
each image made grey once) -> boards on the raw images (:func:`raw_detection_step` ->
:class:`Boards`) -> rim (:func:`rim_step` -> :class:`RimStep`) -> the camera's reflection
(:func:`reflection_step` -> :class:`LensStep`) -> the start (:func:`start_step` ->
:class:`StartStep`: the central fit without a mirror, the posture by Chen's method). The
corners, the adjustment rounds and the report follow in :mod:`.fit_steps`.
"""

from __future__ import annotations

import dataclasses
import math
import os
from typing import Any

import cv2
import numpy as np

from .._typing import FloatArray
from .._validate import float_array, positive_number, validate_D, validate_image_size, validate_K
from ..asphere import AsphericMirror
from ..calibration import rim_posture
from ..calibration.ellipse import conic_distance
from ..calibration.inputs import edge_image
from ..calibration.plausibility import focal_from_rim, rim_radius_px
from ..calibration.reflection import detect_reflection, fit_circle
from ..calibration.rim import detect_rim, fit_rim
from ..calibration.steps import BODY_MAX_RMS_PX
from ..camera import MisalignedCatadioptricCamera
from ..images import read_image
from ..mirror import HyperbolicMirror
from ..raytrace import normalize
from .adjustment import DIST_MODELS, n_coefficients
from .any_start import aligned_camera, generic_start
from .board_pose import object_points
from .board_size import raw_boards
from .central import NOMINAL_RIM_RADIUS, fit_central, hyperbolic_start, pinhole_D_from_unified
from .detect import detect_pattern
from .intrinsics import check_pattern_size, gray8

__all__ = [
    "CENTRAL_RMS_MAX",
    "LENS_PLANE_UNKNOWN",
    "RADIAL_START_GAIN",
    "XI_NOT_HYPERBOLIC",
    "XI_START_MAX",
    "Boards",
    "GreyImage",
    "Inputs",
    "LensStep",
    "PatternOptions",
    "RimStep",
    "StartStep",
    "load_step",
    "pooled_reflection",
    "raw_detection_step",
    "redetect",
    "reflection_step",
    "rim_step",
    "start_step",
]

#: Images whose rims are pooled (:func:`_detected_rim`): the rig is rigid, so every image shows
#: the same rim, and one image's partial rim (cut off by the frame, a holder's edge joining it)
#: can be off by several px. On OCamCalib's MiniOmni the rims of single images differ by up to
#: 11 px in centre and their 2 % eccentricities point every way; the adjustment took one
#: image's for a 9 deg tilt and, the mirror near a sphere, followed it off to a camera 40 mm off
#: the axis. Pooled, its centre lies 1.7 px from the corners' Taylor centre.
RIM_POOL_IMAGES = 6
#: How far (a fraction of the first rim's mean radius) another image's rim may differ from the
#: first's in size and centre to be pooled with it.
_RIM_POOL_SIZE = 0.05
#: Detections of the camera's reflection farther than this (px, centre or radius) from the
#: median of all images' are not pooled.
_LENS_AGREE_PX = 1.0
#: The central fit's ``xi`` above which the mirror is taken for no hyperboloid (a misaligned
#: hyperboloid's fit, with the pinhole's distortion fixed, passes 1 by a few per cent at most;
#: a paraboloid's gives 1.5, a sphere's 2 and more, on the hostile renders' rigs).
XI_NOT_HYPERBOLIC = 1.1
#: The hyperbolic start's ``xi`` when the central fit gives 1 to XI_NOT_HYPERBOLIC.
XI_START_MAX = 0.97
#: The central fit with ``k1, k2`` free starts the rig when its RMS is below this times the
#: distortion-free fit's: a wide-angle lens's distortion, which the latter takes into its
#: aspect and ``xi``, not the trade of ``k1`` with ``xi`` that lowers the RMS a little on any
#: misaligned rig (``benchmarks/bench_chessboard_hostile.py`` prints both fits' RMS).
RADIAL_START_GAIN = 0.5
#: A central fit with ``k1, k2`` free whose RMS (px) is above this fits nothing (cv2.omnidir
#: may return one of 1e9 px): it starts the rig only below it, when the fit without
#: distortion failed.
CENTRAL_RMS_MAX = 5.0
#: Why the camera's reflection joins the adjustment only with its plane known.
LENS_PLANE_UNKNOWN = (
    "not used: its plane is unknown (give lens_z, or --lens-z on the command line: the front "
    "edge's distance from the camera centre, to use it); with z free it trades against the "
    "mirror's tilt, and an outline off the optical axis biases the posture without a trace in "
    "the residuals"
)


# -- the options -------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class PatternOptions:
    """The options of one :func:`.calibrate.calibrate_pattern`, validated
    (:meth:`validated`): a re-run (the held-out check's folds) is
    ``dataclasses.replace(options, ...)``. The arguments of the same names, but:
    ``pattern_size`` is ``(cols, rows)``, ``square`` a float, ``D`` padded to ``n_d``
    coefficients, ``free_d`` and ``n_d`` what ``dist_model`` frees, ``refine_mirror_shape`` a
    bool, ``image_size`` the images' when not given (:func:`load_step`)."""

    pattern_size: tuple[int, int]
    square: float
    mirror: HyperbolicMirror | AsphericMirror | None
    K: Any
    D: FloatArray | None
    image_size: tuple[int, int] | None
    refine_mirror_shape: bool
    dist_model: str
    rim_radius: float | None
    boundary_points: Any
    fit_skew: bool
    drop_outlier_views: bool
    outlier_factor: float
    outlier_min_px: float
    f_scale: float
    lens: Any
    lens_z: float | None
    heldout: int
    free_d: tuple = ()
    n_d: int = 0

    def validated(self) -> PatternOptions:
        """These options checked (``ValueError`` naming what to change), ``D`` padded."""
        cols, rows = check_pattern_size(self.pattern_size)
        square = positive_number(self.square, "square_size")
        mirror = self.mirror
        if mirror is not None and not isinstance(mirror, (HyperbolicMirror, AsphericMirror)):
            raise ValueError(
                f"mirror must be a HyperbolicMirror, an AsphericMirror or None (unknown), got "
                f"{type(mirror).__name__}"
            )
        dist_model = self.dist_model
        if dist_model not in DIST_MODELS and dist_model != "auto":
            raise ValueError(
                f"dist_model must be one of {sorted(DIST_MODELS)} or 'auto', got {dist_model!r}"
            )
        D = validate_D(self.D)
        if D is not None and D.size not in (4, 5, 8):
            raise ValueError(
                f"D must have 4, 5 or 8 coefficients (k1, k2, p1, p2[, k3[, k4, k5, k6]]) for "
                f"pattern calibration, got {D.size}"
            )
        # "auto" is started as its simplest candidate (lens_model.AUTO_CANDIDATES), each
        # candidate's D padded to its own length by the adjustment
        free_d = DIST_MODELS["k1k2" if dist_model == "auto" else dist_model]
        n_d = n_coefficients(free_d, None if D is None else D.size)
        if D is not None and D.size < n_d:
            D = np.concatenate([D, np.zeros(n_d - D.size)])
        return dataclasses.replace(
            self,
            pattern_size=(cols, rows),
            square=square,
            D=D,
            free_d=free_d,
            n_d=n_d,
            # held (an unknown one's uncertainty still counted)
            refine_mirror_shape=bool(self.refine_mirror_shape),
        )


# -- 0. the images, made grey once --------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class GreyImage:
    """One image as its detectors take it, converted once for the whole calibration:
    ``corners``, 8-bit grey for OpenCV's corner detectors (:func:`.intrinsics.gray8`), used by
    every round of detection; ``edges``, for the rim's and the reflection's edge detectors
    (:func:`omnicam.calibration.inputs.edge_image`)."""

    corners: np.ndarray
    edges: np.ndarray


def _grey_image(image, index) -> GreyImage:
    return GreyImage(gray8(image, index), edge_image(image))


@dataclasses.dataclass(frozen=True)
class Inputs:
    """The images (:class:`GreyImage`, empty without images), the corners given (a list, one
    entry or None per image; None: detect them), the image size they share and the names of
    the images given as files ``{index: file name}``."""

    greys: tuple[GreyImage, ...]
    image_points: list | None
    image_size: tuple[int, int] | None
    names: dict


def _names(images):
    """``{index: file name}`` of the images given as paths."""
    return {
        i: os.path.basename(os.fspath(im))
        for i, im in enumerate(images if images is not None else [])
        if isinstance(im, (str, os.PathLike))
    }


def _load_image(image, index):
    if isinstance(image, (str, os.PathLike)):
        return read_image(
            image, cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION, f"images[{index}]"
        )
    if not isinstance(image, np.ndarray) or image.ndim not in (2, 3) or image.size == 0:
        raise ValueError(
            f"images[{index}] must be an image array (H, W) or (H, W, C) or a file "
            f"path, got {type(image).__name__}"
        )
    return image


def load_step(images, image_points, image_size) -> Inputs:
    """0. The images read (paths) and made grey once, ``image_points`` as a list matching
    them, and the one ``image_size`` they share (:class:`Inputs`)."""
    names = _names(images)
    if images is None:
        images = []
    elif isinstance(images, (str, os.PathLike)) or (
        isinstance(images, np.ndarray)
        and images.ndim in (2, 3)
        and images.dtype != object
        and (images.ndim == 2 or images.shape[2] in (1, 3, 4))
    ):
        images = [images]
    images = [_load_image(im, i) for i, im in enumerate(images)]
    if image_points is not None:
        image_points = list(image_points)
        if images and len(images) != len(image_points):
            raise ValueError(
                f"image_points has {len(image_points)} entries for {len(images)} "
                f"images: give one (or None) per image"
            )
    elif not images:
        raise ValueError(
            "give images (corners and rim are detected) or image_points with "
            "boundary_points and image_size"
        )
    if image_size is None and images:
        image_size = (images[0].shape[1], images[0].shape[0])
    image_size = validate_image_size(image_size)
    for i, im in enumerate(images):
        if (im.shape[1], im.shape[0]) != image_size:
            raise ValueError(
                f"images[{i}] is {im.shape[1]}x{im.shape[0]}, expected "
                f"{image_size[0]}x{image_size[1]}: all images must come from the "
                f"same camera mode"
            )
    greys = tuple(_grey_image(im, i) for i, im in enumerate(images))
    return Inputs(greys, image_points, image_size, names)


# -- 1. the boards on the raw images ------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Boards:
    """Every image's corners (None where no board is known yet) and how each was found
    (``"given"``, a detector's name, ``"views"``, ``"views (fitted camera)"``, or None)."""

    points: tuple
    found_by: tuple

    def missing(self) -> list[int]:
        """The images where no board is known."""
        return [i for i, p in enumerate(self.points) if p is None and self.found_by[i] is None]

    def with_found(self, new: dict, how: str) -> Boards:
        """These boards and ``new`` ``{index: corners}``, found by ``how``."""
        points, found_by = list(self.points), list(self.found_by)
        for i, corners in new.items():
            points[i], found_by[i] = corners, how
        return Boards(tuple(points), tuple(found_by))


def raw_detection_step(inputs: Inputs, pattern_size, progress=None) -> Boards:
    """1. The corners given, or every image's board by OpenCV's detectors on the raw image,
    which need no camera: grids that are no chessboard's dropped with a warning, and
    ``ValueError`` naming the size to give when most images show a board of another size
    (:func:`.board_size.raw_boards`); ``progress(index, text)`` hears of each image."""
    if inputs.image_points is not None:
        points = inputs.image_points
        return Boards(tuple(points), tuple("given" if p is not None else None for p in points))
    found, found_by = raw_boards([g.corners for g in inputs.greys], pattern_size, progress)
    return Boards(tuple(found), tuple(found_by))


def redetect(greys, missing, pattern_size, camera, progress=None) -> dict:
    """``{index: corners}`` of the boards that the views of ``camera`` find in the images
    ``missing``; ``progress(index, text)`` hears of each."""
    new = {}
    for i in missing:
        det = detect_pattern(greys[i].corners, pattern_size, camera, methods=("views",))
        if det is not None:
            new[i] = det.corners
        if progress is not None:
            progress(i, "board (views)" if det is not None else "no board in the views either")
    return new


# -- 2. the rim ---------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class RimStep:
    """The rim's ellipse (:class:`.rim.RimFit`), the rim pixels seen (its inliers), the image
    it was found in and the warnings (a rim rejected, corners outside it)."""

    fit: Any
    seen: FloatArray
    image: int
    warnings: tuple[str, ...]


def _corners_outside(rim_fit, corners):
    """How many of the corners lie outside the rim's ellipse by more than 1 px."""
    if not corners:
        return 0
    return int((conic_distance(rim_fit.conic, np.concatenate(corners)) > 1.0).sum())


def _given_rim(boundary_points, corners) -> RimStep:
    rim_seen = float_array(boundary_points, "boundary_points", "pixels on the rim, (M, 2)").reshape(
        -1, 2
    )
    if len(rim_seen) < 6 or not np.isfinite(rim_seen).all():
        raise ValueError("boundary_points must be at least 6 finite pixels on the rim")
    rim_fit = fit_rim(rim_seen)
    rim_seen = rim_seen[np.asarray(rim_fit.inliers, bool)]
    warns = []
    n_out = _corners_outside(rim_fit, corners)
    if n_out:
        warns.append(
            f"{n_out} corner(s) lie outside the rim of the boundary_points given (semi-axes "
            f"{rim_fit.axes[0]:.1f}, {rim_fit.axes[1]:.1f} px): are they the mirror's rim?"
        )
    return RimStep(rim_fit, rim_seen, 0, tuple(warns))


def _image_rim(grey, i, corners, warns, errors):
    """The rim found in one image that leaves no corner outside (a larger one sought where the
    first does, :func:`_detected_rim`), or None; what was rejected is said in ``warns`` and
    ``errors``."""
    try:
        found = detect_rim(grey.edges)
    except ValueError as e:
        errors.append(f"images[{i}]: {e}")
        return None
    n_out = _corners_outside(found, corners)
    if not n_out:
        return found
    need = float(np.max(np.linalg.norm(np.concatenate(corners) - found.center, axis=1)))
    what = (
        f"the rim found in image {i} (centre {found.center[0]:.1f}, {found.center[1]:.1f}, "
        f"semi-axes {found.axes[0]:.1f}, {found.axes[1]:.1f} px) leaves {n_out} corner(s) "
        f"outside: rejected"
    )
    try:
        larger = detect_rim(grey.edges, expected=(need, 2.0 * need))
    except ValueError:
        larger = None
    if larger is None or _corners_outside(larger, corners):
        errors.append(f"images[{i}]: {what}")
        warns.append(what)
        return None
    warns.append(
        f"{what}; the rim taken has semi-axes {larger.axes[0]:.1f}, {larger.axes[1]:.1f} px"
    )
    return larger


def _same_rim(grey, first, corners):
    """The rim of size ``first``'s (its mean radius within :data:`_RIM_POOL_SIZE`) found in
    another image, or None where none is, or where it leaves corners outside or its centre lies
    farther than that fraction of the radius from ``first``'s."""
    r0 = rim_radius_px(first)
    try:
        rim = detect_rim(
            grey.edges, expected=((1.0 - _RIM_POOL_SIZE) * r0, (1.0 + _RIM_POOL_SIZE) * r0)
        )
    except ValueError:
        return None
    if np.linalg.norm(rim.center - first.center) > _RIM_POOL_SIZE * r0 or _corners_outside(
        rim, corners
    ):
        return None
    return rim


def _pooled_rim(found, corners):
    """The ellipse of the rim points of several images ``found`` (:class:`RimFit` each) pooled
    (:func:`omnicam.calibration.rim.fit_rim`: RANSAC, then the geometric fit) and its inliers,
    or the first image's where the pooled ellipse leaves a corner outside."""
    pts = np.concatenate([np.asarray(f.points, np.float64) for f in found])
    pooled = fit_rim(pts)
    if _corners_outside(pooled, corners):
        return found[0], np.asarray(found[0].points, np.float64)
    return pooled, pts[np.asarray(pooled.inliers, bool)]


def _detected_rim(greys, corners) -> RimStep:
    """The rim of the first image that shows one (a rim that leaves corners outside rejected, a
    larger one sought, :func:`_image_rim`), pooled with the rims of its size found in the next
    images (:func:`_same_rim`), up to :data:`RIM_POOL_IMAGES` in all (:func:`_pooled_rim`)."""
    warns: list[str] = []
    errors: list[str] = []
    for i, grey in enumerate(greys):
        first = _image_rim(grey, i, corners, warns, errors)
        if first is not None:
            break
    else:
        raise ValueError(
            "the mirror rim was not found in any image (" + "; ".join(errors[:2]) + "); give "
            "boundary_points"
        )
    found = [first]
    for grey in greys[i + 1 :]:
        if len(found) == RIM_POOL_IMAGES:
            break
        rim = _same_rim(grey, first, corners)
        if rim is not None:
            found.append(rim)
    if len(found) == 1:
        return RimStep(first, np.asarray(first.points, np.float64), i, tuple(warns))
    fit, seen = _pooled_rim(found, corners)
    return RimStep(fit, seen, i, tuple(warns))


def rim_step(greys, boundary_points, image_size, image_points=None) -> RimStep:
    """2. The rim from the points, or from the first image that shows it pooled with the rims
    of its size in the next images (:func:`_detected_rim`, :data:`RIM_POOL_IMAGES`). Every
    corner found must lie inside the mirror: a rim that leaves corners outside (an inner edge
    of the mirror's image, a reflection) is rejected and a larger one sought
    (:func:`.rim.detect_rim` with the size the corners need), in that image and the next; the
    warnings say which was rejected."""
    corners = [
        np.asarray(p, np.float64).reshape(-1, 2) for p in image_points or [] if p is not None
    ]
    if boundary_points is not None:
        rim = _given_rim(boundary_points, corners)
    else:
        rim = _detected_rim(greys, corners)
    if image_size is None:
        raise ValueError("image_size (width, height) is needed when no image is given")
    return rim


# -- 3. the camera's own reflection -------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class LensStep:
    """The outline pixels of the camera's reflection the adjustment uses (None: not used) and
    the report's note on it."""

    points: FloatArray | None
    note: str


def pooled_reflection(images, rim_image, rim_fit) -> tuple[FloatArray | None, str]:
    """The outline of the camera's reflection detected in every image and pooled.

    The rig is rigid, so every image shows the same outline; its detection error is partly
    noise (it averages out over the images) and partly systematic (it does not), so the
    pooled outline is more accurate than any one image's (``benchmarks/bench_pattern.py``
    compares them, ``--lens-one``). Detections whose centre or radius is more than
    :data:`_LENS_AGREE_PX` from the median of the images' are left out (a board or a hand
    over the reflection).
    """
    order = [rim_image] + [i for i in range(len(images)) if i != rim_image]
    fits, errors = [], []
    for i in order:
        try:
            fits.append(detect_reflection(images[i], rim_fit))
        except ValueError as e:
            errors.append(str(e))
    if not fits:
        return None, f"not used: {errors[0]}"
    centre = np.median([f.center for f in fits], axis=0)
    radius = float(np.median([f.radius for f in fits]))
    kept = [
        f
        for f in fits
        if np.linalg.norm(f.center - centre) <= _LENS_AGREE_PX
        and abs(f.radius - radius) <= _LENS_AGREE_PX
    ]
    pts = np.concatenate([np.asarray(f.points, np.float64) for f in kept])
    return pts, (
        f"used: {len(pts)} outline points detected in {len(kept)} of {len(images)} image(s)"
    )


def reflection_step(lens, greys, rim: RimStep, lens_z) -> LensStep:
    """3. The camera's own reflection, whose outline pins the tilt against the principal
    point: the outline only with its plane ``lens_z`` known (:data:`LENS_PLANE_UNKNOWN`; the
    renders of an outline off the axis in ``tests/test_chessboard_hostile.py`` show what a free
    plane does)."""
    if isinstance(lens, str):
        if lens != "auto":
            raise ValueError(
                f"lens must be 'auto', None or an (M, 2) array of outline pixels, got {lens!r}"
            )
        if lens_z is None:
            return LensStep(None, LENS_PLANE_UNKNOWN)
        if not greys:
            return LensStep(None, "not used: no image (give lens=outline pixels to use it)")
        return LensStep(*pooled_reflection([g.edges for g in greys], rim.image, rim.fit))
    if lens is None or lens is False:
        return LensStep(None, "not used (lens=None)")
    if lens_z is None:
        raise ValueError(
            "lens outline pixels need lens_z, the circle's distance from the camera "
            "centre along the optical axis: with it unknown the outline trades against the "
            "mirror's tilt (give lens_z, or lens=None)"
        )
    lens_px = np.asarray(lens, np.float64).reshape(-1, 2)
    if len(lens_px) < 8 or not np.isfinite(lens_px).all():
        raise ValueError(
            "lens must hold at least 8 finite pixels along the outline of the camera's reflection"
        )
    return LensStep(lens_px, f"used: {len(lens_px)} outline points given")


#: Images searched for the camera's reflection to record when it took no part in the fit:
#: a few agree on the rigid rig's outline (:func:`pooled_reflection` pools them).
RECORD_REFLECTION_IMAGES = 4


def recorded_reflection(camera, lens: LensStep, greys, rim: RimStep, lens_option):
    """The camera with its own reflection recorded where it is seen (``camera_reflection``), so
    that a default panorama starts above the lens (:func:`omnicam.views.default_elevation_range`).

    The outline the fit used, or, when it took no part (its plane unknown), the one detected
    in a few images (:data:`RECORD_REFLECTION_IMAGES`); its coaxial circle under the fitted
    posture (:func:`omnicam.calibration.reflection.fit_circle`) is recorded when the outline
    fits it within ``BODY_MAX_RMS_PX``, as the single-image route records it
    (:func:`omnicam.calibration.steps.camera_body`). Otherwise the camera as it is.
    """
    px = lens.points
    if px is None:
        if not (isinstance(lens_option, str) and greys):
            return camera  # not to be detected (lens=None), or no image
        k = rim.image if 0 <= rim.image < len(greys) else 0
        few = [greys[k]] + [g for i, g in enumerate(greys) if i != k]
        px, _ = pooled_reflection([g.edges for g in few[:RECORD_REFLECTION_IMAGES]], 0, rim.fit)
        if px is None:
            return camera
    K = camera.K
    xn = normalize(px, K, camera.D)
    circle = fit_circle(camera.mirror, camera.R, camera.tvec, xn, np.linalg.inv(K)[:2, :2])
    if (
        not (math.isfinite(circle.r) and circle.r > 0 and math.isfinite(circle.z))
        or not circle.rms <= BODY_MAX_RMS_PX
    ):
        return camera
    return camera.replace(camera_reflection=(float(circle.r), float(circle.z)))


# -- 4. the start -------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class StartStep:
    """The start camera (``K`` and the posture by Chen's method, or the aligned rig of the
    generic start), the mirror it holds, the central fit (None if it failed), the Taylor fit
    of the generic start (None: not run) and the start's warnings."""

    camera: MisalignedCatadioptricCamera
    mirror: HyperbolicMirror | AsphericMirror
    central: Any
    warnings: tuple[str, ...]
    taylor: Any = None


def start_step(boards: Boards, rim: RimStep, options: PatternOptions) -> StartStep:
    """4. The start: without a mirror the central fit's rig (:func:`_central_start`: a
    hyperboloid, or where Mei's model gives none the generic start's asphere,
    :mod:`.any_start`), else the mirror given and ``K`` (given, or from the rim's size:
    :func:`_chen_start`), the posture by Chen's method from the rim; a given asphere is
    started aligned (:func:`.any_start.aligned_camera`, ``K`` from the Taylor model unless
    given)."""
    central, K, mirror, D, warns = _central_start(boards.points, rim.fit, options)
    if isinstance(mirror, HyperbolicMirror):
        cam0 = _chen_start(K, mirror, rim, D, options.image_size)
        return StartStep(cam0, mirror, central, tuple(warns))
    if options.mirror is None:  # the generic start's rig, ``K`` here its camera
        return StartStep(K.camera, mirror, central, tuple(warns), K.taylor)
    taylor = None
    if K is None:
        views = _full_views(boards.points, options)
        gen = generic_start(views, _obj(options), options.image_size, rim.fit, mirror.rim_radius)
        K, taylor = gen.camera.K, gen.taylor
    cam0 = aligned_camera(K, mirror, rim.fit, options.image_size)
    if D is not None:
        cam0 = MisalignedCatadioptricCamera(
            cam0.K, mirror, cam0.rvec, cam0.tvec, D=D, image_size=options.image_size
        )
    return StartStep(cam0, mirror, central, tuple(warns), taylor)


def generic_start_step(
    boards: Boards, rim: RimStep, options: PatternOptions, central, taylor=None
) -> StartStep:
    """The generic start (:mod:`.any_start`) whatever Mei's ``central`` fit gives: the
    other start where that fit's ``xi`` is at a hyperboloid's edge (:mod:`.calibrate`), or
    from another focal length (:mod:`.other_starts`, with the Taylor model ``taylor`` of the
    first start)."""
    views = _full_views(boards.points, options)
    R = NOMINAL_RIM_RADIUS if options.rim_radius is None else float(options.rim_radius)
    central, gen, mirror, _, warns = _generic(
        central, "", views, _obj(options), rim.fit, R, options, taylor
    )
    return StartStep(gen.camera, mirror, central, tuple(warns), gen.taylor)


def _obj(options):
    return object_points(options.pattern_size, options.square)


def _full_views(image_points, options):
    """The views whose every corner was found, ``(N, 2)`` each."""
    n = len(_obj(options))
    views = [np.asarray(p, np.float64).reshape(-1, 2) for p in image_points if p is not None]
    return [v for v in views if len(v) == n]


def _central_start(image_points, rim_fit, options):
    """Without a mirror, the central start (:mod:`.central`): ``cv2.omnidir.calibrate`` of the
    corners found so far and the hyperbolic rig it describes, at ``rim_radius``. Returns
    ``(central fit or None, K, mirror, start D, warnings)``; a given mirror is returned as it
    is, with ``K`` (None: from the rim) and the given ``D``, and the central fit only for
    comparison. Without a ``D`` and with ``k1, k2`` free a fit with distortion free is tried
    too and starts the rig (``D`` by :func:`.central.pinhole_D_from_unified`, padded to
    ``n_d``) when its RMS is below :data:`RADIAL_START_GAIN` times the distortion-free fit's,
    or when that one fails: a wide-angle lens's ``k1``, which the fit without it takes into
    its aspect and so into Chen's start posture (:func:`_radial_choice`). The central fit's
    shape is not used to judge a given mirror: with the pinhole's distortion fixed its ``xi``
    is biased on misaligned rigs, and with it free ``xi`` trades with ``k1``."""
    obj = _obj(options)
    image_size, mirror = options.image_size, options.mirror
    views = _full_views(image_points, options)
    central, error = None, ""
    try:
        central = fit_central(views, obj, image_size, hyperbolic=False)
    except ValueError as e:
        error = str(e)
    if mirror is not None:  # the rim's start; the central fit to compare
        return central, options.K, mirror, options.D, []
    central, D_c = _radial_choice(central, views, obj, image_size, options)
    rim_radius = options.rim_radius
    R = NOMINAL_RIM_RADIUS if rim_radius is None else float(rim_radius)
    if central is None or not 0.0 < central.xi < XI_NOT_HYPERBOLIC:  # (no hyperboloid)
        return _generic(central, error, views, obj, rim_fit, R, options)
    xi = central.xi
    warns = []
    if xi >= 1.0:  # a misaligned hyperboloid's fit can pass 1 a little
        warns.append(
            f"the central fit gives xi = {xi:.3f}, at the edge of a hyperboloid's (< 1): the "
            f"mirror's shape was started from xi = {XI_START_MAX:g}"
        )
        xi = XI_START_MAX
    centre = ((image_size[0] - 1) / 2.0, (image_size[1] - 1) / 2.0)  # as the rim's start
    K_c, mirror = hyperbolic_start(central.K, xi, rim_radius_px(rim_fit), R, options.K, centre)
    if rim_radius is None:
        warns.append(_scale_assumed(R, "a, b"))
    return central, K_c, mirror, D_c, warns


def _scale_assumed(R, shape):
    return (
        f"the mirror's scale is assumed (rim_radius = {R:g}, nominal): {shape} and the "
        f"camera's position in the mirror frame scale with it; K, D and the viewing "
        f"directions do not. Give rim_radius for the true scale"
    )


def _generic(central, error, views, obj, rim_fit, R, options, taylor=None):
    """The generic start (:mod:`.any_start`) where Mei's model gives no hyperboloid
    (``central`` None, ``xi <= 0`` or ``xi >= XI_NOT_HYPERBOLIC``): ``(central,
    GenericStart, mirror, None, warnings)``, the :class:`.any_start.GenericStart` in ``K``'s
    place."""
    why = (
        f"Mei's central model fails ({error})"
        if central is None
        else f"Mei's central model gives xi = {central.xi:.2f}, which no hyperboloid has (0 to 1)"
    )
    if len(views) < 3:  # no central model of any kind is fitted from fewer boards
        raise ValueError(
            f"the rig could not be started without a mirror: {why}; boards were found in "
            f"{len(views)} image(s), a central start needs 3 or more: check the pattern size, "
            f"or give the mirror (a, b, rim_radius) as a start"
        )
    try:
        gen = generic_start(views, obj, options.image_size, rim_fit, R, options.K, taylor)
    except ValueError as e:
        raise ValueError(
            f"the rig could not be started without a mirror: {why}, and the Taylor model's "
            f"start failed: {e}; give the mirror (a, b, rim_radius) as a start"
        ) from None
    warns = [f"{why}: {gen.warnings[0]}"]
    if options.rim_radius is None:
        warns.append(_scale_assumed(R, "R, the polynomial terms"))
    return central, gen, gen.camera.mirror, None, warns


def _radial_choice(central, views, obj, image_size, options):
    """The central start: ``(central fit, start D)``, the fit with ``k1, k2`` free where it
    describes a hyperboloid and fits far better (:data:`RADIAL_START_GAIN`) than the
    distortion-free fit ``central``, or fits at all (:data:`CENTRAL_RMS_MAX`) where that one
    failed (None), no ``D`` is given and ``k1, k2`` are free; else ``central`` and ``D`` as
    given. Where OpenCV's fit with ``k1, k2`` free fails itself (an error, a negative focal
    length, an RMS above :data:`CENTRAL_RMS_MAX`, as on some wide-angle renders of
    ``benchmarks/bench_chessboard_hostile.py``), the fit with its whole distortion free takes
    its place under the same conditions (its ``k1, k2`` start the rig; its tangential terms
    and skew, which absorb a tilted mirror on any misaligned rig, do not)."""
    D, free_d, n_d = options.D, options.free_d, options.n_d
    if D is not None or not {0, 1} <= set(free_d):
        return central, D
    try:
        radial = fit_central(views, obj, image_size, hyperbolic=False, radial=True)
    except ValueError:
        radial = None
    if radial is None or not radial.rms < CENTRAL_RMS_MAX:  # OpenCV's fit failed: free all of D
        try:
            radial = fit_central(views, obj, image_size, hyperbolic=True, distortion=True)
        except ValueError:
            return central, D
    bound = CENTRAL_RMS_MAX if central is None else RADIAL_START_GAIN * central.rms
    if not (radial.rms < bound and 0.0 < radial.xi < 1.0):
        return central, D
    D_start = np.zeros(n_d)
    D_start[:4] = pinhole_D_from_unified(radial.D, radial.xi)
    return radial, D_start


def _chen_start(K, mirror, rim: RimStep, D, image_size) -> MisalignedCatadioptricCamera:
    """The start camera: ``K`` from the rim's size unless given (the aligned rig's focal
    length, :func:`omnicam.calibration.plausibility.focal_from_rim`, the principal point at
    the image centre), the posture by Chen's method from the rim."""
    if K is None:
        f0 = focal_from_rim(rim_radius_px(rim.fit), mirror)
        w, h = image_size
        K0 = np.array([[f0, 0.0, (w - 1) / 2.0], [0.0, f0, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
    else:
        K0 = validate_K(K)
    try:
        cam0 = rim_posture(K0, mirror, rim.seen, D=D, image_size=image_size)
    except ValueError as e:
        raise ValueError(f"the posture could not be started from the rim: {e}") from None
    return cam0
