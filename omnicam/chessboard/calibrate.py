"""``calibrate_pattern``: K, D and the mirror posture from chessboards seen through the mirror
(beyond the paper), as named steps, each returning a frozen dataclass.

For rigs whose camera cannot be calibrated without the mirror, and whose mirror may be unknown.
The steps (:mod:`.steps`, :mod:`.fit_steps`):

0. **the options and the images** (:class:`.steps.PatternOptions`, validated;
   :func:`.steps.load_step` -> :class:`.steps.Inputs`): every image read once and made grey
   once, for every detector and every round;
1. **the boards** (:func:`.steps.raw_detection_step` -> :class:`.steps.Boards`), by OpenCV's
   detectors on every raw image, which need no camera (:func:`.detect.detect_pattern`);
2. **the rim** (eqs. 20-22; :func:`.steps.rim_step` -> :class:`.steps.RimStep`):
   :func:`omnicam.calibration.rim.detect_rim` on the first image where it is found, pooled
   with the rims of its size in the next few images (or the given ``boundary_points``); every
   corner must lie inside it, or a larger one is sought;
3. **the camera's reflection** (:func:`.steps.reflection_step` -> :class:`.steps.LensStep`):
   its outline pooled over the images, used only with its plane ``lens_z`` known;
4. **a start without an initial-value problem** (:func:`.steps.start_step` ->
   :class:`.steps.StartStep`): with ``mirror=None`` the central start of :mod:`.central`
   (``cv2.omnidir.calibrate`` of the corners; ``xi`` gives the mirror's shape, its focal
   length the pinhole's, the rim's image the mirror's size at ``rim_radius``, which fixes the
   scale; the fit with ``k1, k2`` free instead when it fits far better, a wide-angle lens).
   Where Mei's model gives no hyperboloid (``xi >= XI_NOT_HYPERBOLIC`` or no fit), the generic
   start of :mod:`.any_start`: the corners' Taylor model and the aligned rig with the even
   asphere that sees its directions, whose shape and focal length the adjustment frees, and
   whose polynomial terms a likelihood-ratio test may extend (:mod:`.family`).
   With a mirror and without ``K``, the aligned rig's focal length from the rim's size
   (:func:`omnicam.calibration.plausibility.focal_from_rim`) and the principal point at the
   image centre; the posture from the rim by :func:`omnicam.calibration.rim_posture` (Chen's
   method, eqs. 23-42); then the boards not found yet, in the unwarped views of the start
   camera (:func:`.steps.redetect`);
5. **the corners** (:func:`.fit_steps.corner_step` -> :class:`.fit_steps.CornerStep`):
   every board's pose from its corners' rays (:func:`.board_pose.board_pose_from_rays`);
6. **the non-central bundle adjustment** (:mod:`.adjustment`; :func:`.fit_steps.adjustment_step`
   -> :class:`.fit_steps.AdjustmentStep`) in two stages (the principal point and the
   distortion held at the start, then freed); views whose RMS stands out are dropped (or only
   reported) and the fit is run again;
7. **rounds** (:func:`.fit_steps.rounds_step` -> :class:`.fit_steps.Rounds`): boards still
   missing are looked for in the views of the fitted camera, and the rig fitted again when
   one is found;
8. a shape held from the central fit is checked, and estimated when the corners reject it
   (:func:`.fit_steps.shape_check_step`); the mirror's family tested by the data: the
   hyperboloid against the conic with a polynomial term, an asphere's terms one more at a
   time (likelihood-ratio tests, :mod:`.family`; the report's ``family`` says which and why);
   where the generic fit's rays are weakly determined (or it ran off to a rig that cannot
   be), the same steps from other starts (along the focal length, the mirror turned), the
   lowest cost taken and the spread of the fits as good stated (:mod:`.other_starts`);
9. a :class:`.report.PatternReport` (:func:`.fit_steps.report_step`): RMS overall and per
   view, poses, standard deviations of the parameters and of the viewing directions, the
   single-image route's plausibility checks, warnings (:mod:`.report_warnings`, one policy
   each) and, with ``heldout=k``, the k-fold held-out check (:mod:`.heldout`), which re-runs
   these steps on each fold with the same options.

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
import warnings as _warnings

import numpy as np

from .._progress import reports_progress, say
from ..camera import MisalignedCatadioptricCamera
from ..formats.verdict import judged
from ..mirror import HyperbolicMirror
from .adjustment import AdjustmentModel
from .board_pose import object_points
from .family import chi2_limit, family_step, hyperboloid_term_check
from .fit_steps import SHAPE_REJECT_CHI2, report_step, rounds_step, shape_check_step, shape_free
from .fold_rays import fold_check
from .heldout import HeldOut, cross_validate
from .lens_model import AUTO_CANDIDATES, AUTO_FOLDS, LensChoice, choose
from .other_starts import first_fit, fitter, other_starts_step
from .report import PatternReport
from .report_warnings import ONE_SIDED
from .second_start import second_start_step
from .steps import (
    CENTRAL_RMS_MAX,
    LENS_PLANE_UNKNOWN,
    RADIAL_START_GAIN,
    XI_NOT_HYPERBOLIC,
    XI_START_MAX,
    Boards,
    Inputs,
    LensStep,
    PatternOptions,
    RimStep,
    StartStep,
    generic_start_step,
    load_step,
    pooled_reflection,
    raw_detection_step,
    recorded_reflection,
    redetect,
    reflection_step,
    rim_step,
    start_step,
)

__all__ = [
    "CENTRAL_RMS_MAX",
    "LENS_PLANE_UNKNOWN",
    "ONE_SIDED",
    "RADIAL_START_GAIN",
    "SHAPE_REJECT_CHI2",
    "XI_NOT_HYPERBOLIC",
    "XI_START_MAX",
    "calibrate_pattern",
    "pooled_reflection",
]


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
    mirror : HyperbolicMirror, AsphericMirror or None
        The mirror (a start, its rim radius the scale: its shape is held, and estimated with
        ``refine_mirror_shape``: a hyperboloid's ``a, b``, an asphere's ``R, k`` and terms;
        an :class:`~omnicam.asphere.AsphericMirror` is started aligned, ``K`` from the
        corners' Taylor model unless given). ``None``: unknown, its
        shape from the central fit's ``xi`` and its size from the rim's image at
        ``rim_radius`` (:func:`.central.hyperbolic_start`); where that fit gives no
        hyperboloid, an even asphere from the corners' Taylor model (:mod:`.any_start`,
        :mod:`.family`).
    K : (3, 3) array_like, optional
        Start of the camera matrix (refined). Default: from the central fit of the corners
        (:func:`.central.fit_central`), else from the rim (see the module docstring).
    D : array_like, optional
        Start of the distortion (4, 5 or 8 coefficients, OpenCV's order); its free
        coefficients follow ``dist_model``.
    image_size : (int, int), optional
        ``(width, height)``; defaults to the images' size.
    image_points : sequence of (N, 1, 2) array_like or None, optional
        Corners per image in OpenCV's order (None for an image without a board); skips
        detection.
    refine_mirror_shape : bool or None
        Also estimate the given mirror's shape (``rim_radius`` fixes the scale). Default (None):
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
        One of ``"none", "k1", "k1k2", "k1k2p1p2", "k1k2p1p2k3"``, ``"radial6"`` (``k1, k2,
        k3`` and ``k4, k5, k6``: OpenCV's rational model without ``p1, p2``), ``"rational"``
        (all 8 of ``CALIB_RATIONAL_MODEL``: a wide-angle lens) or ``"auto"``: the OpenCV
        coefficients estimated (the others stay at ``D``'s values, or 0). ``"auto"`` fits
        each of :data:`.lens_model.AUTO_CANDIDATES` with its held-out check (``heldout``
        folds, 3 when 0) and keeps the simplest within :data:`.lens_model.AUTO_TOLERANCE` of
        the best median held-out RMS; ``report.lens_choice`` says which and why, and costs
        3 (1 + k) calibrations. Default ``"k1k2"``: a decentred lens (``p1, p2``) moves the
        image as a tilt of the mirror does, which the posture already holds, so the
        tangential terms mostly trade against it (see the module docstring) and predict
        held-out views worse (``benchmarks/bench_chessboard_real.py --dist-model``).
    rim_radius : float, optional
        With ``mirror=None``: the rim's radius (mirror units), which fixes the scale of the
        mirror and of the camera's position in its frame (default
        :data:`.central.NOMINAL_RIM_RADIUS`; the report then says the scale is assumed). No
        view of boards tells the scale apart but through the rig's small non-centrality, so a
        nominal scale bends the viewing directions, ``K`` and ``D`` only a little (a 22 mm rim
        at 30: 0.13 deg with 0.001 px of noise, docs/benchmarks.md); distances scale with it.
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
    camera : MisalignedCatadioptricCamera
        Its mirror a ``HyperbolicMirror`` or, for a rig no hyperboloid fits, an
        ``AsphericMirror``.
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
    options = PatternOptions(
        pattern_size=pattern_size,
        square=square_size,
        mirror=mirror,
        K=K,
        D=D,
        image_size=image_size,
        refine_mirror_shape=refine_mirror_shape,
        dist_model=dist_model,
        rim_radius=rim_radius,
        boundary_points=boundary_points,
        fit_skew=fit_skew,
        drop_outlier_views=drop_outlier_views,
        outlier_factor=outlier_factor,
        outlier_min_px=outlier_min_px,
        f_scale=f_scale,
        lens=lens,
        lens_z=lens_z,
        heldout=heldout,
    ).validated()
    inputs = load_step(images, image_points, options.image_size)
    return _calibrate(dataclasses.replace(options, image_size=inputs.image_size), inputs, progress)


@dataclasses.dataclass(frozen=True)
class _Prepared:
    """Steps 1-4, which no lens model changes: the boards, the rim, the camera's reflection
    and the start."""

    boards: Boards
    rim: RimStep
    lens: LensStep
    start: StartStep


def _calibrate(
    options: PatternOptions, inputs: Inputs, progress=None
) -> tuple[MisalignedCatadioptricCamera, PatternReport]:
    """:func:`calibrate_pattern` of validated ``options`` on the loaded ``inputs``: the steps
    of the module docstring, in order; with ``dist_model="auto"`` steps 5-9 once per
    candidate lens model (:func:`_auto_lens`)."""
    boards = raw_detection_step(inputs, options.pattern_size, progress)
    rim = rim_step(inputs.greys, options.boundary_points, options.image_size, boards.points)
    lens = reflection_step(options.lens, inputs.greys, rim, options.lens_z)
    start = start_step(boards, rim, options)
    if inputs.greys:  # the boards not found yet, in the views of the start camera
        new = redetect(inputs.greys, boards.missing(), options.pattern_size, start.camera, progress)
        boards = boards.with_found(new, "views")
    prepared = _Prepared(boards, rim, lens, start)
    for w in rim.warnings + start.warnings:
        _warnings.warn(w, RuntimeWarning, stacklevel=3)
    if options.dist_model == "auto":
        camera, report = _auto_lens(options, inputs, prepared, progress)
    else:
        camera, report = _fit(options, inputs, prepared, progress)
    # where the camera sees itself: default panoramas start above the lens
    camera = recorded_reflection(camera, lens, inputs.greys, rim, options.lens)
    return camera, dataclasses.replace(report, names=inputs.names, camera=camera)


def _fit(
    options: PatternOptions, inputs: Inputs, prepared: _Prepared, progress=None
) -> tuple[MisalignedCatadioptricCamera, PatternReport]:
    """Steps 5-9 of one lens model (``options.dist_model``) from ``prepared``."""
    boards, rim, lens, start = prepared.boards, prepared.rim, prepared.lens, prepared.start
    # the generic start's asphere is always estimated: it is a central model's extrapolation
    # and its focal length a default, which only the adjustment with both free corrects; a
    # mirror given (a data sheet of any kind) is held unless refine_mirror_shape
    aspheric = not isinstance(start.mirror, HyperbolicMirror)
    model = AdjustmentModel(
        options.free_d,
        options.n_d,
        options.fit_skew,
        options.refine_mirror_shape or (aspheric and options.mirror is None),
        lens.points,
        options.lens_z,
    )
    rounds = rounds_step(inputs.greys, boards, start, rim, model, options, progress)
    if options.mirror is None and aspheric:  # a fit worse than its central start, again
        rounds = second_start_step(rounds, start, rim, model, options, inputs.greys, progress)
    if options.mirror is None and not model.fit_shape:
        say("shape check: is the central fit's mirror shape consistent with the corners?")
        rounds = shape_check_step(rounds, start, rim, model, options)
    family = ""
    if options.mirror is None and aspheric:  # the polynomial terms the corners ask for
        rounds, family = family_step(rounds, options)
    elif options.mirror is None:  # does the hyperboloid hold, or do the corners ask for more?
        rounds, family = hyperboloid_term_check(rounds, options)
        rounds, family, start = _other_start(options, prepared, rounds, family, model, progress)
    if options.mirror is None and aspheric and options.K is None:  # other minima: f, the tilt
        first = first_fit(rounds, family, start, lens.note, options)
        fit_from = fitter(first, rim, model, options, lens.note, progress)
        fitted = other_starts_step(first, fit_from, rim, options)
        rounds, family, start = fitted.rounds, fitted.family, fitted.start
        camera, report = fitted.camera, fitted.report
    else:
        camera, report = report_step(rounds, start, lens.note, options)
    held = None
    if options.heldout:  # the same calibration on each fold's views, with these rim points
        rerun = dataclasses.replace(
            options,
            boundary_points=rim.seen,
            drop_outlier_views=False,
            lens=lens.points,
            heldout=0,
        )
        held, folds = _heldout_step(report, rerun, options.heldout)
        report = fold_check(report, camera, folds, options.image_size)[0]  # rays' uncertainty
    found = {i: how for i, how in enumerate(rounds.boards.found_by) if how is not None}
    report = dataclasses.replace(
        report,
        found_by=found,
        central=start.central,
        warnings=rim.warnings + start.warnings + report.warnings,
        heldout=held,
        family=family,
    )
    return judged(camera, report)  # the camera carries the report's verdict


#: Mei's ``xi`` from which the hyperboloid's start is at its edge (clamped to
#: :data:`XI_START_MAX`): the generic start's asphere is fitted too (:func:`_other_start`).
XI_EDGE = 1.0


def _free_count(adj, sol) -> int:
    return len(sol.x) - sum(1 for n in adj.names if n in adj.fixed)


def _other_start(options, prepared, rounds, family, model, progress=None):
    """Where Mei's ``xi`` is at a hyperboloid's edge (at least :data:`XI_EDGE`), the generic
    start's asphere (:func:`.steps.generic_start_step`, its terms by :func:`.family_step`) is
    fitted too, and taken where the same views' robust cost is lower than the hyperboloid's
    by more than chance allows (a likelihood-ratio test, its degrees of freedom the parameters
    it has more, p = 0.001): the hyperboloid's start can end in a minimum of its own there,
    the asphere's holds the hyperboloid. Returns ``(rounds, family, start)``."""
    start = prepared.start
    if start.central is None or not start.central.xi >= XI_EDGE:
        return rounds, family, start
    say("the central fit is at a hyperboloid's edge: the generic start too")
    try:
        other = generic_start_step(rounds.boards, prepared.rim, options, start.central)
        free = dataclasses.replace(model, fit_shape=True)
        alt = rounds_step((), rounds.boards, other, prepared.rim, free, options, progress)
        alt, alt_family = family_step(alt, options)
    except ValueError:
        return rounds, family, start
    fit, fit2 = rounds.fit, alt.fit
    if list(fit.used) != list(fit2.used):  # (not the same residuals: not compared)
        return rounds, family, start
    adj, sol = fit.adj, fit.sol
    if not adj.fit_shape:  # the family against the family: the hyperboloid's a, b freed
        camera, gauged = adj.to_gauge(sol.x, options.image_size)
        adj, x = shape_free(adj, sol.x, camera, gauged)
        sol = adj.solve(x, f_scale=options.f_scale, max_nfev=400)
    dof = max(_free_count(fit2.adj, fit2.sol) - _free_count(adj, sol), 1)
    sigma2 = 2.0 * fit2.sol.cost / max(len(fit2.sol.fun) - _free_count(fit2.adj, fit2.sol), 1)
    chi2 = 2.0 * (sol.cost - fit2.sol.cost) / sigma2
    test = (
        f"the generic start's asphere lowers the cost by {chi2:.2f} times the residual variance "
        f"({{}} {chi2_limit(dof):.2f}, chi-square with {dof} degree(s) of freedom at p = 0.001)"
    )
    if not chi2 > chi2_limit(dof):
        return rounds, f"{family}; {test.format('not above')}", start
    for w in other.warnings:
        _warnings.warn(w, RuntimeWarning, stacklevel=4)
    return alt, f"{alt_family}; Mei's xi at a hyperboloid's edge, {test.format('above')}", other


