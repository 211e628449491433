"""Random rigs and scenes, and the stress cases: reproducible hostile renders
(:func:`stress_cases`, :func:`render_case`) with their ground truth."""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from .far_lines import far_line_pixels, mirror_grid
from .optics import CameraNumbers
from .render import degrade, render_rig
from .scene import FRONT_LABELS, VARIANTS, BodyGeometry, Holder, Photometric, Rig, RoomScene, Strut


def random_room(rng, dark_floor=False):
    """A random :class:`RoomScene`: walls 1.5-4 m away, doors, posters, windows, a rug."""
    hx, hy = rng.uniform(1.5, 4.0, 2)
    floor, ceiling = rng.uniform(1.0, 1.8), rng.uniform(1.0, 2.2)
    walls = [tuple(rng.uniform(110, 215, 3)) for _ in range(4)]
    floor_col = tuple(rng.uniform(50, 150, 3))
    rects = []
    for surf in range(4):
        half = hy if surf < 2 else hx
        for _ in range(int(rng.integers(2, 6))):
            wdt = rng.uniform(0.3, 1.2)
            u0 = rng.uniform(-half, half - wdt)
            v0 = rng.uniform(-floor, ceiling - 0.3)
            hgt = rng.uniform(0.3, min(2.0, ceiling - v0))
            if rng.uniform() < 0.3:  # a door or a shelf down to the floor
                v0 = -floor + 0.0
            tone = rng.choice([rng.uniform(10, 60), rng.uniform(200, 250), rng.uniform(60, 200)])
            colour = tuple(np.clip(tone + rng.normal(0, 25, 3), 0, 255))
            rects.append((surf, u0, u0 + wdt, v0, v0 + hgt, colour))
    for _ in range(int(rng.integers(0, 3))):  # rugs
        cx, cy = rng.uniform(-0.6, 0.6, 2) * (hx, hy)
        rw, rh = rng.uniform(0.4, 1.4, 2)
        rects.append((4, cx - rw, cx + rw, cy - rh, cy + rh, tuple(rng.uniform(30, 220, 3))))
    return RoomScene(
        half_x=float(hx),
        half_y=float(hy),
        floor=float(floor),
        ceiling=float(ceiling),
        yaw_deg=float(rng.uniform(0, 360)),
        wall_colors=(*walls, floor_col, (230.0, 230.0, 228.0)),
        rects=tuple(rects),
        plank=float(rng.choice([0.0, 0.12, 0.2])),
        dark_floor_deg=float(rng.uniform(-72.0, -50.0)) if dark_floor else None,
    )


def random_body(rng, r_range=(5.0, 25.0), z_range=(5.0, 40.0)):
    """A random :class:`BodyGeometry`: barrel radius and length from the ranges, a wider box."""
    r = float(rng.uniform(*r_range))
    z = float(rng.uniform(*z_range))
    rg = r * rng.uniform(0.7, 0.9)
    n_rings = int(rng.integers(1, 3))
    rings = tuple(sorted(rg * rng.uniform(0.4, 0.85, n_rings)))
    highlights = []
    for _ in range(int(rng.integers(1, 4))):
        rr, aa = rg * rng.uniform(0.1, 0.75), rng.uniform(0, 2 * np.pi)
        highlights.append((rr * math.cos(aa), rr * math.sin(aa), rg * rng.uniform(0.04, 0.12)))
    wb = r * rng.uniform(1.0, 2.2)
    glass = rng.uniform(8, 28)
    tone = rng.uniform()
    if tone < 0.5:  # black or dark grey body
        box = np.full(3, rng.uniform(30, 75)) + rng.uniform(-4, 4, 3)
    elif tone < 0.85:  # silver
        box = np.full(3, rng.uniform(130, 200)) + rng.uniform(-6, 6, 3)
    else:  # a bare board camera: green printed circuit board
        box = np.array([40.0, 110.0, 50.0]) + rng.uniform(-15, 15, 3)
    return BodyGeometry(
        r_barrel=r,
        z_barrel=z,
        r_glass=float(rg),
        r_aperture=float(rg * rng.uniform(0.15, 0.3)),
        rings=rings,
        highlights=tuple(highlights),
        z_box=float(rng.uniform(-10.0, 0.4 * z)),
        w_box=float(wb),
        h_box=float(wb * rng.uniform(0.6, 1.0)),
        depth_box=float(rng.uniform(20, 50)),
        box_angle_deg=float(rng.uniform(-3, 3)),
        glass_color=(glass, glass * 0.6, glass * 0.5),
        ring_color=tuple(float(x) for x in np.full(3, rng.uniform(20, 60))),
        side_color=tuple(float(x) for x in np.full(3, rng.uniform(80, 130))),
        box_color=tuple(float(x) for x in box),
    )


