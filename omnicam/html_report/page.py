"""The HTML of the report: one self-contained page (inline CSS, images as data URIs), and the
sections both routes share (the posture sketch, the panorama, the rim on the image)."""

from __future__ import annotations

import base64
import html
import math

import cv2
import numpy as np

from ..mirror import HyperbolicMirror, nominal_camera_z
from ..views import PanoramaView
from .plots import Axes, arrow, fit_width, put_label, with_legend

__all__ = [
    "Page",
    "data_uri",
    "panorama",
    "panorama_pixels",
    "panorama_view",
    "posture_numbers",
    "posture_sketch",
    "rim_overlay",
]

_CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;margin:0;background:#f4f4f2;
color:#222}
main{max-width:1240px;margin:0 auto;padding:12px 24px 40px}
h1{font-size:1.5em;margin:.6em 0 .2em}
h2{font-size:1.15em;margin:1.4em 0 .4em;border-bottom:1px solid #ccc;padding-bottom:.2em}
section{background:#fff;padding:4px 16px 12px;margin:10px 0;border-radius:6px;
box-shadow:0 1px 2px rgba(0,0,0,.08)}
figure{display:inline-block;margin:6px 10px 6px 0;vertical-align:top}
figure img{max-width:100%;border:1px solid #ddd}
figcaption{font-size:.85em;color:#555}
table{border-collapse:collapse;font-size:.88em;margin:6px 0}
td,th{border:1px solid #ddd;padding:2px 8px;text-align:right}
th{background:#f0f0ee}
td.l,th.l{text-align:left}
.note{color:#555;font-size:.9em}
.warn{color:#8a4b00}
"""


def data_uri(img, jpeg=False, quality=88):
    """A ``data:image/png;base64,...`` (or JPEG) URI of a BGR ``uint8`` image."""
    ext = ".jpg" if jpeg else ".png"
    params = [cv2.IMWRITE_JPEG_QUALITY, quality] if jpeg else [cv2.IMWRITE_PNG_COMPRESSION, 3]
    ok, buf = cv2.imencode(ext, np.ascontiguousarray(img), params)
    if not ok:
        raise ValueError("cannot encode an image of the report")
    kind = "jpeg" if jpeg else "png"
    return f"data:image/{kind};base64,{base64.b64encode(buf.tobytes()).decode('ascii')}"


def esc(text):
    """``text`` escaped for HTML."""
    return html.escape(str(text), quote=True)


class Page:
    """Sections of HTML, put together by :meth:`html` into one page."""

    def __init__(self, title):
        self.title = title
        self.parts = []

    def section(self, ident, heading):
        """Start a section ``<section id=ident>`` with its heading."""
        if self.parts:
            self.parts.append("</section>")
        self.parts.append(f'<section id="{esc(ident)}"><h2>{esc(heading)}</h2>')

    def text(self, text, cls="note"):
        """A paragraph (escaped)."""
        self.parts.append(f'<p class="{cls}">{esc(text)}</p>')

    def items(self, texts, cls=""):
        """A bulleted list (escaped)."""
        if texts:
            lis = "".join(f"<li>{esc(t)}</li>" for t in texts)
            self.parts.append(f'<ul class="{cls}">{lis}</ul>')

    def figure(self, img, caption, width=None, jpeg=False):
        """An image (embedded) with its caption; ``width`` scales it first."""
        if width is not None:
            img = fit_width(img, width)
        alt = esc(caption.split(".")[0])
        self.parts.append(
            f'<figure style="max-width:{img.shape[1] + 2}px">'
            f'<img src="{data_uri(img, jpeg)}" alt="{alt}" width="{img.shape[1]}">'
            f"<figcaption>{esc(caption)}</figcaption></figure>"
        )

    def table(self, header, rows, left=1):
        """A table; the first ``left`` columns are left-aligned."""

        def cells(row, tag):
            return "".join(
                f"<{tag}{' class=l' if k < left else ''}>{esc(v)}</{tag}>"
                for k, v in enumerate(row)
            )

        body = "".join(f"<tr>{cells(r, 'td')}</tr>" for r in rows)
        self.parts.append(f"<table><tr>{cells(header, 'th')}</tr>{body}</table>")

    def html(self):
        """The whole page."""
        parts = [*self.parts, "</section>"] if self.parts else []
        return (
            '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f"<title>{esc(self.title)}</title><style>{_CSS}</style></head><body><main>"
            f"<h1>{esc(self.title)}</h1>" + "\n".join(parts) + "</main></body></html>\n"
        )


# -- posture ----------------------------------------------------------------------------------
def posture_numbers(camera):
    """``(tilt deg, tilt azimuth deg, offset (3,))``: the angle between the optical axis and
    the mirror axis, its direction in the camera's x-y plane, and the camera centre minus the
    lower focus ``(0, 0, -c)`` in the mirror frame (any mirror: its nominal camera position,
    :func:`omnicam.mirror.nominal_camera_z`; NaN for a mirror without one)."""
    axis = np.asarray(camera.R)[:, 2]
    tilt = math.degrees(math.atan2(math.hypot(axis[0], axis[1]), axis[2]))
    az = math.degrees(math.atan2(axis[1], axis[0])) if tilt > 0 else 0.0
    z = nominal_camera_z(camera.mirror)
    offset = np.asarray(camera.camera_center) - np.array([0.0, 0.0, math.nan if z is None else z])
    return tilt, az, offset


def _reference_z(camera):
    """The sketch's lower focus: the nominal camera position, or the camera centre's own
    height for a mirror without one."""
    z = nominal_camera_z(camera.mirror)
    return float(camera.camera_center[2]) if z is None else z


def _profile_z(m, x):
    """The mirror's height over ``(x, 0)``."""
    if isinstance(m, HyperbolicMirror):
        return m.b * np.sqrt(1.0 + (x / m.a) ** 2)
    return m.surface_z(x, np.zeros_like(x))


def _rim_z(m):
    if isinstance(m, HyperbolicMirror):
        return m.b * math.sqrt(1 + (m.rim_radius / m.a) ** 2)
    return m.z_rim


def _rot(axis, angle):
    return cv2.Rodrigues(np.asarray(axis, np.float64) * angle)[0]


def posture_sketch(camera, size=(560, 470)):
    """Side view of the rig in the plane of the tilt: the camera's optical axis (blue), the
    mirror's profile and axis (red), the lower focus and the camera centre; the tilt and the
    offset are exaggerated by a stated factor when too small to see."""
    tilt, az, offset = posture_numbers(camera)
    m = camera.mirror
    k = 1.0 if tilt >= 8.0 else min(20.0, max(1.0, round(8.0 / max(tilt, 0.4))))
    R = np.asarray(camera.R)
    t = np.asarray(camera.tvec)
    axis = R[:, 2]
    # exaggerate: rotate the mirror about the camera centre by (k - 1) x its tilt, scale the
    # camera centre's offset from the focus by k
    if k > 1.0 and tilt > 0:
        n = np.cross((0.0, 0.0, 1.0), axis)
        n /= np.linalg.norm(n)
        R = _rot(n, math.radians(tilt) * (k - 1.0)) @ R
    zf = _reference_z(camera)  # -c for a hyperboloid
    focus_cam = R @ np.array([0.0, 0.0, zf])
    # camera centre at the origin: its offset from the focus, scaled; the mirror moved with it
    off_cam = -(np.asarray(camera.R) @ np.array([0.0, 0.0, zf]) + t)  # focus -> centre
    t = -focus_cam - k * off_cam
    u = np.array([math.cos(math.radians(az)), math.sin(math.radians(az)), 0.0])  # across
    x = np.linspace(-m.rim_radius, m.rim_radius, 121)
    prof = np.stack([x, np.zeros_like(x), _profile_z(m, x)], axis=1)
    # the profile in the mirror's plane through its axis and the tilt direction
    e1 = R.T @ u
    e1 -= e1[2] * np.array([0.0, 0.0, 1.0])
    if np.linalg.norm(e1) < 1e-9:
        e1 = np.array([1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    A = np.stack([e1, np.cross((0.0, 0.0, 1.0), e1), (0.0, 0.0, 1.0)], axis=1)
    prof_cam = (prof @ A.T) @ R.T + t
    top = float(prof_cam[:, 2].max()) * 1.08
    half = max(m.rim_radius * 1.6, 0.5 * top)
    ax = Axes(
        size,
        (-half, half),
        (-0.12 * top, top),
        title="the posture: side view in the plane of the tilt",
        xlabel="across the optical axis, towards the tilt (mm)",
        ylabel="along the optical axis (mm)",
    ).frame()
    across = prof_cam @ u
    along = prof_cam[:, 2]
    ax.polyline(across, along, (0, 0, 200), 2)
    ends = np.array([0.0, top * 0.98])
    ax.polyline([0.0, 0.0], ends, (200, 80, 0), 1)
    foc = R @ np.array([0.0, 0.0, zf]) + t
    top_pt = R @ np.array([0.0, 0.0, _rim_z(m)]) + t
    d = top_pt - foc
    s = np.linspace(-0.05, 1.05, 2)
    ax.polyline((foc @ u) + s * (d @ u), foc[2] + s * d[2], (0, 0, 200), 1)
    ax.dots([foc @ u], [foc[2]], (0, 0, 200), 4)
    ax.dots([0.0], [0.0], (200, 80, 0), 4)
    # the camera: a small trapezoid below its centre
    cam = ax.px([-6, 6, 3, -3], [-0.02 * top, -0.02 * top, -0.1 * top, -0.1 * top])
    cv2.polylines(ax.img, [np.round(cam).astype(np.int32)], True, (200, 80, 0), 1, cv2.LINE_AA)
    lines = [
        f"tilt {tilt:.3f} deg towards azimuth {az:.1f} deg (camera x-y plane)",
        (
            f"camera centre - lower focus: ({offset[0]:.2f}, {offset[1]:.2f}, {offset[2]:.2f}) "
            f"mm, |{np.linalg.norm(offset):.2f}| mm"
            if np.all(np.isfinite(offset))
            else "camera centre - lower focus: none (the mirror does not say where it is)"
        ),
        "to scale" if k == 1.0 else f"tilt and offset drawn x{k:g} to be seen",
    ]
    strip = np.full((10 + 18 * len(lines), ax.img.shape[1], 3), 255, np.uint8)
    for i, line in enumerate(lines):
        put_label(strip, line, (10, 16 + 18 * i), scale=0.45)
    img = np.vstack([ax.img, strip])
    return with_legend(
        img,
        [
            ((200, 80, 0), "line", "camera's optical axis, centre (dot)"),
            ((0, 0, 200), "line", "mirror profile and axis, lower focus (dot)"),
        ],
        columns=1,
    )


# -- the panorama -----------------------------------------------------------------------------
def panorama_view(camera, width=1200):
    """An equirectangular :class:`PanoramaView` ``width`` px wide over the default band
    (:meth:`PanoramaView.default_range`), one pixel per ``360 / width`` deg both ways."""
    lo, hi, _ = PanoramaView((8, 8), projection="equirectangular").default_range(camera)
    height = int(round(width * (hi - lo) / 360.0))
    return PanoramaView((width, max(height, 40)), (lo, hi), "equirectangular")


def panorama(camera, image, width=1200):
    """``(panorama, view)``: :func:`panorama_view` of ``image`` (``cv2.remap``)."""
    view = panorama_view(camera, width)
    m1, m2 = view.maps(camera)
    return cv2.remap(image, m1, m2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT), view


def panorama_pixels(view, directions):
    """Pixels ``(N, 2)`` of mirror-frame ``directions`` in an equirectangular ``view``
    (conventions.md, section Views: column ``j`` looks at azimuth ``-360 j / W``)."""
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    w, h = view.size
    lo, hi = view.elevation_range
    az = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    el = np.degrees(np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])))
    col = np.mod(-az * w / 360.0, w)
    row = (hi - el) / (hi - lo) * (h - 1)
    return np.stack([col, row], axis=1)


def draw_wrapped(img, pts, colour, closed=True, thickness=1):
    """A polyline of panorama pixels, broken where it wraps around the panorama's seam."""
    pts = np.asarray(pts, np.float64)
    if closed and len(pts):
        pts = np.vstack([pts, pts[:1]])
    w = img.shape[1]
    ok = np.isfinite(pts).all(axis=1)
    jump = np.abs(np.diff(pts[:, 0])) > w / 2
    cut = np.flatnonzero(jump | ~ok[1:] | ~ok[:-1]) + 1
    for run in np.split(np.arange(len(pts)), cut):
        run = run[ok[run]]
        if len(run) >= 2:
            q = np.round(pts[run] * 16).astype(np.int32)
            cv2.polylines(img, [q], False, colour, thickness, cv2.LINE_AA, 4)


def rim_overlay(camera, image, rim_points=None, width=620):
    """``(image, notes)``: the fitted rim (green), the rim points used (blue dots) and the
    camera's reflection as fitted (magenta), with a legend."""
    img = image.copy() if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    scale = width / img.shape[1]
    img = fit_width(img, width)
    items = []
    notes = []
    if rim_points is not None and len(rim_points):
        for p in np.asarray(rim_points, np.float64).reshape(-1, 2)[::3] * scale:
            if np.isfinite(p).all():
                cv2.circle(img, (int(round(p[0])), int(round(p[1]))), 2, (255, 160, 0), -1)
        items.append(((255, 160, 0), "dot", "rim points used"))
    rim = camera.rim_image_points(720) * scale
    if np.isfinite(rim).all():
        q = np.round(rim * 16).astype(np.int32)
        cv2.polylines(img, [q], True, (0, 200, 0), 1, cv2.LINE_AA, 4)
    items.append(((0, 200, 0), "line", "rim as fitted"))
    refl = camera.camera_reflection
    if refl is not None:
        from ..calibration.reflection import outline_pixels

        out, centre = outline_pixels(camera, refl[0], refl[1], n=180)
        out = out * scale
        ok = np.isfinite(out).all(axis=1)
        if ok.sum() >= 2:
            q = np.round(out[ok] * 16).astype(np.int32)
            cv2.polylines(img, [q], True, (200, 0, 200), 1, cv2.LINE_AA, 4)
        if np.isfinite(centre).all():
            c = np.round(centre * scale).astype(int)
            cv2.drawMarker(img, (int(c[0]), int(c[1])), (200, 0, 200), cv2.MARKER_CROSS, 10, 1)
        items.append(((200, 0, 200), "line", "camera's reflection as fitted (+ its centre)"))
        notes.append(
            f"camera's reflection: circle r {refl[0]:.2f} mm at z {refl[1]:.2f} mm along the "
            f"optical axis"
        )
    else:
        notes.append(
            "the camera's reflection is not drawn: the calibration records none (a chessboard "
            "calibration, or not found)"
        )
    return with_legend(img, items), notes


def residual_arrow(img, p, r, scale, colour):
    """An arrow from ``p`` along ``r * scale`` (pixels)."""
    arrow(img, p, np.asarray(p) + np.asarray(r) * scale, colour)


def bgr_view(image, name="image"):
    """An 8-bit view to draw on as BGR: grey and BGRA converted, BGR as it is; ``ValueError``
    naming ``name`` for any other dtype (the page shows the images as the calibration saw them,
    not rescaled)."""
    a = np.asarray(image)
    if a.dtype != np.uint8:
        raise ValueError(f"{name}: expected uint8, got {a.dtype}")
    if a.ndim == 2:
        return cv2.cvtColor(a, cv2.COLOR_GRAY2BGR)
    if a.ndim == 3 and a.shape[2] == 4:
        return cv2.cvtColor(a, cv2.COLOR_BGRA2BGR)
    return a
