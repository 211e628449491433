"""What a calibration did: the rim, the four candidates, the choice, warnings, and an overlay."""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from ..formats.verdict import Verdict, split_findings
from ..images import to_bgr8
from ..mirror import HyperbolicMirror, describe_mirror

__all__ = ["CalibrationReport"]

# BGR colours of the overlay
_RIM = (0, 200, 0)
_POINTS = (255, 200, 0)
_LINES = (0, 220, 255)
_CHOSEN = (0, 0, 255)
_OTHER = (255, 80, 0)


@dataclasses.dataclass(frozen=True, eq=False)
class CalibrationReport:
    """Everything :func:`omnicam.calibration.calibrate` found, for inspection and logging.

    Attributes
    ----------
    conic : (3, 3) float64 ndarray
        ``Q_I`` of the rim (eq. 22) in pixels; with ``D`` in undistorted pixels ``K x_n``.
    boundary_points : (N, 2) float64 ndarray
        The boundary points the rim fit used (inliers), in image pixels as given/detected.
    rim_rms : float
        RMS orthogonal distance of those points to the fitted ellipse, px.
    candidates : list of Candidate
        The four postures of Chen's method, each with ``rvec, tvec, score, physical`` (and the
        reasons when not physical).
    chosen : int
        Index of the chosen candidate (the analytic posture; see ``refinement`` for the final).
    confidence : float
        ``1 - best / second best`` score among the physical candidates (section 3.2); 0 when the
        choice was made without far lines, 1 with a single physical candidate.
    warnings : list of str
        Everything a user should know before trusting the result.
    camera : MisalignedHyperbolicCamera
        The calibrated camera (the one returned).
    refinement : RefineResult or None
        The non-linear refinement (None with ``refine=False``).
    axis_std_deg, origin_std_mm : float
        A posteriori RMS uncertainty of the axis direction (degrees) and of the origin (length
        unit): every source's rows weighted by its observed RMS residual and the correlation
        of its residuals along the contour; first order where the cost is quadratic in the
        posture, else widened to the region of the cost itself (near alignment:
        :func:`.refine.profile_uncertainty`).
    far_lines : list of (N_i, 2) ndarray
        The far-line pixels used.
    lens_points : (M, 2) ndarray or None
        Outline pixels of the camera's own reflection (None: not used).
    lens_fit : ReflectionFit or None
        What :func:`.reflection.detect_reflection` found (``lens="auto"`` with an image).
    lens_scores : dict or None
        ``{index: RMS outline residual (px)}`` of the physical candidates (selection).
    lens_rms : float
        RMS outline residual of the returned posture, px, with the circle fitted (NaN: not used).
    lens_r, lens_z : float
        The circle coaxial with the optical axis that forms the outline (NaN: not used).
    lens_note : str
        Whether the reflection was used, and why not.
    ambiguous : bool
        The selection could not separate the physical postures (comes with a warning).
    scores_per_cue, sigma_per_cue : dict
        Each cue's score per candidate, and how many standard deviations it separates the two
        best (:class:`.selection.Selection`).
    accepted_cues : tuple of str
        The cues that joined the rim in the refinement.
    rejected_cues : tuple of (str, str)
        The cues left out, with the reason (how much they disagreed).
    skipped_cues : tuple of (str, str)
        Cues not tried in the refinement, with the reason (not a disagreement).
    weak_direction : str
        The least determined combination of the posture in words.
    steps : dict
        The typed results of every step (``rim``, ``reflection``, ``candidates``,
        ``selection``, ``refinement``).
    plausibility : tuple of PlausibilityWarning
        The implausible findings (:mod:`.plausibility`), also in ``warnings``; empty when the
        result is plausible or was not checked.
    """

    conic: np.ndarray
    boundary_points: np.ndarray
    rim_rms: float
    candidates: list
    chosen: int
    confidence: float
    warnings: list
    camera: object
    refinement: object = None
    axis_std_deg: float = math.nan
    origin_std_mm: float = math.nan
    far_lines: list = dataclasses.field(default_factory=list)
    lens_points: object = None
    lens_fit: object = None
    lens_scores: object = None
    lens_rms: float = math.nan
    lens_r: float = math.nan
    lens_z: float = math.nan
    lens_note: str = "not used"
    ambiguous: bool = False
    scores_per_cue: dict = dataclasses.field(default_factory=dict)
    sigma_per_cue: dict = dataclasses.field(default_factory=dict)
    accepted_cues: tuple = ()
    rejected_cues: tuple = ()
    skipped_cues: tuple = ()
    weak_direction: str = "unknown"
    steps: dict = dataclasses.field(default_factory=dict)
    plausibility: tuple = ()

    @classmethod
    def from_steps(cls, rim, cue, cands, sel, ref, warnings, camera, far_lines):
        """The report of :func:`omnicam.calibration.calibrate` from its steps' results."""
        circ = ref.circle
        note = cue.note
        if cue.used and circ is not None:
            note += f", circle r {circ.r:.3f} at z {circ.z:.3f}, RMS {circ.rms:.3f} px; " + (
                "joined the refinement"
                if "reflection" in ref.accepted_cues
                else "not in the refinement"
            )
        return cls(
            conic=np.asarray(rim.fit.conic, np.float64),
            boundary_points=rim.seen,
            rim_rms=float(rim.fit.rms),
            candidates=list(sel.candidates),
            chosen=sel.chosen,
            confidence=float(sel.confidence),
            warnings=warnings,
            camera=camera,
            refinement=ref.result,
            axis_std_deg=ref.uncertainty.axis_std_deg,
            origin_std_mm=ref.uncertainty.origin_std,
            far_lines=far_lines,
            lens_points=cue.points,
            lens_fit=cue.fit,
            lens_scores=sel.scores_per_cue.get("reflection rms px"),
            lens_rms=circ.rms if circ is not None else math.nan,
            lens_r=circ.r if circ is not None else math.nan,
            lens_z=circ.z if circ is not None else math.nan,
            lens_note=note,
            ambiguous=sel.ambiguous,
            scores_per_cue=sel.scores_per_cue,
            sigma_per_cue=sel.sigma,
            accepted_cues=ref.accepted_cues,
            rejected_cues=ref.rejected_cues,
            skipped_cues=ref.skipped_cues,
            weak_direction=ref.uncertainty.describe(),
            steps={
                "rim": rim,
                "reflection": cue,
                "candidates": cands,
                "selection": sel,
                "refinement": ref,
            },
        )

    @property
    def lens_used(self):
        """Whether the camera's reflection took part in the selection and refinement."""
        return self.lens_points is not None

    @property
    def rvec(self):
        """(3,) final mirror rotation (after refinement if any)."""
        return self.camera.rvec

    @property
    def tvec(self):
        """(3,) final mirror origin in the camera frame."""
        return self.camera.tvec

    @property
    def physical(self):
        """Indices of the physically possible candidates."""
        return [i for i, c in enumerate(self.candidates) if c.physical]

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

        ``K_source`` defaults to ``"given"`` (:func:`~omnicam.calibrate` takes ``K``);
        ``implausible`` to :attr:`plausibility`, whose findings are left out of ``warnings``.
        ``K_file``, ``K_note`` and ``forced`` are the verdict's attributes.
        """
        warnings, implausible = split_findings(
            self.warnings, self.plausibility if implausible is None else implausible
        )
        return Verdict(
            method="image",
            K_source=K_source or "given",
            K_file=K_file,
            K_note=K_note,
            forced=forced,
            confidence=self.confidence,
            ambiguous=self.ambiguous,
            axis_std_deg=self.axis_std_deg,
            origin_std_mm=self.origin_std_mm,
            rim_rms_px=self.rim_rms,
            warnings=warnings,
            implausible=implausible,
        )

    def _uncertainty_kind(self):
        """How the stated uncertainty was found, in words."""
        ref = self.steps.get("refinement")
        unc = getattr(ref, "uncertainty", None)
        if unc is None or not unc.widened:
            return "first order"
        return (
            f"from the cost itself, where the first order said "
            f"{unc.first_order_axis_std_deg:.3g} deg on the axis"
        )

    def lead(self, verdict: Verdict | None = None, refused: bool = False) -> list[str]:
        """The report's first lines: what users use, the uncertainty of the viewing directions
        (the mirror axis's and the camera centre's, which move every ray), and the verdict
        (``verdict``, default :meth:`verdict`; ``refused``: the command line refuses it)."""
        v = self.verdict() if verdict is None else verdict
        return [
            f"viewing directions: the mirror axis is known to {self.axis_std_deg:.3g} deg, the "
            f"camera centre to {self.origin_std_mm:.3g} (RMS, {self._uncertainty_kind()}); one "
            f"image has no held-out check",
            f"verdict: {v.status(refused)}",
        ]

    def summary(self, verdict=None, refused=False):
        """A readable multi-line summary (what the CLI prints), :meth:`lead` first."""
        cam = self.camera
        axis = cam.R[:, 2]
        tilt = math.degrees(math.atan2(math.hypot(axis[0], axis[1]), axis[2]))
        lines = [
            "omnicam mirror posture calibration",
            *(f"  {ln}" for ln in self.lead(verdict, refused)),
            _mirror_line(cam.mirror),
            f"  rim: {len(self.boundary_points)} boundary points, RMS {self.rim_rms:.4f} px",
            f"  rvec = [{', '.join(f'{v:.9f}' for v in cam.rvec)}]",
            f"  tvec = [{', '.join(f'{v:.6f}' for v in cam.tvec)}]",
            f"  mirror axis tilt from the optical axis: {tilt:.4f} deg; camera centre in the "
            f"mirror frame: [{', '.join(f'{v:.4f}' for v in cam.camera_center)}]",
            f"  RMS uncertainty (a posteriori, {self._uncertainty_kind()}; rim"
            f"{''.join(' + ' + c for c in self.accepted_cues)}): axis {self.axis_std_deg:.3g} "
            f"deg, origin {self.origin_std_mm:.3g}; weakest: {self.weak_direction}",
            f"  camera reflection (lens): {self.lens_note}",
            f"  candidates (Chen's method, section 3.1; score of eq. 31 with "
            f"{len(self.far_lines)} far line(s)"
            + (", lens outline RMS in px" if self.lens_scores else "")
            + "):",
        ]
        for i, c in enumerate(self.candidates):
            mark = "*" if i == self.chosen else " "
            state = "physical" if c.physical else "impossible: " + "; ".join(c.reasons)
            score = "-" if not np.isfinite(c.score) else f"{c.score:.3e}"
            if self.lens_scores and i in self.lens_scores:
                score += f" lens {self.lens_scores[i]:.3f}"
            if i in self.scores_per_cue.get("self-reflection px", {}):
                score += f" self-px {self.scores_per_cue['self-reflection px'][i]:.1f}"
            lines.append(
                f"   {mark}[{i}] l={c.l} m={c.m} score {score:>10}  "
                f"tvec [{', '.join(f'{v:.4f}' for v in c.tvec)}]  {state}"
            )
        sep = ", ".join(f"{k} {v:.1f} sigma" for k, v in self.sigma_per_cue.items())
        lines.append(
            f"  chosen: {self.chosen}, confidence {self.confidence:.4f}"
            + (f" ({sep})" if sep else "")
            + (" AMBIGUOUS" if self.ambiguous else "")
        )
        if self.refinement is not None:
            r = self.refinement
            kept = "accepted" if r.accepted else "kept the analytic posture"
            lines.append(
                f"  refinement: {kept}"
                f" (cost {r.cost_initial:.4g} -> {r.cost_final:.4g} px^2, rim RMS "
                f"{r.rim_rms:.4f} px"
                + ("" if not np.isfinite(r.line_rms) else f", far-line RMS {r.line_rms:.4f} px")
                + (
                    ""
                    if not np.isfinite(r.reflection_rms)
                    else f", lens RMS {r.reflection_rms:.4f} px"
                )
                + ")"
            )
            for name, why in self.rejected_cues:
                lines.append(f"  refinement left out the {name}: {why}")
            for name, why in self.skipped_cues:
                lines.append(f"  refinement without the {name}: {why}")
        else:
            lines.append("  refinement: off")
        if self.warnings:
            lines.append("  WARNINGS:")
            lines.extend(f"   - {w}" for w in self.warnings)
        else:
            lines.append("  no warnings")
        return "\n".join(lines)

    def __str__(self):
        return self.summary()

    def __repr__(self):
        return (
            f"CalibrationReport(chosen={self.chosen}, confidence={self.confidence:.4f}, "
            f"rim_rms={self.rim_rms:.4f}, warnings={len(self.warnings)})"
        )

    # -- overlay --------------------------------------------------------------------------
    def draw(self, image=None):
        """An overlay to inspect the calibration.

        Draws the boundary points (light blue dots), the rim of the calibrated camera (green),
        the outline points of the camera's reflection when the lens was used (light blue),
        the far-line pixels (yellow), and for each physical candidate the image of the far
        lines it implies (the great circle of the plane of its rays, eq. 31) or, without far
        lines, its horizon (elevation 0): red for the chosen one, blue for the other. Text at
        the top left gives the choice and the confidence; the legend at the bottom left names
        what is drawn (the curves as far lines or horizons), both on a darkened box so that
        they read on bright images too.

        Parameters
        ----------
        image : ndarray or None
            Grey or BGR, uint8, uint16 or float; None draws on black of ``camera.image_size``.

        Returns
        -------
        overlay : (H, W, 3) uint8 ndarray
        """
        if image is not None:
            canvas = to_bgr8(image)
        elif self.camera.image_size is None:
            raise ValueError("draw() needs an image when the camera has no image_size")
        else:
            w, h = self.camera.image_size
            canvas = np.zeros((h, w, 3), np.uint8)
        h, w = canvas.shape[:2]
        scale = max(1.0, min(w, h) / 500.0)
        thick = max(1, int(round(scale)))
        shift = 4
        f = float(1 << shift)

        def poly(pts, colour, closed=False):
            """Draw the finite runs of ``pts``; whether a point of them is in the image."""
            pts = np.asarray(pts, np.float64).reshape(-1, 2)
            ok = np.isfinite(pts).all(axis=1)
            seen = ok.copy()
            seen[ok] = (np.abs(pts[ok] - [(w - 1) / 2, (h - 1) / 2]) <= [w / 2, h / 2]).all(axis=1)
            # split at invisible samples so a curve never jumps across the image
            runs = np.split(np.arange(len(pts)), np.flatnonzero(np.diff(ok.astype(int)) != 0) + 1)
            visible = False
            for run in runs:
                if len(run) >= 2 and ok[run[0]]:
                    visible = visible or bool(seen[run].any())
                    p = np.round(pts[run] * f).astype(np.int32).reshape(-1, 1, 2)
                    cv2.polylines(
                        canvas,
                        [p],
                        closed and len(run) == len(pts),
                        colour,
                        thick,
                        cv2.LINE_AA,
                        shift,
                    )
            return visible

        for p in self.boundary_points[:: max(1, len(self.boundary_points) // 720)]:
            if np.isfinite(p).all():
                cv2.circle(
                    canvas,
                    (int(round(p[0] * f)), int(round(p[1] * f))),
                    int(1.5 * scale * f),
                    _POINTS,
                    -1,
                    cv2.LINE_AA,
                    shift,
                )
        poly(self.camera.rim_image_points(720), _RIM, closed=True)
        if self.lens_points is not None:
            for p in self.lens_points:
                cv2.circle(
                    canvas,
                    (int(round(p[0] * f)), int(round(p[1] * f))),
                    int(scale * f),
                    _POINTS,
                    -1,
                    cv2.LINE_AA,
                    shift,
                )
        for line in self.far_lines:
            for p in line:
                cv2.circle(
                    canvas,
                    (int(round(p[0] * f)), int(round(p[1] * f))),
                    int(2 * scale * f),
                    _LINES,
                    thick,
                    cv2.LINE_AA,
                    shift,
                )
        drawn = set()  # the legend names what is drawn, nothing else
        for i in self.physical:
            cand = self.candidates[i]
            cam = (
                self.camera
                if i == self.chosen
                else self.camera.replace(rvec=cand.rvec, tvec=cand.tvec)
            )
            colour = _CHOSEN if i == self.chosen else _OTHER
            for normal in _curve_normals(cam, self.far_lines):
                if poly(_great_circle_pixels(cam, normal), colour):
                    drawn.add(colour)
        text = f"chosen {self.chosen}  confidence {self.confidence:.3f}"
        if self.warnings:
            text += f"  ({len(self.warnings)} warning(s))"
        _text_box(canvas, [((255, 255, 255), text)], scale, thick, top=True)
        # without far lines the curves are each posture's horizon (elevation 0)
        curve = "far lines" if self.far_lines else "horizon"
        points = "rim and reflection points" if self.lens_points is not None else "rim points"
        entries = [(_RIM, "fitted rim"), (_POINTS, points)]
        if self.far_lines:
            entries.append((_LINES, "far-line pixels"))
        if _CHOSEN in drawn:
            entries.append((_CHOSEN, f"{curve} under the chosen posture"))
        if _OTHER in drawn:
            entries.append((_OTHER, f"{curve} under the other posture"))
        _text_box(canvas, entries, scale, thick, top=False, swatch=True)
        return canvas


def _mirror_line(mirror) -> str:
    """The summary's line on the mirror assumed."""
    if isinstance(mirror, HyperbolicMirror):
        return (
            f"  mirror: assumed the hyperboloid a {mirror.a:g}, b {mirror.b:g}, rim "
            f"{mirror.rim_radius:g} (one image does not tell a paraboloid or a sphere "
            f"from it; far lines that come out bowed do)"
        )
    return (
        f"  mirror: assumed the {describe_mirror(mirror)} (one image does not tell another "
        f"profile from it; far lines that come out bowed do)"
    )


