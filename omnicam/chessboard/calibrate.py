"""``calibrate_pattern``: K, D and the mirror posture from chessboards seen through the mirror
(beyond the paper), as named steps.

For rigs whose camera cannot be calibrated without the mirror, and whose mirror may be unknown:

1. **the boards**, by OpenCV's detectors on every raw image, which need no camera
   (:func:`.detect.detect_pattern`);
2. **the rim** (eqs. 20-22): :func:`omnicam.calibration.rim.detect_rim` on the first image
   where it is found (or the given ``boundary_points``); every corner must lie inside it, or a
   larger one is sought;
3. **a start without an initial-value problem**: with ``mirror=None`` the central start of
   :mod:`.central` (``cv2.omnidir.calibrate`` of the corners; ``xi`` gives the mirror's shape,
   its focal length the pinhole's, the rim's image the mirror's size at ``rim_radius``, which
   fixes the scale; the fit with ``k1, k2`` free instead when it fits far better, a
   wide-angle lens). With a mirror and without ``K``, the focal length from the rim's size (an
   aligned rig images the rim circle of radius ``r`` at depth ``z_rim + c`` with radius
   ``f r / (z_rim + c)`` px) and the principal point at the image centre; the posture from the
   rim by :func:`omnicam.calibration.calibrate` (Chen's method, eqs. 23-42); every board's pose
   from its corners' rays (:func:`.board_pose.board_pose_from_rays`);
4. **the boards not found yet**, in the unwarped views of the start camera;
5. **the non-central bundle adjustment** (:mod:`.adjustment`) in two stages (the principal
   point and the distortion held at the start, then freed); views whose RMS stands out are
   dropped (or only reported) and the fit is run again; boards still missing are looked for in
   the views of the fitted camera, and the rig fitted again when one is found; a shape held
   from the central fit is checked, and estimated when the corners reject it;
6. a :class:`.report.PatternReport`: RMS overall and per view, poses, standard deviations of
   the parameters and of the viewing directions, the single-image route's plausibility checks,
   warnings and, with ``heldout=k``, the k-fold held-out check (:mod:`.heldout`).

What the data determine is printed by ``benchmarks/bench_pattern.py`` (the bound of
:func:`.adjustment.pattern_uncertainty`, the adjustment's a posteriori standard deviations at
the truth, beside the estimates) and ``benchmarks/bench_chessboard_real.py`` (real images):
a turn of the camera about its centre is a shift of the principal point to first order, for
the boards and the rim alike; only second-order perspective over the camera's narrow field
tells them apart, tangential distortion (``p1, p2``) absorbs even that, and ``k1, k2`` and the
mirror's ``a, b`` trade against the focal length. The outline of the camera's reflection
separates tilt and shift (it moves with twice the tilt). The rays, what a panorama uses, stay
accurate when those parameters are not; the report says which case a calibration is in.
"""

from __future__ import annotations

import dataclasses
import math
import os
import warnings as _warnings

import cv2
import numpy as np

from .._progress import reports_progress, say
from .._typing import FloatArray
from .._validate import (
    float_array,
    positive_number,
    validate_D,
    validate_image_size,
    validate_K,
)
from ..calibration import calibrate
from ..calibration.chen import rim_conic
from ..calibration.ellipse import conic_distance
from ..calibration.plausibility import check_plausibility
from ..calibration.reflection import detect_reflection
from ..calibration.rim import detect_rim, fit_rim
from ..camera import MisalignedCatadioptricCamera
from ..formats.verdict import judged
from ..images import read_image
from ..mirror import HyperbolicMirror
from .adjustment import (
    DIST_MODELS,
    AdjustmentModel,
    BundleAdjustment,
    ray_uncertainty,
    robust_residuals,
    std_from_jacobian,
)
from .board_pose import board_pose_from_rays, object_points, rodrigues, start_viewpoint
from .central import NOMINAL_RIM_RADIUS, fit_central, hyperbolic_start, pinhole_D_from_unified
from .detect import detect_pattern
from .heldout import cross_validate
from .intrinsics import check_pattern_size
from .report import ONE_SIDED, PatternReport

__all__ = ["ONE_SIDED", "calibrate_pattern", "pooled_reflection"]

_MIN_VIEWS = 3
_EDGE_ON_SIN = math.sin(math.radians(5.0))  # a board plane within 5 deg of the viewpoint
_N_RIM = 360  # rim points kept for the adjustment
#: Detections of the camera's reflection farther than this (px, centre or radius) from the
#: median of all images' are not pooled.
_LENS_AGREE_PX = 1.0
#: A relative standard deviation of ``a`` or ``b`` above this: the shape is not determined.
_SHAPE_WEAK = 0.01
#: Rounds of detection and adjustment: a board the views of the fitted camera find that the
#: start's did not is added and the rig fitted again, until no new board is found.
_DETECT_ROUNDS = 3
#: MINPACK's tolerances of the adjustment's first stage (the second's are 1e-10).
_STAGE1_TOL = 1e-6
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
#: Evaluations of the short refinement with the shape free that checks a held shape.
_SHAPE_CHECK_NFEV = 10
#: The held shape is rejected when freeing ``a, b`` lowers the cost by more than this times
#: the residual variance: chi-square with 2 degrees of freedom exceeds ``-2 ln p`` with
#: probability ``p = 0.001``.
SHAPE_REJECT_CHI2 = -2.0 * math.log(1e-3)


# -- helpers ----------------------------------------------------------------------------------


# -- input handling ---------------------------------------------------------------------------
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


def _check_points(points, n, index, pattern_size):
    arr = np.asarray(points, np.float64)
    if arr.ndim == 3 and arr.shape[1:] == (1, 2):
        arr = arr.reshape(-1, 2)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(
            f"image_points[{index}] must be an (N, 1, 2) or (N, 2) array, got shape {arr.shape}"
        )
    if len(arr) != n:
        raise ValueError(
            f"image_points[{index}] has {len(arr)} corners but pattern_size "
            f"{tuple(pattern_size)} has {n}: fix pattern_size (inner corners "
            f"(columns, rows), not squares)"
        )
    if not np.isfinite(arr).all():
        raise ValueError(f"image_points[{index}] has non-finite values")
    return arr