def random_struts(rng, camera, count=None):
    """2-4 thin rods from the holder (just outside the rim) down towards the camera.

    Each runs from a point at 1.05-1.15 rim radii just below the rim plane to a point on the
    line of sight from the camera centre to a mirror point at 25-60 % of the rim radius, 55-80 %
    of the way to the mirror: in the image a radial stripe from the rim inwards.
    """
    num = CameraNumbers(camera)
    count = int(rng.integers(2, 5)) if count is None else int(count)
    colour = (24.0, 24.0, 26.0) if rng.uniform() < 0.5 else (228.0, 228.0, 225.0)
    phi0 = rng.uniform(0, 2 * np.pi)
    out = []
    for k in range(count):
        phi = phi0 + 2 * np.pi * k / count + rng.uniform(-0.2, 0.2)
        rh = num.rim * rng.uniform(1.05, 1.15)
        top = np.array([rh * math.cos(phi), rh * math.sin(phi), num.z_rim - 0.5])
        rho = num.rim * rng.uniform(0.25, 0.6)
        psi = phi + rng.uniform(-0.15, 0.15)
        m = np.array(
            [rho * math.cos(psi), rho * math.sin(psi), num.b * math.sqrt(1 + (rho / num.a) ** 2)]
        )
        frac = rng.uniform(0.55, 0.8)
        for _ in range(10):  # keep the rod below the mirror surface all along
            low = num.C + frac * (m - num.C)
            s = np.linspace(0, 1, 64)[:, None]
            pts = top + s * (low - top)
            rr = np.hypot(pts[:, 0], pts[:, 1])
            zm = num.b * np.sqrt(1 + (rr / num.a) ** 2)
            if np.all((pts[:, 2] < zm - 1.0) | (rr > num.rim + 0.5)):
                break
            frac *= 0.9
        out.append(Strut(tuple(top), tuple(low), float(rng.uniform(0.35, 0.9)), colour))
    return tuple(out)


