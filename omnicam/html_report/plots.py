"""Plot primitives drawn with cv2 and numpy alone: axes with ticks and labels, legends, colours.

Every plot of the report is a BGR ``uint8`` image; :class:`Axes` maps data coordinates to
pixels of a white canvas with a frame, ticks, axis labels and a title, and :func:`with_legend`
adds a legend strip below it (so a legend never hides data).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = [
    "Axes",
    "FONT",
    "arrow",
    "fit_width",
    "nice_ticks",
    "put_label",
    "view_colours",
    "with_legend",
    "with_title",
]

FONT = cv2.FONT_HERSHEY_SIMPLEX
_SCALE = 0.45
_INK = (40, 40, 40)
_GRID = (225, 225, 225)


def view_colours(n):
    """``n`` distinct BGR colours (hues evenly spaced, saturated, dark enough on white)."""
    n = max(int(n), 1)
    hsv = np.zeros((1, n, 3), np.uint8)
    hsv[0, :, 0] = (np.arange(n) * 180 // n) % 180
    hsv[0, :, 1] = 220
    hsv[0, :, 2] = 200
    bgr = cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)[0]
    return [tuple(int(v) for v in c) for c in bgr]


def put_label(img, text, org, colour=_INK, scale=_SCALE, anchor="left", background=None):
    """Text at ``org`` (its baseline's left, centre or right end, by ``anchor``), optionally on
    a filled box of ``background`` so it reads over an image."""
    (w, h), base = cv2.getTextSize(text, FONT, scale, 1)
    x, y = int(round(org[0])), int(round(org[1]))
    if anchor == "center":
        x -= w // 2
    elif anchor == "right":
        x -= w
    if background is not None:
        cv2.rectangle(img, (x - 2, y - h - 3), (x + w + 2, y + base), background, -1)
    cv2.putText(img, text, (x, y), FONT, scale, colour, 1, cv2.LINE_AA)


def arrow(img, p, q, colour, thickness=1):
    """An arrow from ``p`` to ``q`` (float pixels), tip length a fixed 4 px."""
    p = np.asarray(p, np.float64)
    q = np.asarray(q, np.float64)
    n = float(np.hypot(*(q - p)))
    if not math.isfinite(n):
        return
    tip = min(0.5, 4.0 / n) if n > 0 else 0.0
    cv2.arrowedLine(
        img,
        tuple(int(v) for v in np.round(p * 16)),
        tuple(int(v) for v in np.round(q * 16)),
        colour,
        thickness,
        cv2.LINE_AA,
        4,
        tip,
    )


def nice_ticks(lo, hi, target=6):
    """Round tick values within ``[lo, hi]`` (steps of 1, 2 or 5 times a power of ten)."""
    span = hi - lo
    if not (math.isfinite(span) and span > 0):
        return np.array([lo])
    raw = span / max(target, 1)
    mag = 10.0 ** math.floor(math.log10(raw))
    step = min((m * mag for m in (1, 2, 5, 10) if m * mag >= raw), default=10 * mag)
    first = math.ceil(lo / step - 1e-9) * step
    return np.arange(first, hi + step * 1e-6, step)


def _tick_text(v, step):
    if step >= 1 or step == 0:
        return f"{v:.0f}"
    digits = max(0, -int(math.floor(math.log10(step))))
    return f"{v:.{digits}f}"


class Axes:
    """A white canvas with a plot area mapping ``xlim`` x ``ylim`` to pixels.

    Parameters
    ----------
    size : (int, int)
        ``(width, height)`` of the whole canvas, px.
    xlim, ylim : (float, float)
        Data ranges; ``ylim`` runs upwards unless ``y_down`` (image-like plots).
    title, xlabel, ylabel : str
    y_down : bool
        Row 0 of the plot area is ``ylim[0]`` (as in an image) instead of ``ylim[1]``.
    """

    def __init__(
        self,
        size,
        xlim,
        ylim,
        title="",
        xlabel="",
        ylabel="",
        y_down=False,
        margins=(62, 16, 30, 46),
    ):
        self.w, self.h = (int(v) for v in size)
        self.left, self.right, self.top, self.bottom = margins
        self.xlim = tuple(float(v) for v in xlim)
        self.ylim = tuple(float(v) for v in ylim)
        self.y_down = y_down
        self.img = np.full((self.h, self.w, 3), 255, np.uint8)
        self.x0, self.x1 = self.left, self.w - self.right
        self.y0, self.y1 = self.top, self.h - self.bottom
        if title:
            put_label(self.img, title, (self.w / 2, 20), scale=0.52, anchor="center")
        if xlabel:
            put_label(self.img, xlabel, ((self.x0 + self.x1) / 2, self.h - 8), anchor="center")
        if ylabel:
            self._ylabel(ylabel)

    def _ylabel(self, text):
        (w, h), base = cv2.getTextSize(text, FONT, _SCALE, 1)
        strip = np.full((h + base + 4, w + 4, 3), 255, np.uint8)
        cv2.putText(strip, text, (2, h + 1), FONT, _SCALE, _INK, 1, cv2.LINE_AA)
        strip = cv2.rotate(strip, cv2.ROTATE_90_COUNTERCLOCKWISE)
        sh, sw = strip.shape[:2]
        cy = (self.y0 + self.y1) // 2
        y = max(0, min(self.h - sh, cy - sh // 2))
        if sh <= self.h:
            self.img[y : y + sh, 2 : 2 + sw] = np.minimum(self.img[y : y + sh, 2 : 2 + sw], strip)

    @property
    def area(self):
        """The plot area's pixels ``(x0, y0, x1, y1)``."""
        return self.x0, self.y0, self.x1, self.y1

    def px(self, x, y):
        """Data ``(x, y)`` (arrays) -> float pixel coordinates ``(N, 2)``."""
        x = np.asarray(x, np.float64)
        y = np.asarray(y, np.float64)
        (a, b), (c, d) = self.xlim, self.ylim
        u = self.x0 + (x - a) / (b - a) * (self.x1 - self.x0)
        t = (y - c) / (d - c)
        v = self.y0 + (t if self.y_down else 1.0 - t) * (self.y1 - self.y0)
        return np.stack([u, v], axis=-1)

    def polyline(self, x, y, colour, thickness=1, closed=False):
        """A polyline through finite data points (broken at NaN)."""
        p = self.px(x, y)
        ok = np.isfinite(p).all(axis=-1)
        runs = np.split(np.arange(len(p)), np.flatnonzero(np.diff(ok.astype(int)) != 0) + 1)
        for run in runs:
            if len(run) >= 2 and ok[run[0]]:
                pts = np.round(p[run] * 16).astype(np.int32)
                cv2.polylines(self.img, [pts], closed, colour, thickness, cv2.LINE_AA, 4)

    def dots(self, x, y, colour, radius=2):
        """Filled dots at the finite data points."""
        for u, v in self.px(x, y):
            if math.isfinite(u) and math.isfinite(v):
                cv2.circle(
                    self.img, (int(round(u)), int(round(v))), radius, colour, -1, cv2.LINE_AA
                )

    def frame(self, xticks=None, yticks=None, grid=True, xfmt=None, yfmt=None):
        """The frame, the ticks with their numbers, and optionally a light grid."""
        xt = nice_ticks(*self.xlim) if xticks is None else np.asarray(xticks, np.float64)
        yt = nice_ticks(*sorted(self.ylim)) if yticks is None else np.asarray(yticks, np.float64)
        xs = float(np.diff(xt).min()) if len(xt) > 1 else 1.0
        ys = float(np.diff(yt).min()) if len(yt) > 1 else 1.0
        for v in xt:
            u = int(round(self.px(v, self.ylim[0])[0]))
            if grid:
                cv2.line(self.img, (u, self.y0), (u, self.y1), _GRID, 1)
            cv2.line(self.img, (u, self.y1), (u, self.y1 + 4), _INK, 1)
            text = xfmt(v) if xfmt else _tick_text(v, xs)
            put_label(self.img, text, (u, self.y1 + 18), anchor="center", scale=0.4)
        for v in yt:
            w = int(round(self.px(self.xlim[0], v)[1]))
            if grid:
                cv2.line(self.img, (self.x0, w), (self.x1, w), _GRID, 1)
            cv2.line(self.img, (self.x0 - 4, w), (self.x0, w), _INK, 1)
            text = yfmt(v) if yfmt else _tick_text(v, ys)
            put_label(self.img, text, (self.x0 - 6, w + 4), anchor="right", scale=0.4)
        cv2.rectangle(self.img, (self.x0, self.y0), (self.x1, self.y1), _INK, 1)
        return self


def with_legend(img, items, columns=None, scale=_SCALE):
    """``img`` with a legend strip below it.

    ``items``: ``(colour, kind, label)`` with ``kind`` one of ``"line"``, ``"dot"``,
    ``"patch"``, ``"arrow"``, ``"cross"``, ``"hatch"``.
    """
    if not items:
        return img
    w = img.shape[1]
    widths = [cv2.getTextSize(label, FONT, scale, 1)[0][0] + 48 for _, _, label in items]
    if columns:  # a grid of equal cells
        cell = min(max(widths), (w - 10) // columns)
        places = [(8 + (k % columns) * cell, k // columns) for k in range(len(items))]
    else:  # left to right, wrapped at the image's width
        places, x, row = [], 8, 0
        for width in widths:
            if x > 8 and x + width > w - 4:
                x, row = 8, row + 1
            places.append((x, row))
            x += width
    rows = max(r for _, r in places) + 1
    strip = np.full((rows * 22 + 8, w, 3), 255, np.uint8)
    for (colour, kind, label), (x, r) in zip(items, places):
        y = 16 + r * 22
        if kind == "line":
            cv2.line(strip, (x, y - 4), (x + 24, y - 4), colour, 2, cv2.LINE_AA)
        elif kind == "dot":
            cv2.circle(strip, (x + 12, y - 4), 4, colour, -1, cv2.LINE_AA)
        elif kind == "circle":
            cv2.circle(strip, (x + 12, y - 4), 5, colour, 1, cv2.LINE_AA)
        elif kind == "cross":
            cv2.drawMarker(strip, (x + 12, y - 4), colour, cv2.MARKER_CROSS, 9, 1)
        elif kind == "arrow":
            arrow(strip, (x, y - 4), (x + 24, y - 4), colour)
        elif kind == "hatch":
            patch = np.full((14, 25, 3), 255, np.uint8)
            for d in range(-14, 25, 5):
                cv2.line(patch, (d, 13), (d + 13, 0), colour, 1, cv2.LINE_AA)
            cv2.rectangle(patch, (0, 0), (24, 13), colour, 1)
            strip[y - 11 : y + 3, x : x + 25] = patch
        else:  # patch
            cv2.rectangle(strip, (x, y - 11), (x + 24, y + 2), colour, -1)
            cv2.rectangle(strip, (x, y - 11), (x + 24, y + 2), _INK, 1)
        put_label(strip, label, (x + 32, y + 1), scale=scale)
    cv2.line(strip, (0, 0), (w, 0), _GRID, 1)
    return np.vstack([img, strip])


def with_title(img, title):
    """``img`` with a title strip above it."""
    strip = np.full((26, img.shape[1], 3), 255, np.uint8)
    put_label(strip, title, (img.shape[1] / 2, 18), scale=0.5, anchor="center")
    return np.vstack([strip, img])


def fit_width(img, width):
    """``img`` scaled (INTER_AREA down, INTER_LINEAR up) to ``width`` px wide."""
    h, w = img.shape[:2]
    if w == width:
        return img
    interp = cv2.INTER_AREA if width < w else cv2.INTER_LINEAR
    return cv2.resize(img, (int(width), max(1, round(h * width / w))), interpolation=interp)