def _azimuth_gap_deg(centres):
    az = np.sort(np.degrees(np.arctan2(centres[:, 1], centres[:, 0])))
    gaps = np.diff(np.append(az, az[0] + 360.0))
    return float(gaps.max())


@reports_progress  # progress(None, text) hears the long steps (omnicam._progress)
def calibrate_pattern(
    images,
    pattern_size,
    square_size,
    mirror=None,
    K=None,
    D=None,
    image_size=None,
    image_points=None,
    refine_mirror_shape=None,
    dist_model="k1k2",
    *,
    rim_radius=None,
    boundary_points=None,
    fit_skew=False,
    drop_outlier_views=True,
    outlier_factor=3.0,
    outlier_min_px=1.0,
    f_scale=1.0,
    lens="auto",
    lens_z=None,
    heldout=0,
    progress=None,
) -> tuple[MisalignedCatadioptricCamera, PatternReport]:
    """Calibrate ``K``, ``D`` and the mirror posture from chessboards seen through the mirror.

    Parameters
    ----------
    images : sequence of ndarray or path, or None
        Images of the rig (BGR or grey), each showing the whole board once; used to detect the
        corners (:func:`omnicam.find_pattern`, unless ``image_points``) and the rim (unless
        ``boundary_points``). ``None`` needs ``image_points``, ``boundary_points`` and
        ``image_size``.
    pattern_size : (int, int)
        Inner corners ``(columns, rows)``, as ``cv2.findChessboardCorners``.
    square_size : float
        Side of a square in the mirror's length unit (mm by convention).
    mirror : HyperbolicMirror or None
        The mirror (a start: only its shape's agreement with the central fit is checked, and
        with ``refine_mirror_shape`` its ``a, b`` are estimated). ``None``: unknown, its shape
        from the central fit's ``xi`` and its size from the rim's image at ``rim_radius``
        (:func:`.central.hyperbolic_start`).
    K : (3, 3) array_like, optional
        Start of the camera matrix (refined). Default: from the central fit of the corners
        (:func:`.central.fit_central`), else from the rim (see the module docstring).
    D : array_like, optional
        Start of the distortion (4 or 5 coefficients); its free coefficients follow
        ``dist_model``.
    image_size : (int, int), optional
        ``(width, height)``; defaults to the images' size.
    image_points : sequence of (N, 1, 2) array_like or None, optional
        Corners per image in OpenCV's order (None for an image without a board); skips
        detection.
    refine_mirror_shape : bool or None
        Also estimate the mirror's ``a, b`` (``rim_radius`` fixes the scale). Default (None):
        not; with ``mirror=None`` the shape is then the central fit's, held, and the reported
        standard deviations (of ``K`` and of the rays) are those of the fit with ``a, b``
        free at the same solution, so what the unknown shape leaves unknown is in them;
        unless the corners reject the held shape (a short refinement with ``a, b`` free
        lowers the cost beyond chance, :data:`SHAPE_REJECT_CHI2`): then they are estimated,
        and a warning says so. The
        data hardly determine ``a, b``: they trade against the focal length and the camera's
        distance to the mirror, which only the rig's non-centrality tells apart
        (:func:`.adjustment.pattern_uncertainty` gives the bound, ``benchmarks/bench_pattern.py``
        prints it); estimating them costs several times the held fit, along that valley.
    dist_model : str
        One of ``"none", "k1", "k1k2", "k1k2p1p2", "k1k2p1p2k3"``: the OpenCV coefficients
        estimated (the others stay at ``D``'s values, or 0). Default ``"k1k2"``: a decentred
        lens (``p1, p2``) moves the image as a tilt of the mirror does, which the posture
        already holds, so the tangential terms mostly trade against it (see the module
        docstring) and predict held-out views worse
        (``benchmarks/bench_chessboard_real.py --dist-model``).
    rim_radius : float, optional
        With ``mirror=None``: the rim's radius (mirror units), which fixes the scale of the
        mirror and of the camera's position in its frame (default
        :data:`.central.NOMINAL_RIM_RADIUS`; the report then says the scale is assumed). No
        view of boards tells the scale apart but through the rig's small non-centrality; the
        viewing directions, ``K`` and ``D`` do not depend on it, distances do in proportion.
    boundary_points : (M, 2) array_like, optional
        Pixels on the rim (as seen), instead of detecting it in the images.
    fit_skew : bool
        Also estimate the skew ``K[0, 1]``.
    drop_outlier_views : bool
        Drop views whose RMS exceeds ``max(outlier_factor * median, outlier_min_px)`` and fit
        again (else they are only reported); either way a ``RuntimeWarning`` names them.
    f_scale : float
        Scale of the robust ``soft_l1`` loss, px (residuals well below it count fully).
    lens : "auto", None or (M, 2) array_like
        The camera's own reflection (:mod:`.reflection`, a circle coaxial with the optical
        axis): ``"auto"`` detects its outline in every image and pools the detections that
        agree (and goes on without it if there is none); an array gives the outline pixels;
        ``None`` does not use it. Its residuals join the adjustment, ``r`` fitted in closed
        form, only with ``lens_z`` given: without it ``"auto"`` leaves it out (the report's
        ``lens_note`` says so) and an array is refused.
    lens_z : float, optional
        The circle's known axial distance from the camera centre (the front edge of the lens
        barrel, mirror length unit). With it the reflection separates a tilt of the mirror
        from a shift of the principal point, which corners and rim alone determine only
        through second-order perspective (see the report's ``std``). With ``z`` unknown the
        outline trades against the tilt, and one a little off the optical axis (a real
        barrel's, a housing's) biases the posture by more than its stated uncertainty without
        raising the residuals, so it is not used.
    heldout : int
        With ``k >= 2``, also the ``k``-fold held-out check (:mod:`.heldout`: the rig
        calibrated on the other folds with the same options, each held-out view's board pose
        alone fitted; ``cv2.omnidir.calibrate`` on the same folds beside it) in
        ``report.heldout``; it costs ``k`` more calibrations. 0: not run.
    progress : callable, optional
        ``progress(index, text)`` hears of each image as its board is looked for (a command
        line prints it), and ``progress(None, text)`` of the long steps: the adjustment's
        evaluations and cost, the shape check, each fold of the held-out check. Silent by
        default.

    Returns
    -------
    camera : MisalignedHyperbolicCamera
    report : PatternReport

    Raises
    ------
    FileNotFoundError
        An image file that does not exist.
    ValueError
        Bad arguments, fewer than 3 usable views, no board found anywhere, all boards seen
        edge-on (coplanar with the camera), corner arrays that do not match ``pattern_size``;
        the message says what to change.
    """
    cols, rows, square, D, free_d, n_d, images, image_points, image_size = _check_arguments(
        images,
        pattern_size,
        square_size,
        mirror,
        D,
        dist_model,
        image_points,
        image_size,
    )
    mirror_given, K_given = mirror, K
    if refine_mirror_shape is None:  # held (an unknown one's uncertainty still counted)
        refine_mirror_shape = False
    names = _names(images)
    found_by = ["given" if p is not None else None for p in (image_points or [])]
    if image_points is None:
        image_points, found_by = _raw_detection_step(images, (cols, rows), progress)
    rim_fit, rim_seen, rim_image, rim_warns = _rim_step(
        images, boundary_points, image_size, image_points
    )
    lens_px, lens_note = _reflection_step(lens, images, rim_image, rim_fit, lens_z)
    obj = object_points((cols, rows), square)  # (_corner_step returns the same)
    K, mirror, central, start_warns, D_start = _central_step(
        image_points, obj, image_size, rim_fit, mirror, rim_radius, K, (D, free_d, n_d)
    )
    cam0 = _start_step(K, mirror, rim_fit, rim_seen, D_start, image_size)
    missing = [i for i, p in enumerate(image_points) if p is None] if images else []
    for i, corners in _redetect(images, missing, (cols, rows), cam0, progress).items():
        image_points[i], found_by[i] = corners, "views"
    model = AdjustmentModel(free_d, n_d, fit_skew, refine_mirror_shape, lens_px, lens_z)
    outliers = _Outliers(drop_outlier_views, outlier_factor, outlier_min_px)
    start, shape = cam0, mirror
    for _round in range(_DETECT_ROUNDS):
        corners = _corner_step(image_points, (cols, rows), square, start)
        fit = _adjustment_step(start, shape, corners, rim_seen, model, f_scale, outliers)
        missing = [i for i, p in enumerate(image_points) if p is None and found_by[i] is None]
        if not images or not missing or _round == _DETECT_ROUNDS - 1:
            break  # (a board found after the last fit would be reported but not fitted)
        # the fitted camera aims the views better than the start did: look again, and fit
        # again only if a board is found that was not
        start = fit.adj.to_gauge(fit.sol.x, image_size)[0]
        shape = start.mirror
        new = _redetect(images, missing, (cols, rows), start, progress)
        if not new:
            break
        for i in new:
            image_points[i], found_by[i] = new[i], "views (fitted camera)"

    def shape_free_from_start():
        start_corners = _corner_step(image_points, (cols, rows), square, cam0)
        free = dataclasses.replace(model, fit_shape=True)
        step = _adjustment_step(cam0, mirror, start_corners, rim_seen, free, f_scale, outliers)
        return step, start_corners

    if mirror_given is None and not refine_mirror_shape:
        say("shape check: is the central fit's mirror shape consistent with the corners?")
        fit, corners = _shape_check_step(fit, corners, image_size, f_scale, shape_free_from_start)
    camera, report = _report_step(
        fit, corners, cam0, image_size, lens_note, central, shape_unknown=mirror_given is None
    )
    found = {i: m for i, m in enumerate(found_by) if m is not None}
    start_warns = rim_warns + start_warns
    warns_all = tuple(start_warns) + report.warnings
    for w in start_warns:
        _warnings.warn(w, RuntimeWarning, stacklevel=2)
    held = None
    if heldout:  # the same calibration on each fold's views: the same options, these rim points
        options = dict(
            K=K_given,
            D=D,
            image_size=image_size,
            refine_mirror_shape=refine_mirror_shape,
            dist_model=dist_model,
            rim_radius=rim_radius,
            boundary_points=rim_seen,
            fit_skew=fit_skew,
            drop_outlier_views=False,
            f_scale=f_scale,
            lens=lens_px,
            lens_z=lens_z,
        )
        held = _heldout_step(report, mirror_given, (cols, rows), square, options, heldout)
    report = dataclasses.replace(
        report, found_by=found, central=central, warnings=warns_all, heldout=held, names=names
    )
    return judged(camera, report)  # the camera carries the report's verdict