def _auto_lens(
    options: PatternOptions, inputs: Inputs, prepared: _Prepared, progress=None
) -> tuple[MisalignedCatadioptricCamera, PatternReport]:
    """``dist_model="auto"``: steps 5-9 with each of :data:`.lens_model.AUTO_CANDIDATES` and
    its k-fold held-out check (``heldout`` folds, :data:`.lens_model.AUTO_FOLDS` when 0), the
    model of :func:`.lens_model.choose` taken; its report holds the comparison
    (``lens_choice``) and its held-out check."""
    k = options.heldout or AUTO_FOLDS
    fits, figures, errors = {}, {}, []
    for name in AUTO_CANDIDATES:
        candidate = dataclasses.replace(options, dist_model=name, heldout=k).validated()
        with _warnings.catch_warnings(record=True) as caught:  # said for the one taken
            _warnings.simplefilter("always")
            try:
                fits[name] = (*_fit(candidate, inputs, prepared, progress), caught)
            except ValueError as e:
                figures[name] = math.inf
                errors.append(e)
                continue
        held = fits[name][1].heldout
        figures[name] = held.median if held is not None and not held.failed else math.inf
    if not fits:  # no model fits these views: the simplest's reason
        raise errors[0]
    chosen = choose({m: v for m, v in figures.items() if m in fits})
    camera, report, caught = fits[chosen]
    for w in caught:
        _warnings.warn(w.message, w.category, stacklevel=4)
    return camera, dataclasses.replace(report, lens_choice=LensChoice(chosen, figures, k))


def _heldout_step(report: PatternReport, options: PatternOptions, k: int) -> tuple[HeldOut, list]:
    """The ``k``-fold held-out check of the views used (:func:`.heldout.cross_validate`), the
    rig on each fold's training views calibrated with ``options``, its warnings (said once,
    for the whole fit) silenced; and the folds' cameras (for :func:`.fold_rays.fold_check`)."""
    cameras = []
    views = {
        i: np.asarray(report.image_points[i], np.float64).reshape(-1, 2) for i in report.view_rms
    }

    def fit(train):
        points = [views[i] for i in train]
        inputs = Inputs((), points, options.image_size, {})
        with _warnings.catch_warnings():
            _warnings.simplefilter("ignore")
            camera, _ = _calibrate(options, inputs)
        cameras.append(camera)
        return camera

    obj = object_points(options.pattern_size, options.square)
    return cross_validate(fit, views, obj, options.image_size, k), cameras