def _background(rng, size):
    """What the camera sees beside the mirror: a dark, blotchy housing with a few shapes."""
    w, h = size
    base = rng.uniform(12, 55)
    small = (base + rng.normal(0, 18, (6, 8, 3))).astype(np.float32)
    bg = cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)
    for _ in range(int(rng.integers(2, 6))):
        x0, y0 = int(rng.integers(0, w)), int(rng.integers(0, h))
        x1, y1 = x0 + int(rng.integers(20, w // 3)), y0 + int(rng.integers(20, h // 3))
        bg[y0:y1, x0:x1] = rng.uniform(10, 120)
    return np.clip(bg, 0, 255)


# -- stress cases --------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class StressCase:
    """One reproducible stress render: a truth rig, the variants on, and the seed of the rest.

    Attributes
    ----------
    index, seed : int
        Case ``index`` of :func:`stress_cases` with ``seed``; every random choice of
        :func:`render_case` is drawn from ``numpy.random.default_rng([seed, index, 1])``.
    flags : frozenset of str
        The :data:`VARIANTS` switched on.
    image_size : (int, int)
    K : (3, 3) tuple
    D : tuple or None
    tilt_deg, tilt_azimuth_deg : float
    offset_mm : (3,) tuple
        Mirror origin minus ``(0, 0, c)``, camera frame.
    body : BodyGeometry or None
    photometric : Photometric
    supersample : int
    """

    index: int
    seed: int
    flags: frozenset
    image_size: tuple
    K: tuple
    D: object
    tilt_deg: float
    tilt_azimuth_deg: float
    offset_mm: tuple
    body: object
    photometric: Photometric
    supersample: int = 3

    def camera(self):
        """The truth :class:`~omnicam.camera.MisalignedHyperbolicCamera`."""
        from ...hyperbolic_camera import MisalignedHyperbolicCamera
        from .. import default_mirror

        mirror = default_mirror()
        phi = math.radians(self.tilt_azimuth_deg)
        rvec = math.radians(self.tilt_deg) * np.array([-math.sin(phi), math.cos(phi), 0.0])
        tvec = np.array([0.0, 0.0, mirror.c]) + np.asarray(self.offset_mm)
        return MisalignedHyperbolicCamera(
            np.array(self.K), mirror, rvec, tvec, D=self.D, image_size=self.image_size
        )


@dataclasses.dataclass(frozen=True)
class RealisticRender:
    """A rendered stress case and its ground truth.

    Attributes
    ----------
    image : (h, w, 3) uint8 ndarray, BGR
    camera : MisalignedHyperbolicCamera
        The truth.
    body_circles : tuple of (r, z)
        Coaxial circles (camera frame) whose reflections make the outermost round dark
        silhouette; empty without a body.
    flags : frozenset of str
    far_lines : tuple of (N, 2) float64 ndarrays
        Pixels of the room's wall-floor edges that are seen (not occluded, in the frame),
        longest first: the ``far_lines`` argument of ``calibrate``.
    far_line_normals : tuple of (3,) ndarrays
        Unit normals (mirror frame) of their great circles.
    reflection_visible : bool
        The body's silhouette is in the frame and contrasts (>= 20 grey levels) with what is
        around it over >= 70 % of its outline.
    labels : (h, w) int8 ndarray
    case : StressCase
    """

    image: np.ndarray
    camera: object
    body_circles: tuple
    flags: frozenset
    far_lines: tuple
    far_line_normals: tuple
    reflection_visible: bool
    labels: np.ndarray
    case: StressCase


_SIZES = ((640, 480), (800, 600), (640, 640), (1000, 1000))
_SIZE_P = (0.4, 0.3, 0.2, 0.1)
_CLIPPED_SIZES = ((960, 540), (854, 480), (1000, 562))


def _flags_for(i, rng):
    kind = i % 4
    v = VARIANTS[(i // 4) % len(VARIANTS)]
    if kind == 0:  # one variant alone
        return frozenset({v})
    if kind == 1:  # one variant with the camera body
        return frozenset({"body", v})
    if kind == 2:  # any combination
        return frozenset(x for x in VARIANTS if rng.uniform() < 0.5)
    # a real rig: body and photographic degradations, the rest at random
    extra = [
        x
        for x in ("holder", "struts", "dark_floor", "clipped", "distortion")
        if rng.uniform() < 0.5
    ]
    return frozenset({"body", "blur", "noise", "jpeg", "vignette", *extra})


def stress_cases(n=100, seed=0, image_size=None):
    """Reproducible stress cases over the variants, seeds, postures and body sizes.

    Case ``i`` draws from ``numpy.random.default_rng([seed, i])``: ``i % 4 == 0`` one variant
    alone, ``1`` one variant with the camera body, ``2`` any combination, ``3`` a real rig (body,
    blur, noise, JPEG, vignetting and the rest at random); the variant cycles with ``i // 4``.
    Tilt up to 5 deg, offset up to 5 mm (uniform in a ball), barrel radius 5-25 mm at 5-40 mm,
    images 640x480 to 1000x1000 (clipped: 16:9 frames whose height is 1.08-1.3x smaller than
    the rim's diameter).

    Parameters
    ----------
    n : int
    seed : int
    image_size : (int, int) or None
        Force one image size (e.g. small ones for tests); clipped cases then get a 16:9 frame
        of the same width.

    Yields
    ------
    StressCase
    """
    from .. import default_mirror

    mirror = default_mirror()
    depth = mirror.z_rim + mirror.c  # aligned rim depth
    for i in range(int(n)):
        rng = np.random.default_rng([seed, i])
        flags = _flags_for(i, rng)
        clipped = "clipped" in flags
        if image_size is not None:
            size = tuple(int(v) for v in image_size)
            if clipped:  # a 16:9 frame of the same width
                size = (size[0], round(size[0] * 9 / 16))
        elif clipped:
            size = _CLIPPED_SIZES[int(rng.integers(len(_CLIPPED_SIZES)))]
        else:
            size = _SIZES[int(rng.choice(len(_SIZES), p=_SIZE_P))]
        w, h = size
        if clipped:
            diameter = h * rng.uniform(1.08, 1.3)
            diameter = min(diameter, 0.92 * w)
        else:
            diameter = min(w, h) * rng.uniform(0.72, 0.88)
        f = 0.5 * diameter * depth / mirror.rim_radius
        cx = (w - 1) / 2 + rng.uniform(-0.02, 0.02) * w
        cy = (h - 1) / 2 + rng.uniform(-0.02, 0.02) * h
        K = ((f, 0.0, cx), (0.0, f, cy), (0.0, 0.0, 1.0))
        D = None
        if "distortion" in flags:
            D = (
                float(rng.uniform(-0.12, 0.08)),
                float(rng.uniform(-0.03, 0.03)),
                float(rng.uniform(-1e-3, 1e-3)),
                float(rng.uniform(-1e-3, 1e-3)),
                0.0,
            )
        u = rng.normal(size=3)
        offset = u / np.linalg.norm(u) * 5.0 * rng.uniform() ** (1 / 3)
        body = random_body(rng) if "body" in flags else None
        photo = Photometric(
            vignette=float(rng.uniform(0.2, 0.5)) if "vignette" in flags else 0.0,
            blur_sigma=float(rng.uniform(0.5, 1.5)) if "blur" in flags else 0.0,
            noise_sigma=float(rng.uniform(1.5, 5.0)) if "noise" in flags else 0.0,
            jpeg_quality=int(rng.integers(70, 96)) if "jpeg" in flags else None,
        )
        yield StressCase(
            index=i,
            seed=int(seed),
            flags=flags,
            image_size=size,
            K=K,
            D=D,
            tilt_deg=float(rng.uniform(0, 5)),
            tilt_azimuth_deg=float(rng.uniform(0, 360)),
            offset_mm=tuple(float(x) for x in offset),
            body=body,
            photometric=photo,
        )


def _reflection_visible(rendering, size, n_sectors=36):
    """Whether the barrel front's silhouette is in the frame and contrasts with its surround."""
    front = np.isin(rendering.labels, FRONT_LABELS).astype(np.uint8)
    if front.sum() < 20:
        return False
    w, h = size
    ys, xs = np.nonzero(front)
    if xs.min() < 3 or ys.min() < 3 or xs.max() > w - 4 or ys.max() > h - 4:
        return False
    k = np.ones((3, 3), np.uint8)
    inner = cv2.erode(front, k, iterations=1).astype(bool) & ~cv2.erode(
        front, k, iterations=3
    ).astype(bool)
    outer = cv2.dilate(front, k, iterations=3).astype(bool) & ~cv2.dilate(
        front, k, iterations=1
    ).astype(bool)
    img = rendering.image
    grey = 0.114 * img[..., 0] + 0.587 * img[..., 1] + 0.299 * img[..., 2]
    cx, cy = xs.mean(), ys.mean()

    def sectors(band):
        yb, xb = np.nonzero(band)
        sec = np.floor((np.arctan2(yb - cy, xb - cx) + np.pi) / (2 * np.pi) * n_sectors)
        return grey[yb, xb], np.minimum(sec.astype(int), n_sectors - 1)

    gi, si = sectors(inner)
    go, so = sectors(outer)
    ok = 0
    for k_ in range(n_sectors):
        a, b = gi[si == k_], go[so == k_]
        if len(a) and len(b) and abs(np.median(a) - np.median(b)) >= 20.0:
            ok += 1
    return ok >= 0.7 * n_sectors


def render_case(case):
    """Render a :class:`StressCase` with its hostile elements and ground truth.

    Returns
    -------
    RealisticRender
    """
    if not isinstance(case, StressCase):
        raise ValueError(f"case must be a StressCase, got {type(case).__name__}")
    camera = case.camera()
    num = CameraNumbers(camera)
    rng = np.random.default_rng([case.seed, case.index, 1])
    flags = case.flags
    room = random_room(rng, dark_floor="dark_floor" in flags)
    holder = None
    if "holder" in flags:
        holder = Holder(
            outer_axes=tuple(float(x) for x in num.rim * rng.uniform(1.1, 1.3, 2)),
            angle_deg=float(rng.uniform(0, 180)),
            kind=str(rng.choice(["white", "black", "metal"])),
        )
    struts = random_struts(rng, camera) if "struts" in flags else ()
    rig = Rig(
        body=case.body if "body" in flags else None,
        holder=holder,
        struts=struts,
        room=room,
        background=_background(rng, case.image_size),
        mirror_gain=float(rng.uniform(0.85, 0.95)),
    )
    rendering = render_rig(camera, rig, case.supersample)
    image = degrade(rendering.image, case.photometric, seed=[case.seed, case.index, 2])
    circles = ()
    visible = False
    if rig.body is not None:
        circles = rig.body.circles()
        if rendering.side_seen:
            circles = circles + ((float(rig.body.r_barrel), float(rig.body.z_box)),)
        visible = _reflection_visible(rendering, case.image_size)
    # far lines: the wall-floor edges, where the scene is seen all around the pixel
    scene = np.isin(rendering.labels, (3,)).astype(np.uint8)
    valid = cv2.erode(scene, np.ones((7, 7), np.uint8)).astype(bool)
    lines = []
    grid = mirror_grid(camera)
    for p1, p2 in room.edges():
        px = far_line_pixels(camera, p1, p2, n_points=40, valid=valid, _grid=grid)
        if len(px) >= 8:
            span = float(np.linalg.norm(px[-1] - px[0]))
            nrm = np.cross(p1, p2)
            lines.append((span, px, nrm / np.linalg.norm(nrm)))
    lines.sort(key=lambda x: -x[0])
    return RealisticRender(
        image=image,
        camera=camera,
        body_circles=tuple(circles),
        flags=flags,
        far_lines=tuple(x[1] for x in lines),
        far_line_normals=tuple(x[2] for x in lines),
        reflection_visible=bool(visible),
        labels=rendering.labels,
        case=case,
    )