# -- the steps' results ------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class _Outliers:
    """Views whose RMS exceeds ``max(factor * median, min_px)`` stand out; ``drop``: fit
    again without them."""

    drop: bool
    factor: float
    min_px: float


@dataclasses.dataclass
class CornerStep:
    """3b. The corners of every image (None where there is no board), each usable board's
    start pose ``{index: (rvec_b, tvec_b)}``, the images left out ``{index: reason}`` and the
    board's object points."""

    pts: list
    poses: dict
    dropped: dict
    obj: np.ndarray


@dataclasses.dataclass
class AdjustmentStep:
    """4. The adjustment (:class:`.adjustment.BundleAdjustment`) and its solution, the views
    used, their RMS ``{index: px}``, the rim points used and the warnings."""

    adj: BundleAdjustment
    sol: object
    used: list
    view_rms: dict
    rim_px: np.ndarray
    warnings: list


# -- the steps of calibrate_pattern ----------------------------------------------------------
def _check_arguments(
    images, pattern_size, square_size, mirror, D, dist_model, image_points, image_size
):
    """Validated arguments: ``(cols, rows, square, D, free_d, n_d, images, image_points,
    image_size)``; ``ValueError`` naming what to change."""
    cols, rows = check_pattern_size(pattern_size)
    square = positive_number(square_size, "square_size")
    if mirror is not None and not isinstance(mirror, HyperbolicMirror):
        raise ValueError(
            f"mirror must be a HyperbolicMirror or None (unknown), got {type(mirror).__name__}"
        )
    if dist_model not in DIST_MODELS:
        raise ValueError(f"dist_model must be one of {sorted(DIST_MODELS)}, got {dist_model!r}")
    D = validate_D(D)
    if D is not None and D.size not in (4, 5):
        raise ValueError(
            f"D must have 4 or 5 coefficients (k1, k2, p1, p2[, k3]) for pattern "
            f"calibration, got {D.size}"
        )
    free_d = DIST_MODELS[dist_model]
    if not free_d and D is None:
        n_d = 0
    else:
        n_d = 5 if (4 in free_d or (D is not None and D.size == 5)) else 4
    if D is not None and D.size < n_d:
        D = np.concatenate([D, np.zeros(n_d - D.size)])
    images, image_points, image_size = _images_and_size(images, image_points, image_size)
    return cols, rows, square, D, free_d, n_d, images, image_points, image_size