def _text_box(canvas, entries, scale, thick, top, swatch=False):
    """Lines of text on a darkened box, readable on any image: top left, or bottom left.

    ``entries`` are ``(colour, text)``; with ``swatch`` each line gets a square of its colour
    and white text (the legend of :meth:`CalibrationReport.draw`), else the text is in its
    colour.
    """
    h, w = canvas.shape[:2]
    font, size = cv2.FONT_HERSHEY_SIMPLEX, (0.4 if swatch else 0.5) * scale
    weight = max(1, thick - 1) if swatch else thick
    pad, step = int(4 * scale), int(16 * scale)
    indent = int(14 * scale) if swatch else 0
    widths = [cv2.getTextSize(t, font, size, weight)[0][0] for _, t in entries]
    box_w = indent + max(widths) + 2 * pad
    box_h = step * len(entries) + pad
    x0 = int(4 * scale)
    y0 = int(4 * scale) if top else h - int(4 * scale) - box_h
    x1, y1 = min(w, x0 + box_w), min(h, y0 + box_h)
    region = canvas[max(0, y0) : y1, max(0, x0) : x1]
    region[:] = (region.astype(np.float32) * 0.25).astype(np.uint8)  # darkened, not hidden
    for k, (colour, label) in enumerate(entries):
        y = y0 + pad + (k + 1) * step - int(4 * scale)
        x = x0 + pad
        if swatch:
            cv2.rectangle(canvas, (x, y - int(9 * scale)), (x + int(9 * scale), y), colour, -1)
        cv2.putText(
            canvas,
            label,
            (x + indent, y),
            font,
            size,
            (255, 255, 255) if swatch else colour,
            weight,
            cv2.LINE_AA,
        )


def _curve_normals(cam, far_lines):
    """Plane normals of the rays of each far line under ``cam`` (eq. 31), or the horizon's."""
    if not far_lines:
        return [np.array([0.0, 0.0, 1.0])]
    out = []
    for line in far_lines:
        _, V = cam.unproject(line)
        V = V[np.isfinite(V).all(axis=1)]
        if len(V) >= 2:
            out.append(np.linalg.eigh(V.T @ V)[1][:, 0])
    return out


def _great_circle_pixels(cam, normal, n=720):
    a = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(normal, a)
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    t = np.linspace(0.0, 2 * np.pi, n)
    return cam.project_directions(np.outer(np.cos(t), u) + np.outer(np.sin(t), v))
