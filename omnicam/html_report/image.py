"""The report page of a calibration from one image
(:class:`~omnicam.calibration.CalibrationReport`): the rim, Chen's four candidate postures as
panoramas, the far lines, the choice and its confidence, the posture."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np

from ..mirror import HyperbolicMirror, describe_mirror
from .page import (
    Page,
    bgr_view,
    draw_wrapped,
    panorama,
    panorama_pixels,
    posture_numbers,
    posture_sketch,
    rim_overlay,
)
from .plots import fit_width, put_label, view_colours, with_legend, with_title

__all__ = ["IMAGE_SECTIONS", "candidate_panoramas", "image_report_html"]

#: The ``id`` of every section of the one-image page, in order.
IMAGE_SECTIONS = ("summary", "rim", "candidates", "choice", "panorama", "posture")


def _candidate_camera(camera, cand):
    """``(camera, "")``: the calibrated camera with the candidate's posture, or ``(None,
    why)`` when no camera can have it."""
    try:
        return camera.replace(rvec=np.asarray(cand.rvec), tvec=np.asarray(cand.tvec)), ""
    except (ValueError, np.linalg.LinAlgError) as e:
        return None, str(e)


def candidate_panoramas(
    camera: Any, report: Any, image: np.ndarray, width: int = 560
) -> tuple[list[tuple[int, np.ndarray | None, str]], Any]:
    """``[(index, panorama or None, why not)]``: each candidate's panorama of ``image`` with
    the far lines drawn as that posture sees them (in the colours of the page's legend), on one
    elevation band (the first candidate's default); and that band's :class:`PanoramaView`
    (None when no candidate could be drawn)."""
    view = None
    out: list[tuple[int, np.ndarray | None, str]] = []
    colours = view_colours(max(len(report.far_lines), 1))
    for i, cand in enumerate(report.candidates):
        cam, why = _candidate_camera(camera, cand)
        if cam is None:
            out.append((i, None, f"no panorama: no camera can have this posture ({why})"))
            continue
        try:
            if view is None:
                pano, view = panorama(cam, image, width)
            else:
                m1, m2 = view.maps(cam)
                pano = cv2.remap(image, m1, m2, cv2.INTER_LINEAR)
        except (ValueError, np.linalg.LinAlgError) as e:
            out.append((i, None, f"no panorama: {e}"))
            continue
        for k, line in enumerate(report.far_lines):
            d = cam.unproject(np.asarray(line, np.float64).reshape(-1, 2))[1]
            q = panorama_pixels(view, d)
            draw_wrapped(pano, q, colours[k], closed=False, thickness=2)
        out.append((i, pano, ""))
    return out, view


def _caption(report, i):
    c = report.candidates[i]
    state = "physical" if c.physical else "impossible: " + "; ".join(c.reasons)
    score = "" if not np.isfinite(c.score) else f", score {c.score:.3g}"
    mark = " CHOSEN" if i == report.chosen else ""
    return f"[{i}] l={c.l} m={c.m}{score}{mark}", state


def _summary(page, camera, report, notes):
    page.section("summary", "Summary")
    page.items(notes, "note")
    tilt, az, off = posture_numbers(camera)
    K = camera.K
    m = camera.mirror
    rows = [
        ("method", "one image: rim ellipse, Chen's method, choice among 4 postures"),
        ("chosen candidate", f"{report.chosen} of {len(report.candidates)}"),
        ("confidence", f"{report.confidence:.4f}" + (" (AMBIGUOUS)" if report.ambiguous else "")),
        ("rim", f"{len(report.boundary_points)} points, RMS {report.rim_rms:.4f} px"),
        ("K", f"fx {K[0, 0]:.2f} fy {K[1, 1]:.2f} cx {K[0, 2]:.2f} cy {K[1, 2]:.2f} px"),
        (
            ("mirror a, b, rim", f"{m.a:g}, {m.b:g}, {m.rim_radius:g} mm")
            if isinstance(m, HyperbolicMirror)
            else ("mirror", describe_mirror(m) + " mm")
        ),
        ("tilt", f"{tilt:.4f} deg towards {az:.1f} deg"),
        ("centre - lower focus", f"({off[0]:.3f}, {off[1]:.3f}, {off[2]:.3f}) mm"),
        (
            "stated uncertainty",
            f"axis {report.axis_std_deg:.3g} deg, origin {report.origin_std_mm:.3g} mm; "
            f"weakest: {report.weak_direction}",
        ),
        ("far lines", f"{len(report.far_lines)}"),
        ("camera's reflection", report.lens_note),
    ]
    page.table(("figure", "value"), rows, left=2)
    if report.warnings:
        page.text("Warnings:", "warn")
        page.items([str(w) for w in report.warnings], "warn")


def _rim(page, camera, report, image):
    page.section("rim", "The rim, the far lines and the camera's reflection")
    page.figure(
        fit_width(report.draw(image), 620),
        "The calibration's own overlay: rim points (light blue), the rim as fitted (green), "
        "the far-line pixels (yellow), each physical candidate's image of the far lines or "
        "horizon (red: chosen, blue: the other).",
        jpeg=True,
    )
    img, notes = rim_overlay(camera, image, report.boundary_points)
    page.figure(
        img,
        f"The rim as fitted (RMS {report.rim_rms:.4f} px) and the camera's reflection.",
        jpeg=True,
    )
    page.items(notes)


def _candidates(page, camera, report, image):
    page.section("candidates", "The four candidate postures as panoramas")
    panos, view = candidate_panoramas(camera, report, image)
    if view is not None:
        lo, hi = view.elevation_range
        page.text(
            f"Each of Chen's postures (section 3.1) unwarps the image into an equirectangular "
            f"panorama over elevation {lo:.1f} to {hi:.1f} deg; the right one shows vertical "
            f"edges vertical and the far lines"
            + (" (drawn in colour)" if report.far_lines else "")
            + " as smooth great circles."
            + (
                ""
                if report.far_lines
                else " No far lines were given: the choice rests on the other cues (see below)."
            )
        )
    pano_h = next((p.shape[0] for _, p, _ in panos if p is not None), 120)
    for i, pano, why in panos:
        head, state = _caption(report, i)
        if pano is None:
            blank = np.full((pano_h, 560, 3), 235, np.uint8)
            for k in range(0, min(len(why), 4 * 80), 80):
                put_label(blank, why[k : k + 80], (10, 30 + 20 * k // 80), scale=0.42)
            pano = blank
        framed = with_title(pano, head)
        if i == report.chosen:
            framed = cv2.copyMakeBorder(framed, 3, 3, 3, 3, cv2.BORDER_CONSTANT, value=(0, 0, 220))
        page.figure(framed, f"{head}: {state}.", jpeg=True)
    if report.far_lines:
        cols = view_colours(len(report.far_lines))
        legend = with_legend(
            np.full((1, 560, 3), 255, np.uint8),
            [(c, "line", f"far line {k}") for k, c in enumerate(cols)]
            + [((0, 0, 220), "patch", "frame of the chosen candidate")],
        )
        page.figure(legend, "Legend of the candidate panoramas.")


def _choice(page, report):
    page.section("choice", "The choice and its confidence")
    page.text(
        f"Chosen: candidate {report.chosen}, confidence {report.confidence:.4f} "
        f"(1 - best / second best score among the physical candidates; 0 without a cue, 1 "
        f"with a single physical candidate)"
        + (
            "; AMBIGUOUS: the cues could not separate the physical postures."
            if report.ambiguous
            else "."
        )
    )
    sel = report.steps.get("selection") if isinstance(report.steps, dict) else None
    if getattr(sel, "chosen_by", "cues") == "user":
        page.text(f"Candidate {report.chosen} was chosen by the user (by eye), not by the cues.")
    cues = list(report.scores_per_cue)
    header = ["candidate", "physical"] + cues
    rows = []
    for i, c in enumerate(report.candidates):
        row = [f"{i}{' (chosen)' if i == report.chosen else ''}", "yes" if c.physical else "no"]
        for cue in cues:
            v = report.scores_per_cue[cue].get(i)
            row.append("-" if v is None or not math.isfinite(v) else f"{v:.4g}")
        rows.append(row)
    page.table(header, rows, left=2)
    if report.sigma_per_cue:
        page.text(
            "Separation of the two best: "
            + ", ".join(f"{k} {v:.1f} sigma" for k, v in report.sigma_per_cue.items())
        )
    extra = [f"refinement left out the {n}: {w}" for n, w in report.rejected_cues]
    extra += [f"refinement without the {n}: {w}" for n, w in report.skipped_cues]
    if report.accepted_cues:
        extra.append("joined the rim in the refinement: " + ", ".join(report.accepted_cues))
    page.items(extra)


def image_report_html(
    camera: Any,
    report: Any,
    image: np.ndarray,
    *,
    notes: Sequence[str] = (),
    title: str = "omnicam calibration from one image",
) -> str:
    """The report page of a calibration from one image, as one self-contained HTML string.

    Parameters
    ----------
    camera : MisalignedCatadioptricCamera
        The calibrated camera.
    report : CalibrationReport
        Its report (:func:`omnicam.calibration.calibrate`).
    image : (H, W[, 3]) uint8 ndarray
        The image calibrated from.
    notes : sequence of str
        Lines for the top of the page.
    title : str

    Returns
    -------
    str
        The page (sections :data:`IMAGE_SECTIONS`).
    """
    image = bgr_view(image, "image")
    page = Page(title)
    _summary(page, camera, report, list(notes))
    _rim(page, camera, report, image)
    _candidates(page, camera, report, image)
    _choice(page, report)
    page.section("panorama", "Panorama")
    pano, view = panorama(camera, image)
    colours = view_colours(max(len(report.far_lines), 1))
    for k, line in enumerate(report.far_lines):
        d = camera.unproject(np.asarray(line, np.float64).reshape(-1, 2))[1]
        draw_wrapped(pano, panorama_pixels(view, d), colours[k], closed=False, thickness=2)
    lo, hi = view.elevation_range
    page.figure(
        pano,
        f"The calibrated camera's equirectangular panorama, elevation {lo:.1f} to "
        f"{hi:.1f} deg, azimuth 0 at the left, turning right; the far lines in the colours of "
        f"the candidates' legend.",
        jpeg=True,
    )
    page.section("posture", "The posture")
    page.figure(posture_sketch(camera), "The mirror's tilt and the camera's offset.")
    return page.html()
