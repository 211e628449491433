"""The report page of a chessboard calibration (:class:`~omnicam.chessboard.PatternReport`)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
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
    panorama_view,
    posture_numbers,
    posture_sketch,
    residual_arrow,
    rim_overlay,
)
from .plots import Axes, fit_width, nice_ticks, put_label, view_colours, with_legend, with_title

__all__ = ["PATTERN_SECTIONS", "pattern_report_html"]

#: The ``id`` of every section of the chessboard page, in order.
PATTERN_SECTIONS = (
    "summary",
    "views",
    "coverage",
    "residuals",
    "rim",
    "uncertainty",
    "panorama",
    "posture",
)

_EMPTY = (40, 40, 220)  # BGR: where no corner was seen
_OUTSIDE = (200, 200, 200)


def _pts(a):
    return None if a is None else np.asarray(a, np.float64).reshape(-1, 2)


def _outline_index(pattern_size, n):
    """Indices of the border of a ``cols x rows`` corner grid, in order around it (or None)."""
    if pattern_size is None:
        return None
    cols, rows = (int(v) for v in pattern_size)
    if cols * rows != n:
        return None
    g = np.arange(n).reshape(rows, cols)
    return np.concatenate([g[0, :], g[1:, -1], g[-1, -2::-1], g[-2:0:-1, 0]])


def _outline(points, order):
    """The board's outline in pixels: the grid's border, else the convex hull."""
    p = points[np.isfinite(points).all(axis=1)]
    if order is not None and len(p) == len(points):
        return points[order]
    if len(p) < 3:
        return p
    return cv2.convexHull(p.astype(np.float32)).reshape(-1, 2).astype(np.float64)


def _views(report):
    """The views used, in order."""
    return sorted(report.view_rms)


def _name(report, names, i):
    if names is not None and i < len(names):
        return str(names[i])
    return str(report.names.get(i, i)) if getattr(report, "names", None) else str(i)


# -- the sections ------------------------------------------------------------------------------
def _summary(page, camera, report, verdict, notes, terms):
    page.section("summary", "Summary")
    # what users use first: the rays' uncertainty, the held-out check, the verdict
    lead = report.lead(verdict) if hasattr(report, "lead") else []
    page.items([terms(line) for line in lead], "lead")
    page.items(notes, "note")
    K = camera.K
    std = report.std or {}
    m = camera.mirror

    def pm(key, fmt="{:.3f}"):
        v = std.get(key)
        return "" if v is None or not math.isfinite(v) else " ± " + fmt.format(v)

    rows = [
        ("views used", f"{len(report.view_rms)} (dropped {len(report.dropped)})"),
        ("corner RMS", f"{report.rms:.3f} px"),
        ("rim RMS", f"{report.rim_rms:.3f} px"),
        ("fx, fy", f"{K[0, 0]:.2f}{pm('fx', '{:.2f}')}, {K[1, 1]:.2f}{pm('fy', '{:.2f}')} px"),
        ("cx, cy", f"{K[0, 2]:.2f}{pm('cx', '{:.2f}')}, {K[1, 2]:.2f}{pm('cy', '{:.2f}')} px"),
        ("D", "none" if camera.D is None else " ".join(f"{v:.4g}" for v in camera.D.ravel())),
        (
            ("mirror a, b, rim", f"{m.a:.3f}{pm('a')}, {m.b:.3f}{pm('b')}, {m.rim_radius:g} mm")
            if isinstance(m, HyperbolicMirror)
            else ("mirror", describe_mirror(m) + " mm")
        ),
        ("mirror axis std", f"{std['axis_deg']:.3f} deg" if "axis_deg" in std else "not stated"),
        (
            "camera centre std",
            f"{std['origin']:.3f} mm" if "origin" in std else "not stated",
        ),
    ]
    tilt, az, off = posture_numbers(camera)
    rows.append(("tilt", f"{tilt:.3f} deg towards {az:.1f} deg"))
    rows.append(("centre - lower focus", f"|{np.linalg.norm(off):.3f}| mm"))
    held = _heldout_line(report, verdict)
    rows.append(("held-out corner RMS", held))
    ray = report.ray_std_deg
    if ray is not None and all(math.isfinite(v) for v in ray):
        rows.append(("viewing directions std", f"median {ray[0]:.3f} deg, worst {ray[1]:.3f} deg"))
    if report.lens_note:
        rows.append(("camera's reflection", report.lens_note))
    page.table(("figure", "value"), rows, left=2)
    by_nature = tuple(getattr(report, "notes", ()))
    alarms = [str(w) for w in report.warnings if w not in by_nature]
    if by_nature:  # what boards cannot fix by nature: stated, not doubted
        page.text("Notes (by nature, not doubts):", "note")
        page.items([terms(w) for w in by_nature], "note")
    if alarms:
        page.text("Warnings:", "warn")
        page.items([terms(w) for w in alarms], "warn")


def _heldout_line(report, verdict):
    held = report.heldout
    if held is not None and held.rms:
        line = f"median {held.median:.3f} px, worst {held.max:.3f} px ({held.folds}-fold)"
        if held.omnidir:
            v = list(held.omnidir.values())
            line += f"; cv2.omnidir on the same folds {np.median(v):.3f} / {np.max(v):.3f} px"
        return line
    if verdict is not None and verdict.heldout_median_px is not None:
        return (
            f"median {verdict.heldout_median_px:.3f} px, worst {verdict.heldout_max_px:.3f} px "
            f"({verdict.heldout_folds}-fold; from the calibration file, per view not recorded)"
        )
    return "not computed (calibrate with --heldout K, K >= 2, and 4 views or more)"


def _per_view(page, camera, report, names):
    page.section("views", "Per view: RMS and held-out error")
    held = report.heldout
    views = _views(report)
    header = ["view", "image", "corners", "RMS px"]
    if held is not None and held.rms:
        header += ["held-out px", "cv2.omnidir held-out px"]
    header += ["distance mm", "elevation deg", "found by"]
    rows = []
    for i in views:
        t = np.asarray(report.board_poses[i][1], np.float64)
        el = math.degrees(math.atan2(t[2], math.hypot(t[0], t[1])))
        row = [
            i,
            _name(report, names, i),
            report.corners_used.get(i, ""),
            f"{report.view_rms[i]:.3f}",
        ]
        if held is not None and held.rms:
            h = held.rms.get(i)
            o = held.omnidir.get(i)
            row += [
                "-" if h is None else f"{h:.3f}",
                "-" if o is None else f"{o:.3f}",
            ]
        row += [f"{np.linalg.norm(t):.1f}", f"{el:.1f}", report.found_by.get(i, "-")]
        rows.append(row)
    for i, why in sorted(report.dropped.items()):
        rows.append(
            [i, _name(report, names, i), "-", "dropped: " + str(why)] + [""] * (len(header) - 4)
        )
    page.table(header, rows, left=2)
    page.figure(
        _rms_bars(report, names),
        "Each view's corner RMS (px), with the held-out "
        "errors beside it when the calibration ran the held-out check.",
    )


def _rms_bars(report, names):
    views = _views(report)
    held = report.heldout
    series = [("RMS (fitted)", report.view_rms, (180, 110, 30))]
    if held is not None and held.rms:
        series.append(("held-out (omnicam)", held.rms, (40, 150, 40)))
        if held.omnidir:
            series.append(("held-out (cv2.omnidir)", held.omnidir, (40, 40, 200)))
    vals = [v for _, d, _ in series for v in d.values() if math.isfinite(v)]
    top = max(vals + [1e-3]) * 1.15
    width = max(420, min(1100, 70 + 60 * len(views) * len(series) // 2 + 40 * len(views)))
    ax = Axes(
        (width, 300),
        (-0.5, len(views) - 0.5),
        (0.0, top),
        title="corner RMS per view",
        xlabel="view (the image's index)",
        ylabel="RMS (px)",
    )
    ax.frame(xticks=range(len(views)), xfmt=lambda v: str(views[int(v)]))
    bw = 0.8 / len(series)
    for s, (_, data, colour) in enumerate(series):
        for k, i in enumerate(views):
            v = data.get(i)
            if v is None or not math.isfinite(v):
                continue
            x = k - 0.4 + s * bw
            p = ax.px([x, x + bw * 0.9], [0.0, min(v, top)])
            cv2.rectangle(
                ax.img,
                tuple(int(round(c)) for c in p[0]),
                tuple(int(round(c)) for c in p[1]),
                colour,
                -1,
            )
    return with_legend(ax.img, [(c, "patch", label) for label, _, c in series])


def _coverage_image(camera, report, images, order, colours):
    """The boards over the first image: each view's corner area, and the mirror's pixels far
    from every corner shaded."""
    base = images[0]
    img = (base.astype(np.float32) * 0.45 + 140).astype(np.uint8)
    h, w = img.shape[:2]
    rim = camera.rim_image_points(720)
    mask = np.zeros((h, w), np.uint8)
    if np.isfinite(rim).all():
        cv2.fillPoly(mask, [np.round(rim).astype(np.int32)], 255)
    occupied = np.zeros((h, w), np.uint8)
    overlay = img.copy()
    for k, i in enumerate(_views(report)):
        p = _pts(report.image_points[i])
        if p is None:
            continue
        poly = np.round(_outline(p, order)).astype(np.int32)
        cv2.fillPoly(overlay, [poly], colours[k])
        cv2.fillPoly(occupied, [poly], 255)
    img = cv2.addWeighted(overlay, 0.55, img, 0.45, 0)
    radius = math.sqrt(max(mask.sum() / 255.0, 1.0) / math.pi)
    dist = cv2.distanceTransform(255 - occupied, cv2.DIST_L2, 5)
    empty = (mask > 0) & (dist > 0.2 * radius)
    hatch = np.zeros((h, w), bool)
    yy, xx = np.mgrid[0:h, 0:w]
    hatch[((xx + yy) % 9) < 2] = True
    img[empty & hatch] = _EMPTY
    cv2.polylines(img, [np.round(rim * 16).astype(np.int32)], True, (0, 160, 0), 1, cv2.LINE_AA, 4)
    for i in _views(report):
        p = _pts(report.image_points[i])
        if p is not None and np.isfinite(p).any():
            c = np.nanmean(p, axis=0)
            put_label(img, str(i), c, (0, 0, 0), 0.5, "center", (255, 255, 255))
    share = 100.0 * empty.sum() / max((mask > 0).sum(), 1)
    items = [((0, 160, 0), "line", "rim")]
    items.append((_EMPTY, "hatch", f"mirror far from every corner ({share:.0f}% of it)"))
    return img, items, share


def _coverage_directions(camera, report, view, order, colours):
    """Azimuth-elevation plot of every board's corners' directions, the cells of 15 x 10 deg
    of the band without any corner hatched."""
    lo, hi = view.elevation_range
    ax = Axes(
        (760, 60 + int(4.0 * (hi - lo)) + 50),
        (-180.0, 180.0),
        (lo, hi),
        title="board coverage over the directions (equirectangular)",
        xlabel="azimuth (deg, mirror frame, from +X towards +Y)",
        ylabel="elevation (deg)",
    )
    counts = np.zeros((int(math.ceil((hi - lo) / 10.0)), 24), int)
    polys = []
    for k, i in enumerate(_views(report)):
        p = _pts(report.image_points[i])
        if p is None:
            continue
        d = camera.unproject(p)[1]
        ok = np.isfinite(d).all(axis=1)
        az = np.degrees(np.arctan2(d[ok, 1], d[ok, 0]))
        el = np.degrees(np.arctan2(d[ok, 2], np.hypot(d[ok, 0], d[ok, 1])))
        ci = np.clip(((az + 180.0) // 15).astype(int), 0, 23)
        ri = np.clip(((el - lo) // 10).astype(int), 0, len(counts) - 1)
        np.add.at(counts, (ri, ci), 1)
        outline = _outline(p, order)
        od = camera.unproject(outline)[1]
        polys.append((k, od, az, el))
    x0, y0, x1, y1 = ax.area
    for r in range(counts.shape[0]):
        for c in range(24):
            if counts[r, c]:
                continue
            a = ax.px([-180 + 15 * c, -165 + 15 * c], [lo + 10 * r, min(lo + 10 * r + 10, hi)])
            (u0, v1), (u1, v0) = np.round(a).astype(int)
            sub = ax.img[v0:v1, u0:u1]
            yy, xx = np.mgrid[v0:v1, u0:u1]
            sub[((xx + yy) % 9) < 2] = _EMPTY
    for k, od, az, el in polys:
        oaz = np.degrees(np.arctan2(od[:, 1], od[:, 0]))
        oel = np.degrees(np.arctan2(od[:, 2], np.hypot(od[:, 0], od[:, 1])))
        # break at the +-180 seam
        oaz = np.append(oaz, oaz[:1])
        oel = np.append(oel, oel[:1])
        jump = np.flatnonzero(np.abs(np.diff(oaz)) > 180) + 1
        for run in np.split(np.arange(len(oaz)), jump):
            ax.polyline(oaz[run], oel[run], colours[k], 2)
        ax.dots(az, el, colours[k], 1)
        if len(az):
            put_label(
                ax.img,
                str(_views(report)[k]),
                ax.px(np.median(az), np.median(el)),
                (0, 0, 0),
                0.45,
                "center",
                (255, 255, 255),
            )
    ax.frame(xticks=range(-180, 181, 30), yticks=nice_ticks(lo, hi, 6))
    share = 100.0 * (counts == 0).mean()
    items = [(_EMPTY, "hatch", f"15 x 10 deg cell without corners ({share:.0f}% of the band)")]
    return ax.img, items


def _coverage(page, camera, report, images, view, order, colours):
    page.section("coverage", "Board coverage")
    img, items, share = _coverage_image(camera, report, images, order, colours)
    legend = [(colours[k], "patch", f"view {i}") for k, i in enumerate(_views(report))]
    page.figure(
        with_legend(fit_width(img, 560), items + legend),
        "Over the image: each view's board (its corner grid, coloured and numbered) on the "
        "first image; hatched: the mirror's pixels farther than 20 % of the rim's radius from "
        "any corner, where no view constrains the model.",
        jpeg=True,
    )
    img2, items2 = _coverage_directions(camera, report, view, order, colours)
    page.figure(
        with_legend(img2, items2 + legend),
        "Over azimuth and elevation: each board's corner directions (dots) and outline, over "
        "the band a panorama shows; hatched cells hold no corner (add views there).",
    )


def _residual_scale(report):
    r = []
    for i in _views(report):
        d = _pts(report.image_points[i])
        q = _pts(report.reprojected.get(i))
        if d is not None and q is not None:
            e = q - d
            r.append(np.hypot(e[:, 0], e[:, 1]))
    r = np.concatenate(r) if r else np.zeros(1)
    r = r[np.isfinite(r)]
    big = float(np.percentile(r, 98)) if len(r) else 0.0
    if big <= 0:
        return 100.0
    target = 18.0 / big  # the 98th percentile drawn 18 px long
    mag = 10.0 ** math.floor(math.log10(target))
    return max(m * mag for m in (1, 2, 5) if m * mag <= target)


def _residuals(page, report, images, names, colours):
    page.section("residuals", "Residual vectors")
    scale = _residual_scale(report)
    views = _views(report)
    panels = []
    for i in views:
        d = _pts(report.image_points[i])
        q = _pts(report.reprojected.get(i))
        if d is None or q is None:
            continue
        ok = np.isfinite(d).all(axis=1) & np.isfinite(q).all(axis=1)
        lo = np.floor(d[ok].min(axis=0) - 25).astype(int)
        hi = np.ceil(d[ok].max(axis=0) + 25).astype(int)
        h, w = images[i].shape[:2]
        lo = np.maximum(lo, 0)
        hi = np.minimum(hi, (w - 1, h - 1))
        crop = images[i][lo[1] : hi[1] + 1, lo[0] : hi[0] + 1]
        s = 280.0 / max(crop.shape[:2])
        crop = cv2.resize(crop, None, fx=s, fy=s, interpolation=cv2.INTER_LINEAR)
        crop = (crop.astype(np.float32) * 0.5 + 127).astype(np.uint8)
        for p, e in zip((d[ok] - lo) * s, (q[ok] - d[ok])):
            cv2.circle(crop, (int(round(p[0])), int(round(p[1]))), 2, (0, 150, 0), -1, cv2.LINE_AA)
            residual_arrow(crop, p, e, scale, (0, 0, 220))
        # a scale bar of 1 px (or the residual's own size) in the corner
        length = _bar_length(scale)  # image px, drawn scale x longer
        bar = length * scale
        y = crop.shape[0] - 8
        cv2.line(crop, (8, y), (8 + int(round(bar)), y), (0, 0, 0), 2)
        put_label(
            crop, f"{length:g} px", (12 + bar, y + 4), (0, 0, 0), 0.4, "left", (255, 255, 255)
        )
        title = f"{i}: {_name(report, names, i)[:22]}  RMS {report.view_rms[i]:.3f} px"
        panels.append(with_title(crop, title))
    grid = _tile(panels, 4)
    page.figure(
        with_legend(
            grid,
            [
                ((0, 150, 0), "dot", "corner as detected"),
                ((0, 0, 220), "arrow", f"reprojected - detected, drawn x{scale:g}"),
                ((0, 0, 0), "line", "scale bar (length in image px)"),
            ],
        ),
        f"Each view's corners and their residuals (the calibrated camera's reprojection minus "
        f"the detection), magnified {scale:g} times, on a crop of the view around its board.",
        jpeg=True,
    )
    page.figure(_residual_scatter(report, colours), "All residuals, coloured per view.")


def _bar_length(scale):
    """A round length (image px: 1, 2 or 5 x 10^k) that ``scale`` draws 30 to 90 px long."""
    target = 50.0 / scale
    mag = 10.0 ** math.floor(math.log10(target))
    return min((m * mag for m in (1, 2, 5, 10)), key=lambda v: abs(math.log(v / target)))


def _tile(panels, cols):
    if not panels:
        return np.full((40, 300, 3), 255, np.uint8)
    h = max(p.shape[0] for p in panels)
    w = max(p.shape[1] for p in panels)
    rows = []
    for r in range(0, len(panels), cols):
        row = [
            cv2.copyMakeBorder(
                p,
                0,
                h - p.shape[0] + 6,
                0,
                w - p.shape[1] + 6,
                cv2.BORDER_CONSTANT,
                value=(255, 255, 255),
            )
            for p in panels[r : r + cols]
        ]
        row += [np.full((h + 6, w + 6, 3), 255, np.uint8)] * (cols - len(row))
        rows.append(np.hstack(row))
    return np.vstack(rows)


def _residual_scatter(report, colours):
    es = []
    for k, i in enumerate(_views(report)):
        d = _pts(report.image_points[i])
        q = _pts(report.reprojected.get(i))
        if d is not None and q is not None:
            e = q - d
            es.append((k, e[np.isfinite(e).all(axis=1)]))
    allr = np.concatenate([e for _, e in es]) if es else np.zeros((1, 2))
    lim = max(float(np.abs(allr).max()) * 1.1, 1e-3) if len(allr) else 1.0
    ax = Axes(
        (420, 440),
        (-lim, lim),
        (-lim, lim),
        title="residuals (reprojected - detected)",
        xlabel="x (px)",
        ylabel="y (px, down)",
        y_down=True,
    ).frame()
    for k, e in es:
        ax.dots(e[:, 0], e[:, 1], colours[k], 2)
    rms = report.rms / math.sqrt(2.0)
    t = np.linspace(0, 2 * np.pi, 90)
    ax.polyline(rms * np.cos(t), rms * np.sin(t), (0, 0, 0), 1, closed=True)
    items = [((0, 0, 0), "line", f"circle of the RMS per axis ({rms:.3f} px)")]
    items += [(colours[k], "dot", f"view {_views(report)[k]}") for k, _ in es]
    return with_legend(ax.img, items)


def _rim(page, camera, report, images):
    page.section("rim", "The rim and the camera's reflection")
    img, notes = rim_overlay(camera, images[0], report.rim_points)
    page.figure(
        img,
        f"The rim as fitted on the first image (rim RMS {report.rim_rms:.3f} px).",
        jpeg=True,
    )
    page.items(notes + ([f"reflection: {report.lens_note}"] if report.lens_note else []))


def _uncertainty(page, report):
    page.section("uncertainty", "Uncertainty of the viewing directions")
    ray = report.ray_std_deg
    if ray is not None and all(math.isfinite(v) for v in ray):
        page.text(
            f"Standard deviation of the viewing directions over the mirror's image: median "
            f"{ray[0]:.3f} deg, worst {ray[1]:.3f} deg (the parameters' covariance propagated to "
            f"the rays of a 24 x 24 grid of pixels)."
        )
    else:
        page.text("The report states no uncertainty of the viewing directions.")
    page.text(
        "No colour map: the report keeps only the median and the worst figure, not the "
        "covariance a per-pixel map would need."
    )
    std = report.std or {}
    rows = [(k, f"{v:.4g}") for k, v in std.items() if isinstance(v, float) and math.isfinite(v)]
    if rows:
        page.table(("parameter", "1 sigma"), rows)


def _panorama(page, camera, report, images, order, colours):
    page.section("panorama", "Panorama with the boards")
    pano, view = panorama(camera, images[0])
    m1, m2 = view.maps(camera)
    out = (pano.astype(np.float32) * 0.6 + 60).astype(np.uint8)
    for k, i in enumerate(_views(report)):
        p = _pts(report.image_points[i])
        if p is None:
            continue
        # each board from its own image, inside its outline
        od = camera.unproject(_outline(p, order))[1]
        q = panorama_pixels(view, od)
        own = cv2.remap(images[i], m1, m2, cv2.INTER_LINEAR)
        mask = np.zeros(out.shape[:2], np.uint8)
        ok = np.isfinite(q).all(axis=1)
        if ok.sum() >= 3:
            w = out.shape[1]
            u = q[ok].copy()  # unwrapped across the seam, filled at both ends
            u[:, 0] = u[0, 0] + np.mod(u[:, 0] - u[0, 0] + w / 2, w) - w / 2
            for shift in (-w, 0, w):
                poly = np.round(u + (shift, 0)).astype(np.int32)
                cv2.fillPoly(mask, [poly], 255)
            out[mask > 0] = own[mask > 0]
        draw_wrapped(out, q, colours[k], True, 2)
        c = q[ok].mean(axis=0) if ok.any() else None
        if c is not None:
            put_label(out, str(i), c, (0, 0, 0), 0.5, "center", (255, 255, 255))
    lo, hi = view.elevation_range
    legend = [(colours[k], "line", f"view {i}") for k, i in enumerate(_views(report))]
    page.figure(
        with_legend(out, legend),
        f"Equirectangular panorama (elevation {lo:.1f} to {hi:.1f} deg; azimuth 0 at the "
        f"left, turning right) of the first image, each board shown from its own image inside "
        f"its outline (the corner grid's border, reprojected through the calibrated camera).",
        jpeg=True,
    )


def _posture(page, camera):
    page.section("posture", "The posture")
    page.figure(posture_sketch(camera), "The mirror's tilt and the camera's offset.")


def pattern_report_html(
    camera: Any,
    report: Any,
    images: Sequence[np.ndarray],
    *,
    names: Sequence[str] | None = None,
    pattern_size: tuple[int, int] | None = None,
    verdict: Any = None,
    notes: Sequence[str] = (),
    title: str = "omnicam chessboard calibration",
    terms: Callable[[str], str] = str,
) -> str:
    """The report page of a chessboard calibration, as one self-contained HTML string.

    Parameters
    ----------
    camera : MisalignedCatadioptricCamera
        The calibrated camera.
    report : PatternReport
        Its report (:meth:`~omnicam.MisalignedHyperbolicCamera.calibrate_pattern`), or one
        with the same fields (``omnicam report`` builds it from the corners redetected).
    images : sequence of (H, W[, 3]) uint8 ndarray
        The views, in the report's order (BGR or grey).
    names : sequence of str, optional
        The views' names (default the report's ``names``, else the indices).
    pattern_size : (int, int), optional
        ``(cols, rows)`` of inner corners: the boards' outlines follow the corner grid's
        border (without it, the convex hull of the corners).
    verdict : Verdict, optional
        The calibration file's verdict: its held-out figures stand in for the report's when
        the report has none.
    notes : sequence of str
        Lines for the top of the page (where the figures came from).
    title : str
    terms : callable
        How the report's texts are worded on the page (the command line passes its own,
        which names options instead of the library's parameters).

    Returns
    -------
    str
        The page (sections :data:`PATTERN_SECTIONS`).
    """
    images = [bgr_view(im, "images") for im in images]
    if not images:
        raise ValueError("images: give the views of the calibration")
    views = _views(report)
    if not views:
        raise ValueError("report: no view was used")
    if max(views) >= len(images):
        raise ValueError(f"images: {len(images)} given, the report uses view {max(views)}")
    n = next(len(_pts(report.image_points[i])) for i in views)
    order = _outline_index(pattern_size, n)
    colours = view_colours(len(views))
    page = Page(title)
    _summary(page, camera, report, verdict, list(notes), terms)
    _per_view(page, camera, report, names)
    view = panorama_view(camera, 64)
    _coverage(page, camera, report, images, view, order, colours)
    _residuals(page, report, images, names, colours)
    _rim(page, camera, report, images)
    _uncertainty(page, report)
    _panorama(page, camera, report, images, order, colours)
    _posture(page, camera)
    return page.html()