def _images_and_size(images, image_points, image_size):
    """The images as arrays (paths read), ``image_points`` as a list matching them, and the
    one ``image_size`` they share."""
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
    return images, image_points, image_size


def _corners_outside(rim_fit, corners):
    """How many of the corners lie outside the rim's ellipse by more than 1 px."""
    if not corners:
        return 0
    return int((conic_distance(rim_fit.conic, np.concatenate(corners)) > 1.0).sum())


def _rim_step(images, boundary_points, image_size, image_points=None):
    """1. The rim: ``(rim_fit, rim_seen, rim_image, warnings)`` from the points or the first
    image that shows it. Every corner found must lie inside the mirror: a rim that leaves
    corners outside (an inner edge of the mirror's image, a reflection) is rejected and a
    larger one sought (:func:`.rim.detect_rim` with the size the corners need), in that image
    and the next; the warnings say which was rejected."""
    corners = [
        np.asarray(p, np.float64).reshape(-1, 2) for p in image_points or [] if p is not None
    ]
    warns = []
    rim_image = 0
    if boundary_points is not None:
        rim_seen = float_array(
            boundary_points, "boundary_points", "pixels on the rim, (M, 2)"
        ).reshape(-1, 2)
        if len(rim_seen) < 6 or not np.isfinite(rim_seen).all():
            raise ValueError("boundary_points must be at least 6 finite pixels on the rim")
        rim_fit = fit_rim(rim_seen)
        rim_seen = rim_seen[np.asarray(rim_fit.inliers, bool)]
        n_out = _corners_outside(rim_fit, corners)
        if n_out:
            warns.append(
                f"{n_out} corner(s) lie outside the rim of the boundary_points given (semi-axes "
                f"{rim_fit.axes[0]:.1f}, {rim_fit.axes[1]:.1f} px): are they the mirror's rim?"
            )
    else:
        rim_fit, errors = None, []
        for i, im in enumerate(images):
            try:
                found = detect_rim(im)
            except ValueError as e:
                errors.append(f"images[{i}]: {e}")
                continue
            n_out = _corners_outside(found, corners)
            if n_out:
                need = float(np.max(np.linalg.norm(np.concatenate(corners) - found.center, axis=1)))
                what = (
                    f"the rim found in image {i} (centre {found.center[0]:.1f}, "
                    f"{found.center[1]:.1f}, semi-axes {found.axes[0]:.1f}, {found.axes[1]:.1f} "
                    f"px) leaves {n_out} corner(s) outside: rejected"
                )
                try:
                    larger = detect_rim(im, expected=(need, 2.0 * need))
                except ValueError:
                    larger = None
                if larger is None or _corners_outside(larger, corners):
                    errors.append(f"images[{i}]: {what}")
                    warns.append(what)
                    continue
                warns.append(
                    f"{what}; the rim taken has semi-axes {larger.axes[0]:.1f}, "
                    f"{larger.axes[1]:.1f} px"
                )
                found = larger
            rim_fit, rim_image = found, i
            break
        if rim_fit is None:
            raise ValueError(
                "the mirror rim was not found in any image ("
                + "; ".join(errors[:2])
                + "); give boundary_points"
            )
        rim_seen = np.asarray(rim_fit.points, np.float64)
    if image_size is None:
        raise ValueError("image_size (width, height) is needed when no image is given")
    return rim_fit, rim_seen, rim_image, warns


