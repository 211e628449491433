"""The report of a chessboard calibration: what was fitted, how well, and what it predicts."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import cv2
import numpy as np

from ..calibration.chen import rim_conic
from ..calibration.plausibility import (
    DEFAULT_MAX_OFFSET_MM,
    DEFAULT_MAX_TILT_DEG,
    check_plausibility,
)
from ..formats.verdict import Verdict, split_findings
from ..images import to_bgr8
from .heldout import HeldOut
from .lens_model import LensChoice, coefficient_lines

__all__ = ["ONE_SIDED", "PatternReport"]

#: The start of the warning that the views cannot tell the principal point from the tilt (an
#: implausible finding: the command line refuses such a calibration unless forced).
ONE_SIDED = "all boards are on one side of the mirror (an azimuth gap over 180 deg)"
#: The starts of the findings that the data cannot fix by nature when the mirror is not given
#: (its scale without a rim radius; its shape, which trades against fx): notes, not alarms.
_SCALE_ASSUMED = "the mirror's scale is assumed"
_SHAPE_HELD = "the mirror's shape is the central fit's"
#: The start of the note that the rays' stated uncertainty is the held-out check's folds'
#: (:func:`.fold_rays.fold_check`): the data's own figure, stated, not doubted.
FOLDS_STATED = "the viewing directions' uncertainty is the held-out check's"
#: The start of the note that the rays' stated uncertainty is the spread of the fits as good
#: from other starts (:func:`.other_starts.other_starts_step`): stated, not doubted.
STARTS_STATED = "the viewing directions' uncertainty is the spread of the fits from other starts"
_BY_NATURE = (
    _SCALE_ASSUMED,
    _SHAPE_HELD,
    "the mirror's a, b were estimated",
    "the focal length is weakly determined",
)


@dataclasses.dataclass(frozen=True, eq=False)
class PatternReport:
    """Outcome of :func:`calibrate_pattern`.

    Attributes
    ----------
    rms : float
        RMS corner reprojection error over the views used, px.
    view_rms : dict
        ``{image index: RMS px}`` of every view used.
    corners_used : dict
        ``{image index: number of corners}`` of every view used.
    board_poses : dict
        ``{image index: (rvec_b, tvec_b)}``, ``X_mirror = R(rvec_b) X_board + tvec_b``.
    image_points : list
        Per input image the ``(N, 1, 2)`` float32 corners detected or given (None if none).
    reprojected : dict
        ``{image index: (N, 1, 2) float64}`` corners reprojected by the calibrated camera.
    rim_points : (M, 2) float64 ndarray
        The rim points used.
    rim_rms : float
        RMS distance of the rim points to the calibrated rim image, px.
    std : dict
        Standard deviations (1 sigma, from ``(J^T J)^-1 J^T S J (J^T J)^-1``, ``S`` each row's
        variance estimated from the residuals of its group: the corners, the rim, the
        outline): ``fx, fy, cx, cy`` (px), ``skew`` if estimated, ``k1``... of the free
        distortion coefficients, ``axis_deg`` (RMS angle of the mirror axis), ``origin`` (RMS
        distance of the camera centre in the mirror frame, mirror units), ``a, b`` with
        ``refine_mirror_shape``.
    warnings : tuple of str
    dropped : dict
        ``{image index: reason}`` of the views left out.
    nfev : int
        Residual evaluations of the last adjustment.
    camera : MisalignedHyperbolicCamera
    start : MisalignedHyperbolicCamera
        The start of the adjustment (K from the rim, posture from Chen's method).
    lens_rms : float
        RMS outline residual of the camera's reflection, px (NaN when not used).
    lens_note : str
        Whether and how the camera's reflection was used.
    central : CentralFit or None
        The central start (:func:`.central.fit_central` of the corners found on the raw
        images), or None when it could not be made.
    found_by : dict
        ``{image index: how its corners were found}``: ``"given"``, one of
        :data:`.detect.METHODS` (``"raw"``, ``"raw-sb"``: OpenCV's detectors on the
        image as it is; ``"views"``: in the start camera's unwarped views) or ``"views (fitted
        camera)"`` (a later round, in the views of the camera fitted to the boards found
        before).
    ray_std_deg : (float, float)
        Standard deviation of the viewing directions over the mirror's image (deg; median,
        worst), the parameters' covariance propagated to the rays (what panoramas use): small
        even when ``a, b`` or ``fx`` are not.
    names : dict
        ``{image index: file name}`` of the images given as paths (the table shows them).
    heldout : HeldOut or None
        With ``calibrate_pattern(heldout=k)``, the k-fold held-out corner RMS of the views
        used (:mod:`.heldout`), ``cv2.omnidir``'s on the same folds beside it.
    plausibility : tuple of PlausibilityWarning
        The implausible findings of the single-image route's checks (tilt, offset, ``K``
        against the image, with its default limits; :meth:`with_limits` checks at others),
        also in ``warnings``. :attr:`implausible` adds boards all on one side.
    dist_model : str
        The lens model fitted (a key of :data:`.adjustment.DIST_MODELS`).
    lens_choice : LensChoice or None
        With ``dist_model="auto"``, the candidates' held-out figures and the model taken
        (:mod:`.lens_model`).
    family : str
        With the mirror unknown, which family the data chose for it and why (the
        likelihood-ratio tests of :mod:`.family`); "" with a mirror given.
    """

    rms: float
    view_rms: dict
    corners_used: dict
    board_poses: dict
    image_points: list
    reprojected: dict
    rim_points: np.ndarray
    rim_rms: float
    std: dict
    warnings: tuple
    dropped: dict
    nfev: int
    # of the camera class calibrate_pattern was given (this package sits below the camera's)
    camera: Any
    start: Any
    lens_rms: float = math.nan
    lens_note: str = ""
    found_by: dict = dataclasses.field(default_factory=dict)
    central: object = None
    heldout: HeldOut | None = None
    ray_std_deg: tuple = (math.nan, math.nan)
    names: dict = dataclasses.field(default_factory=dict)
    plausibility: tuple = ()
    dist_model: str = ""
    lens_choice: LensChoice | None = None
    family: str = ""

    def lens_lines(self) -> list[str]:
        """The lens model: with ``"auto"`` which model and why (:meth:`.LensChoice.summary`),
        then each estimated coefficient with its standard deviation and whether these views
        determine it (:func:`.lens_model.coefficient_lines`)."""
        lines = [] if self.lens_choice is None else [self.lens_choice.summary()]
        if self.dist_model and self.camera is not None:
            coeffs = coefficient_lines(self.camera.D, self.std, self.dist_model)
            if coeffs:
                lines.append(f"distortion ({self.dist_model}): " + "; ".join(coeffs))
        return lines

    # -- what the warnings say: implausible, by nature, or alarms ------------------------------
    @property
    def implausible(self) -> tuple[str, ...]:
        """The implausible findings: :attr:`plausibility` (the single-image route's checks,
        :func:`omnicam.calibration.plausibility.check_plausibility`, with the same limits) and
        boards all on one side of the mirror. ``omnicam calibrate`` refuses on them without
        ``--force``, as it refuses an implausible calibration from one image."""
        found = [str(w) for w in self.plausibility]
        found += [w for w in self.warnings if w.startswith(ONE_SIDED) and w not in found]
        return tuple(found)

    @property
    def mirror_unknown(self) -> bool:
        """The mirror was not given: its scale (without ``rim_radius``) or its shape is
        unknown, which no view of boards can fix."""
        return any(w.startswith((_SCALE_ASSUMED, _SHAPE_HELD)) for w in self.warnings)

    @property
    def notes(self) -> tuple[str, ...]:
        """What the data cannot fix by nature (with the mirror unknown: its scale, its shape
        and ``fx``, which trades against the shape), and that the rays' uncertainty is the
        held-out check's folds' (:data:`FOLDS_STATED`) or the other starts' fits'
        (:data:`STARTS_STATED`): stated, not doubted (:meth:`verdict` records them as
        ``notes``)."""
        folds = tuple(w for w in self.warnings if w.startswith((FOLDS_STATED, STARTS_STATED)))
        if not self.mirror_unknown:
            return folds
        return tuple(w for w in self.warnings if w.startswith(_BY_NATURE)) + folds

    @property
    def alarms(self) -> tuple[str, ...]:
        """The warnings that say something may be wrong: the others than :attr:`notes` and
        :attr:`implausible`."""
        skip = set(self.notes) | set(self.implausible)
        return tuple(w for w in self.warnings if w not in skip)

    def undetermined(self) -> str:
        """One neutral line on what these boards cannot fix by nature ("" with the mirror
        given): ``fx`` against the mirror's size, and the scale without a rim radius."""
        if not self.mirror_unknown:
            return ""
        scale = any(w.startswith(_SCALE_ASSUMED) for w in self.warnings)
        return (
            "by nature, boards alone do not fix fx and the mirror's size separately, only "
            "their ratio (the viewing directions do not depend on it)"
            + ("; nor the scale, without rim_radius (the rim's radius is nominal)" if scale else "")
        )

    def with_limits(
        self,
        max_tilt_deg: float = DEFAULT_MAX_TILT_DEG,
        max_offset_mm: float = DEFAULT_MAX_OFFSET_MM,
    ) -> PatternReport:
        """The report with the plausibility checks made at other limits (``omnicam calibrate
        --max-tilt, --max-offset``; :func:`calibrate_pattern` checks at the defaults, as the
        single-image route does): :attr:`plausibility` and their warnings replaced."""
        cam = self.camera
        size = cam.image_size
        found = tuple(
            check_plausibility(
                cam,
                rim_conic(cam.K, cam.R, cam.tvec, cam.mirror),
                size,
                max_tilt_deg=max_tilt_deg,
                max_offset_mm=max_offset_mm,
            )
        )
        old = {str(w) for w in self.plausibility}
        kept = [w for w in self.warnings if w not in old]
        return dataclasses.replace(
            self, plausibility=found, warnings=tuple(kept) + tuple(str(w) for w in found)
        )

    # -- what users use first ----------------------------------------------------------------
    def lead(self, verdict: Verdict | None = None, refused: bool = False) -> list[str]:
        """The report's first lines: the viewing directions' uncertainty over the field, the
        held-out error beside cv2.omnidir's (when checked), the verdict (``verdict``, default
        :meth:`verdict`; ``refused``: the command line refuses it), the mirror's family the
        data chose and what the boards cannot fix by nature."""
        v = self.verdict() if verdict is None else verdict
        med, worst = self.ray_std_deg
        lines = [
            f"viewing directions known to {med:.3f} deg (median over the mirror's image, worst "
            f"{worst:.3f} deg; 1 sigma)"
        ]
        if self.heldout is not None:  # cv2.omnidir's on the same folds beside it
            lines.append(self.heldout.summary())
        lines.append(f"verdict: {v.status(refused)}")
        if self.family:
            lines.append(self.family)
        undetermined = self.undetermined()
        if undetermined:
            lines.append(undetermined)
        return lines

    def summary(self) -> str:
        """A readable multi-line summary: :meth:`lead`, the per-view table, the fitted values,
        the notes and the warnings (``str(report)``)."""
        cam = self.camera
        std = self.std or {}
        lines = ["omnicam chessboard calibration", *(f"  {ln}" for ln in self.lead())]
        lines.append(self.table())
        lines.append(
            f"  RMS {self.rms:.3f} px over {len(self.view_rms)} views; rim RMS "
            f"{self.rim_rms:.3f} px; K fx {cam.K[0, 0]:.2f} fy {cam.K[1, 1]:.2f} cx "
            f"{cam.K[0, 2]:.2f} cy {cam.K[1, 2]:.2f}; axis std {std.get('axis_deg', math.nan):.3f}"
            f" deg, origin std {std.get('origin', math.nan):.3f}"
        )
        for title, texts in (
            ("implausible", self.implausible),
            ("warnings", self.alarms),
            ("by nature", self.notes),
        ):
            if texts:
                lines.append(f"  {title}:")
                lines.extend(f"   - {w}" for w in texts)
        return "\n".join(lines)

    __str__ = summary

    def table(self, names=None) -> str:
        """The per-view table as text: image, corners, RMS px, distance and elevation of the
        board and how it was found, or why the view was dropped. ``names``: a sequence of the
        images' names (default :attr:`names`, else the indices)."""
        names = dict(enumerate(names)) if names is not None else self.names
        rows = sorted(set(self.view_rms) | set(self.dropped))
        label = {i: str(names.get(i, i)) for i in rows}
        wide = max([5] + [len(v) for v in label.values()])
        lines = [
            f"{'image':>{wide}} {'corners':>7} {'rms px':>8} {'dist':>8} {'elev deg':>8}  found by"
        ]
        for i in rows:
            if i in self.view_rms:
                t = np.asarray(self.board_poses[i][1])
                el = math.degrees(math.atan2(t[2], math.hypot(t[0], t[1])))
                lines.append(
                    f"{label[i]:>{wide}} {self.corners_used[i]:>7} {self.view_rms[i]:>8.3f} "
                    f"{np.linalg.norm(t):>8.1f} {el:>8.1f}  {self.found_by.get(i, '-')}"
                )
            else:
                lines.append(f"{label[i]:>{wide}} {'-':>7} {'-':>8}   dropped: {self.dropped[i]}")
        return "\n".join(lines)

    def draw(self, image, index) -> np.ndarray:
        """BGR overlay of view ``index``: detected corners (green circles) and reprojected ones
        (red crosses), with the rim (blue)."""
        img = to_bgr8(image)
        rim = self.camera.rim_image_points(720)
        if np.isfinite(rim).all():
            cv2.polylines(
                img, [np.round(rim * 16).astype(np.int32)], True, (255, 0, 0), 1, cv2.LINE_AA, 4
            )
        det = self.image_points[index]
        if det is not None:
            for p in np.asarray(det).reshape(-1, 2):
                cv2.circle(
                    img,
                    tuple(int(v) for v in np.round(p * 16)),
                    4 * 16,
                    (0, 200, 0),
                    1,
                    cv2.LINE_AA,
                    4,
                )
        rep = self.reprojected.get(index)
        if rep is not None:
            for p in np.asarray(rep).reshape(-1, 2):
                if np.isfinite(p).all():
                    cv2.drawMarker(
                        img, tuple(round(v) for v in p), (0, 0, 255), cv2.MARKER_CROSS, 6, 1
                    )
        return img

    def verdict(
        self,
        *,
        K_source: str | None = None,
        K_file: str | None = None,
        K_note: str = "",
        forced: bool = False,
        implausible=None,
    ) -> Verdict:
        """How far to trust this calibration, as its file records it (:class:`omnicam.Verdict`).

        ``K_source`` defaults to ``"chessboard"`` (``K`` is fitted to the boards);
        ``implausible``: the findings a refusal rests on (left out of ``warnings``), by
        default :attr:`implausible`; :attr:`notes` (by nature) are recorded apart.
        ``K_file``, ``K_note`` and ``forced`` are the verdict's attributes.
        """
        implausible = self.implausible if implausible is None else implausible
        warnings, implausible = split_findings(self.warnings, implausible)
        notes = tuple(w for w in self.notes if w not in implausible)
        warnings = tuple(w for w in warnings if w not in notes)
        std = self.std or {}
        held = self.heldout
        return Verdict(
            method="chessboard",
            K_source=K_source or "chessboard",
            K_file=K_file,
            K_note=K_note,
            forced=forced,
            axis_std_deg=std.get("axis_deg"),
            origin_std_mm=std.get("origin"),
            rim_rms_px=self.rim_rms,
            rms_px=self.rms,
            heldout_median_px=None if held is None else held.median,
            heldout_max_px=None if held is None else held.max,
            heldout_folds=None if held is None else held.folds,
            ray_std_deg=tuple(self.ray_std_deg),
            warnings=warnings,
            implausible=implausible,
            notes=notes,
        )