def pooled_reflection(images, rim_image, rim_fit) -> tuple[FloatArray | None, str]:
    """The outline of the camera's reflection detected in every image and pooled.

    The rig is rigid, so every image shows the same outline; its detection error is partly
    noise (it averages out over the images) and partly systematic (it does not): on the
    benchmark's renders 0.12 px RMS in one image, 0.066 px RMS per direction averaged over 13,
    and the principal point's error over 3 trials 2-24 px from one image against 4-6 px pooled.
    Detections whose centre or radius is more than :data:`_LENS_AGREE_PX` from the median of
    the images' are left out (a board or a hand over the reflection).
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


#: Why the camera's reflection joins the adjustment only with its plane known.
LENS_PLANE_UNKNOWN = (
    "not used: its plane is unknown (give lens_z, or --lens-z on the command line: the front "
    "edge's distance from the camera centre, to use it); with z free it trades against the "
    "mirror's tilt, and an outline off the optical axis biases the posture without a trace in "
    "the residuals"
)


def _reflection_step(lens, images, rim_image, rim_fit, lens_z):
    """The camera's own reflection: ``(outline pixels or None, note)``, the outline only with
    its plane ``lens_z`` known (:data:`LENS_PLANE_UNKNOWN`; the renders of an outline off the
    axis in ``tests/test_chessboard_hostile.py`` show what a free plane did)."""
    # the camera's own reflection (its outline pins the tilt against the principal point)
    lens_px, lens_note = None, "not used (lens=None)"
    if isinstance(lens, str):
        if lens != "auto":
            raise ValueError(
                f"lens must be 'auto', None or an (M, 2) array of outline pixels, got {lens!r}"
            )
        if lens_z is None:
            lens_note = LENS_PLANE_UNKNOWN
        elif not images:
            lens_note = "not used: no image (give lens=outline pixels to use it)"
        else:
            lens_px, lens_note = pooled_reflection(images, rim_image, rim_fit)
    elif lens is not None and lens is not False:
        if lens_z is None:
            raise ValueError(
                "lens outline pixels need lens_z, the circle's distance from the camera "
                "centre along the optical axis: with it unknown the outline trades against the "
                "mirror's tilt (give lens_z, or lens=None)"
            )
        lens_px = np.asarray(lens, np.float64).reshape(-1, 2)
        if len(lens_px) < 8 or not np.isfinite(lens_px).all():
            raise ValueError(
                "lens must hold at least 8 finite pixels along the outline of the "
                "camera's reflection"
            )
        lens_note = f"used: {len(lens_px)} outline points given"

    return lens_px, lens_note


def _start_step(K, mirror, rim_fit, rim_seen, D, image_size):
    """2. The start: ``K`` from the rim's size unless given, the posture by Chen's method."""
    # 2. the start: K from the rim, posture by Chen's method
    if K is None:
        r_px = math.sqrt(float(rim_fit.axes[0] * rim_fit.axes[1]))
        f0 = r_px * (mirror.z_rim + mirror.c) / mirror.rim_radius
        w, h = image_size
        K0 = np.array([[f0, 0.0, (w - 1) / 2.0], [0.0, f0, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
    else:
        K0 = validate_K(K)
    try:
        cam0, _ = calibrate(
            K0,
            mirror,
            boundary_points=rim_seen,
            D=D,
            image_size=image_size,
            refine=True,
            lens=None,
        )
    except ValueError as e:
        raise ValueError(f"the posture could not be started from the rim: {e}") from None

    return cam0


def _raw_detection_step(images, pattern_size, progress=None):
    """2a. Every image's board by OpenCV's detectors on the raw image, which need no camera
    (:func:`.detect.detect_pattern`). Returns ``(corners or None per image, how each
    was found or None)``; ``progress(index, text)`` hears of each image."""
    points, found_by = [], []
    for k, im in enumerate(images):
        det = detect_pattern(im, pattern_size, None, methods=("raw", "raw-sb"))
        points.append(None if det is None else det.corners)
        found_by.append(None if det is None else det.method)
        if progress is not None:
            progress(k, "no board on the raw image" if det is None else f"board ({det.method})")
    return points, found_by


def _central_step(image_points, obj, image_size, rim_fit, mirror, rim_radius, K, dist):
    """2b. Without a mirror, the central start (:mod:`.central`): ``cv2.omnidir.calibrate``
    of the corners found so far and the hyperbolic rig it describes, at ``rim_radius``.
    Returns ``(K, mirror, central fit or None, warnings, start D)``; a given mirror is
    returned as it is, with ``K`` (None: from the rim) and the given ``D``, and the central
    fit only for comparison. ``dist`` is ``(D, free_d, n_d)``, the start distortion given and
    the adjustment's: without a ``D`` and with ``k1, k2`` free a fit with distortion free is
    tried too and starts the rig (``D`` by :func:`.central.pinhole_D_from_unified`, padded to
    ``n_d``) when its RMS is below :data:`RADIAL_START_GAIN` times the distortion-free fit's,
    or when that one fails: a wide-angle lens's ``k1``, which the fit without it takes into
    its aspect and so into Chen's start posture (:func:`_radial_choice`). The central fit's
    shape is not used to judge a given mirror: with the pinhole's distortion fixed its ``xi``
    is biased on misaligned rigs (``a / b`` 1.22-1.28 on the test rig whose mirror has
    0.83), and with it free ``xi`` trades with ``k1``."""
    warns = []
    views = [np.asarray(p, np.float64).reshape(-1, 2) for p in image_points if p is not None]
    views = [v for v in views if len(v) == len(obj)]
    central, error = None, ""
    try:
        central = fit_central(views, obj, image_size, hyperbolic=False)
    except ValueError as e:
        error = str(e)
    if mirror is not None:  # the rim's start (module docstring); the central fit to compare
        return K, mirror, central, warns, dist[0]
    central, D_c = _radial_choice(central, views, obj, image_size, dist)
    if central is None:
        raise ValueError(
            f"the rig could not be started without a mirror: {error}; give the mirror "
            f"(a, b, rim_radius) as a start"
        )
    xi = central.xi
    if not xi < XI_NOT_HYPERBOLIC:
        raise ValueError(
            f"the central fit of the corners gives xi = {xi:.2f}: no hyperboloid does (a "
            f"hyperboloid has xi < 1, a paraboloid 1, a sphere more); the mirror may not be a "
            f"hyperboloid, which omnicam does not model. If it is one, give its a, b and "
            f"rim_radius as a start"
        )
    if xi >= 1.0:  # a misaligned hyperboloid's fit can pass 1 a little
        warns.append(
            f"the central fit gives xi = {xi:.3f}, at the edge of a hyperboloid's (< 1): the "
            f"mirror's shape was started from xi = {XI_START_MAX:g}"
        )
        xi = XI_START_MAX
    r_px = math.sqrt(float(rim_fit.axes[0] * rim_fit.axes[1]))
    centre = ((image_size[0] - 1) / 2.0, (image_size[1] - 1) / 2.0)  # as the rim's start
    R = NOMINAL_RIM_RADIUS if rim_radius is None else float(rim_radius)
    K_c, mirror = hyperbolic_start(central.K, xi, r_px, R, K, centre)
    if rim_radius is None:
        warns.append(
            f"the mirror's scale is assumed (rim_radius = {R:g}, nominal): a, b and the "
            f"camera's position in the mirror frame scale with it; K, D and the viewing "
            f"directions do not. Give rim_radius for the true scale"
        )
    return K_c, mirror, central, warns, D_c


def _radial_choice(central, views, obj, image_size, dist):
    """The central start: ``(central fit, start D)``, the fit with ``k1, k2`` free where it
    describes a hyperboloid and fits far better (:data:`RADIAL_START_GAIN`) than the
    distortion-free fit ``central``, or fits at all (:data:`CENTRAL_RMS_MAX`) where that one
    failed (None), no ``D`` is given and ``k1, k2`` are free (``dist = (D, free_d, n_d)``);
    else ``central`` and ``D`` as given. Where OpenCV's fit with ``k1, k2`` free fails
    itself (an error, a negative focal length, an RMS above :data:`CENTRAL_RMS_MAX`: on a
    wide-angle lens it does, on 2 of 8 renders of ``benchmarks/bench_chessboard_hostile.py
    --wide-seeds 8``), the fit with its whole distortion free takes its place under the same
    conditions (its ``k1, k2`` start the rig; its tangential terms and skew, which absorb a
    tilted mirror on any misaligned rig, do not)."""
    D, free_d, n_d = dist
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


def _redetect(images, missing, pattern_size, camera, progress=None):
    """3a. ``{index: corners}`` of the boards that the views of ``camera`` find in the images
    ``missing``; ``progress(index, text)`` hears of each."""
    new = {}
    for i in missing:
        det = detect_pattern(images[i], pattern_size, camera, methods=("views",))
        if det is not None:
            new[i] = det.corners
        if progress is not None:
            progress(i, "board (views)" if det is not None else "no board in the views either")
    return new


def _corner_step(image_points, pattern_size, square, cam0):
    """3b. The corners of every view, checked, and each board's start pose from its rays
    (:class:`CornerStep`)."""
    cols, rows = pattern_size
    n_corners = cols * rows
    dropped = {}
    pts = []
    for i, p in enumerate(image_points):
        if p is None:
            pts.append(None)
            dropped[i] = "no board found"
            continue
        pts.append(_check_points(p, n_corners, i, (cols, rows)))
    found = [i for i, p in enumerate(pts) if p is not None]
    if found:  # (with no board at all the error below says it)
        for i in sorted(dropped):
            _warnings.warn(f"view {i} dropped: {dropped[i]}", RuntimeWarning, stacklevel=2)
    if not found:
        raise ValueError(
            f"no {cols}x{rows} chessboard was found in any of the {len(pts)} "
            f"image(s): check pattern_size (inner corners (columns, rows), not "
            f"squares) and that the whole board is seen in the mirror"
        )
    obj = object_points((cols, rows), square)
    viewpoint = start_viewpoint(cam0)
    poses, edge_on = {}, []
    for i in found:
        P, d = cam0.unproject(pts[i])
        if not np.isfinite(d).all():
            dropped[i] = "corners outside the mirror rim"
            _warnings.warn(f"view {i} dropped: {dropped[i]}", RuntimeWarning, stacklevel=2)
            continue
        rvec_b, tvec_b, _ = board_pose_from_rays(P, d, obj, viewpoint)
        n = rodrigues(rvec_b)[:, 2]
        centre = obj.mean(axis=0) @ rodrigues(rvec_b).T + tvec_b - viewpoint
        if abs(n @ centre) < _EDGE_ON_SIN * np.linalg.norm(centre):
            dropped[i] = "board seen edge-on (its plane passes through the camera)"
            _warnings.warn(f"view {i} dropped: {dropped[i]}", RuntimeWarning, stacklevel=2)
            edge_on.append(i)
            continue
        poses[i] = (rvec_b, tvec_b)
    if edge_on and len(edge_on) == len(found):
        raise ValueError(
            "all boards are seen edge-on (their planes pass through the camera): "
            "turn the board towards the mirror"
        )
    used = sorted(poses)
    if len(used) < _MIN_VIEWS:
        raise ValueError(
            f"only {len(used)} usable view(s) of the board (need at least "
            f"{_MIN_VIEWS}; dropped: {dropped}): take more views of the whole "
            f"board around the mirror"
        )

    return CornerStep(pts, poses, dropped, obj)


def _adjustment_step(cam0, mirror, corners, rim_seen, model, f_scale, outliers):
    """4. The bundle adjustment in two stages, views that stand out reported (and dropped by
    ``outliers.drop``): an :class:`AdjustmentStep`."""
    obj, pts, poses, dropped = corners.obj, corners.pts, corners.poses, corners.dropped
    warns = []
    used = sorted(poses)
    # 4. the bundle adjustment
    rim_px = rim_seen
    if len(rim_px) > _N_RIM:
        rim_px = rim_px[np.linspace(0, len(rim_px) - 1, _N_RIM).round().astype(int)]

    def adjust(view_ids, x_boards, x_global=None):
        adj = BundleAdjustment(cam0, mirror, obj, [pts[i] for i in view_ids], rim_px, model)
        x0 = np.concatenate(
            [adj.x0_global if x_global is None else x_global, np.concatenate(x_boards)]
        )
        if x_global is None:
            # stage 1: principal point, skew and distortion held at the start, so the fit does
            # not first wander along the valley where a shift of the principal point (or
            # tangential distortion) trades against a tilt of the mirror; only a start for
            # stage 2, which converges to 1e-10 on its own: to 1e-6 (its last evaluations
            # lower the cost by fractions of a millionth)
            adj.fixed = {"cx", "cy", "skew", "k1", "k2", "p1", "p2", "k3"}
            x0 = adj.solve(x0, f_scale=f_scale, max_nfev=20, tol=_STAGE1_TOL).x
            adj.fixed = set()
        # with the mirror's shape free the fit follows a long, flat valley (a, b trade against
        # f and the camera's axial position; only the rig's non-centrality tells them apart):
        # on exact corners started 2 % off it needs ~150 iterations to reach the truth
        return adj, adj.solve(x0, f_scale=f_scale, max_nfev=400 if model.fit_shape else 100)

    adj, sol = adjust(used, [np.concatenate(poses[i]) for i in used])

    vr = _view_rms(adj, sol.x, used)
    med = float(np.median(list(vr.values())))
    limit = max(outliers.factor * med, outliers.min_px)
    standing_out = [i for i in used if vr[i] > limit]
    if standing_out:
        what = "dropped" if outliers.drop else "kept"
        msg = (
            f"view(s) {standing_out} reproject with RMS "
            f"{', '.join(f'{vr[i]:.2f}' for i in standing_out)} px against a median of "
            f"{med:.3f} px ({what}; check their corners)"
        )
        warns.append(msg)
        _warnings.warn(msg, RuntimeWarning, stacklevel=2)
        if outliers.drop and len(used) - len(standing_out) >= _MIN_VIEWS:
            B = adj.boards(sol.x)
            keep = [k for k, i in enumerate(used) if i not in standing_out]
            for i in standing_out:
                dropped[i] = f"RMS {vr[i]:.2f} px stands out (median {med:.3f} px)"
            used = [used[k] for k in keep]
            adj, sol = adjust(used, [B[k] for k in keep], sol.x[: adj.n_global])
            vr = _view_rms(adj, sol.x, used)
        elif outliers.drop:
            warns.append("too few views would remain: the outliers were kept")

    return AdjustmentStep(adj, sol, used, vr, rim_px, warns)


def _view_rms(adj, x, ids):
    """``{view index: corner RMS, px}`` of the views ``ids`` of ``adj`` at ``x``."""
    r = adj.corner_residuals(x).reshape(len(ids), -1)
    return {i: float(np.sqrt(np.mean(r[k] ** 2) * 2)) for k, i in enumerate(ids)}


def _shape_check_step(fit, corners, image_size, f_scale, from_start):
    """4b. A shape held from the central fit checked: a short refinement with ``a, b`` free,
    started at the held solution (:func:`_shape_free`). A likelihood-ratio test: when it lowers
    the corners' and the rim's robust cost (the camera's reflection, whose misfit is the coaxial
    circle's model error more than noise, left out) by more than :data:`SHAPE_REJECT_CHI2` times
    the residual variance, the corners reject the central fit's shape (on a wide-angle rig the
    rays are then off by several times their stated uncertainty, which a shape held at a biased
    value does not contain), and ``a, b`` are estimated, with a warning: the fit with them free
    carried on from the held solution, and ``from_start()``, the adjustment with them free from
    the start camera (``(AdjustmentStep, CornerStep)``), whichever ends at the lower mean robust
    cost. The held solution lies in the valley the wrong shape made, and can lead to a minimum
    of its own (one of 8 wide-angle renders of ``benchmarks/bench_chessboard_hostile.py
    --wide-seeds 8``, its rays 6 times their stated uncertainty off). Returns ``(fit,
    corners)``, as given when the held shape stands."""
    adj, sol = fit.adj, fit.sol
    camera, gauged = adj.to_gauge(sol.x, image_size)
    adj2, x2 = _shape_free(adj, sol.x, camera, gauged)
    n_boards = adj2.obs.size + len(adj2.rim_px)  # the corners' and the rim's rows come first

    def boards_cost(x):  # the corners' and the rim's robust cost, the outline's left out
        z = robust_residuals(adj2.residuals(x), f_scale)[0][:n_boards]
        return float(z @ z)

    cost = boards_cost(x2)
    sigma2 = cost / max(n_boards - len(sol.x), 1)
    short = adj2.solve(x2, f_scale=f_scale, max_nfev=_SHAPE_CHECK_NFEV)
    chi2 = (cost - boards_cost(short.x)) / sigma2
    if not chi2 > SHAPE_REJECT_CHI2:
        return fit, corners
    ratio = camera.mirror.a / camera.mirror.b
    msg = (
        f"the central fit's mirror shape (a / b = {ratio:.3f}) is rejected by the corners: "
        f"freeing a, b lowers the cost by {chi2:.0f} times the residual variance (above "
        f"{SHAPE_REJECT_CHI2:.1f}, chi-square with 2 degrees of freedom at p = 0.001), so a, b "
        f"were estimated"
    )
    _warnings.warn(msg, RuntimeWarning, stacklevel=2)
    sol2 = adj2.solve(short.x, f_scale=f_scale, max_nfev=400)
    vr = _view_rms(adj2, sol2.x, fit.used)
    held = AdjustmentStep(adj2, sol2, fit.used, vr, fit.rim_px, [*fit.warnings, msg])
    with _warnings.catch_warnings(record=True) as caught:  # said only if it is taken
        _warnings.simplefilter("always")
        try:
            alt, alt_corners = from_start()
        except ValueError:
            return held, corners
    if not _mean_cost(alt.sol) < _mean_cost(sol2):
        return held, corners
    for w in caught:
        _warnings.warn(w.message, w.category, stacklevel=2)
    return dataclasses.replace(alt, warnings=[*alt.warnings, msg]), alt_corners


def _mean_cost(sol) -> float:
    """The robust cost per residual of a solution (fits of different views compared)."""
    return 2.0 * float(sol.cost) / max(len(sol.fun), 1)


def _heldout_step(report, mirror, pattern_size, square, options, k):
    """6. The k-fold held-out check of the views used (:func:`.heldout.cross_validate`), the
    rig on each fold's training views calibrated with the same ``options``, its warnings
    (said once, for the whole fit) silenced."""
    views = {
        i: np.asarray(report.image_points[i], np.float64).reshape(-1, 2) for i in report.view_rms
    }

    def fit(train):
        points = [views[i] for i in train]
        with _warnings.catch_warnings():
            _warnings.simplefilter("ignore")
            camera, _ = calibrate_pattern(
                None, pattern_size, square, mirror, image_points=points, **options
            )
        return camera

    obj = object_points(pattern_size, square)
    return cross_validate(fit, views, obj, options["image_size"], k)


def _shape_free(adj, x, camera, board_poses):
    """The adjustment ``adj`` at ``x`` again, with the mirror's ``a, b`` free: ``(adj2, x2)``
    at the same solution (``camera`` and its ``board_poses`` in the gauge), whose covariance
    holds what an unknown shape leaves unknown."""
    model = AdjustmentModel(
        adj.free_d,
        adj.n_d,
        adj.fit_skew,
        True,
        adj.lens_px,
        None if adj.fit_lens_z else adj.lens_z,
    )
    adj2 = BundleAdjustment(camera, camera.mirror, adj.obj, adj.views, adj.rim_px, model)
    boards = [np.concatenate([np.ravel(r), np.ravel(t)]) for r, t in board_poses]
    return adj2, np.concatenate([adj2.x0_global, *boards])


def _row_sigma(r, n_params, sizes):
    """Each row's noise, estimated from the residuals ``r`` of its group (the corners, the rim,
    then the outline: ``sizes`` gives the first groups' lengths, the last takes the rest): the
    RMS of the group, its degrees of freedom shared out in proportion to its rows. The
    adjustment weighs every row alike, so one sigma pooled over groups of different noise (the
    rim's points fit better than the corners) understated the rays' uncertainty (8 % below the
    bound at the truth on the hostile renders)."""
    m = len(r)
    dof = max(m - n_params, 1) / max(m, 1)
    edges = np.cumsum([0, *sizes, m - sum(sizes)])
    sigma = np.empty(m)
    for lo, hi in zip(edges[:-1], edges[1:]):
        if hi > lo:
            sigma[lo:hi] = math.sqrt(float(r[lo:hi] @ r[lo:hi]) / (dof * (hi - lo)))
    return sigma


def _report_step(fit, corners, cam0, image_size, lens_note, central, shape_unknown=False):
    """5. The camera in the gauge and the :class:`PatternReport` with the a posteriori
    standard deviations, the plausibility checks and the warnings. With ``shape_unknown``
    and the shape held (``refine_mirror_shape=False``), the standard deviations are those of
    the fit with ``a, b`` free at the same solution (:func:`_shape_free`): the shape taken
    from the central fit is not known, and what it leaves unknown must be in them."""
    adj, sol, used, vr, rim_px = fit.adj, fit.sol, fit.used, fit.view_rms, fit.rim_px
    warns = list(fit.warnings)
    obj, pts, dropped = corners.obj, corners.pts, corners.dropped
    n_corners, refine_mirror_shape = len(obj), adj.fit_shape
    nv_rows = adj.n_rows_view
    # 5. the report
    camera, gauged = adj.to_gauge(sol.x, image_size)
    r_all = adj.residuals(sol.x)
    held_shape = shape_unknown and not adj.fit_shape
    adj_u, x_u = _shape_free(adj, sol.x, camera, gauged) if held_shape else (adj, sol.x)
    sigma = _row_sigma(r_all, len(sol.x), (len(used) * nv_rows, len(rim_px)))
    std, cov = std_from_jacobian(adj_u, x_u, adj_u.jacobian(x_u), sigma, unweighted=True)
    ray_deg = ray_uncertainty(adj_u, x_u, cov, image_size)
    corner_r = r_all[: len(used) * nv_rows]
    rim_r = r_all[len(used) * nv_rows : len(used) * nv_rows + len(rim_px)]
    lens_r = r_all[len(used) * nv_rows + len(rim_px) :]
    board_poses = {i: gauged[k] for k, i in enumerate(used)}
    reprojected = {i: camera.project(obj, *board_poses[i]).reshape(-1, 1, 2) for i in used}
    if len(used) < 6:
        warns.append(
            f"only {len(used)} views: take 10 or more, spread around the mirror, for a "
            f"reliable K and posture"
        )
    centres = np.array([obj.mean(axis=0) @ rodrigues(p[0]).T + p[1] for p in board_poses.values()])
    if _azimuth_gap_deg(centres) > 180.0:
        warns.append(
            f"{ONE_SIDED}: "
            "add views on the other side, or the principal point and the tilt are "
            "poorly separated"
        )
    if max(std["cx"], std["cy"]) > 1.0:
        warns.append(
            f"the principal point is weakly determined (std {std['cx']:.2f}, "
            f"{std['cy']:.2f} px): add views at other azimuths and elevations"
        )
    if not sol.success:
        warns.append(f"the adjustment did not converge: {sol.message}")
    rays = (
        f"the viewing directions are known to {ray_deg[0]:.3f} deg (median over the mirror's "
        f"image, worst {ray_deg[1]:.3f} deg)"
    )
    if held_shape:
        warns.append(
            f"the mirror's shape is the central fit's (a = {camera.mirror.a:.3f} +- "
            f"{std['a']:.3f}, b = {camera.mirror.b:.3f} +- {std['b']:.3f}), held, and its "
            f"uncertainty is in the stated ones of K and of the rays; refine_mirror_shape=True "
            f"(--refine-mirror-shape) estimates it, at several times the cost"
        )
    if refine_mirror_shape:
        ra = std["a"] / camera.mirror.a
        rb = std["b"] / camera.mirror.b
        weak = max(ra, rb) > _SHAPE_WEAK
        warns.append(
            f"the mirror's a, b were estimated (a = {camera.mirror.a:.3f} +- "
            f"{std['a']:.3f} ({100 * ra:.1f} %), b = {camera.mirror.b:.3f} +- "
            f"{std['b']:.3f} ({100 * rb:.1f} %))"
            + (
                ": NOT determined by these data (they trade against the focal length and the "
                "camera's distance to the mirror, which only the rig's small non-centrality "
                f"tells apart), but {rays}; use the data sheet's values for distances"
                if weak
                else "; they trade against the focal length and the camera's distance to the "
                "mirror: prefer the data sheet's values when there is one"
            )
        )
    if std["fx"] > _SHAPE_WEAK * camera.K[0, 0]:
        warns.append(
            f"the focal length is weakly determined (fx = {camera.K[0, 0]:.1f} +- "
            f"{std['fx']:.1f} px: it trades against the mirror's shape and distance), but {rays}"
        )
    rms = float(np.sqrt(np.mean(corner_r**2) * 2))
    if central is not None and central.xi >= XI_NOT_HYPERBOLIC:
        warns.append(
            f"the central fit of the corners gives xi = {central.xi:.2f}, which no hyperboloid "
            f"gives (xi < 1; a paraboloid 1, a sphere more): the mirror may not be a "
            f"hyperboloid, which omnicam does not model"
        )
    elif central is not None and rms > 2.0 * central.rms + 0.1:
        warns.append(
            f"the corners fit this rig to {rms:.3f} px RMS, far above the "
            f"central fit's {central.rms:.3f} px: the mirror may not be a hyperboloid (a "
            f"sphere, a paraboloid, a cone), or the start was far off"
        )
    implausible = tuple(
        check_plausibility(
            camera, rim_conic(camera.K, camera.R, camera.tvec, camera.mirror), image_size
        )
    )
    warns.extend(str(w) for w in implausible)
    image_points_out = [None if p is None else p.reshape(-1, 1, 2).astype(np.float32) for p in pts]
    report = PatternReport(
        rms=rms,
        ray_std_deg=ray_deg,
        view_rms=vr,
        corners_used={i: n_corners for i in used},
        board_poses=board_poses,
        image_points=image_points_out,
        reprojected=reprojected,
        rim_points=rim_px,
        rim_rms=float(np.sqrt(np.mean(rim_r**2))),
        std=std,
        warnings=tuple(warns),
        lens_rms=float(np.sqrt(np.mean(lens_r**2))) if len(lens_r) else math.nan,
        lens_note=lens_note,
        dropped=dict(sorted(dropped.items())),
        nfev=int(sol.nfev),
        camera=camera,
        start=cam0,
        plausibility=implausible,
    )
    return camera, report
