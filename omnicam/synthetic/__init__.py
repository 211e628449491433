"""Synthetic rigs and ground-truth renders for tests, examples and benchmarks (paper Fig. 6).

The rigs here are the canonical ones every test, example and benchmark uses: a HyperOmni-style
mirror seen by a 500x500 camera (the paper's synthetic image size), aligned or misaligned.

The renderer shows what such a rig sees, by ray tracing every subpixel with
:meth:`~omnicam.camera.MisalignedHyperbolicCamera.unproject`:

* :func:`render_environment`: a scene at infinity given as an equirectangular image
  (:func:`make_environment` builds a procedural one), looked up by the reflected direction;
* :func:`render_room`: a box-shaped room with checker walls and a cube at finite distance
  (:class:`Room`), hit by the reflected rays from their mirror points;
* both with the dark housing outside the rim (pixels whose ray misses the mirror), the camera's
  own reflection near the centre (reflected rays that come back to a dark ball around the
  camera centre, with a darker lens facing the mirror), ``s x s`` supersampling and optional
  seeded noise.

Equirectangular mapping (the panorama convention of ``docs/conventions.md`` over the full sphere):
in an environment of ``W x H`` pixels, pixel centres at integer coordinates, column ``x`` looks
at azimuth ``-360 * x / W`` degrees (azimuth in the mirror frame from +X towards +Y; wraps
around) and row ``y`` at elevation ``90 - 180 * y / (H - 1)`` degrees (row 0 is the zenith
+Z, row ``H - 1`` the nadir). An ``equirectangular`` panorama over ``(-90, 90)`` of the same size
made from a render therefore reproduces the environment.

Supersampling: pixel ``(x, y)`` covers ``[x - 1/2, x + 1/2] x [y - 1/2, y + 1/2]``; its ``s x s``
samples sit at offsets ``(k + 1/2) / s - 1/2``, their colours are averaged in float (the image
values taken as linear, no gamma) and rounded once, so an edge's pixel value is its area
coverage and edges are subpixel-true.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from ..camera import MisalignedCatadioptricCamera
from ..hyperbolic_camera import MisalignedHyperbolicCamera
from ..mirror import HyperbolicMirror

__all__ = [
    "default_mirror",
    "aligned_rig",
    "misaligned_rig",
    "random_misaligned_rig",
    "equirect_directions",
    "equirect_coords",
    "make_environment",
    "render_environment",
    "Room",
    "render_room",
    "HOUSING_COLOR",
    "line_pixels",
    "far_line_pixels",
]

#: BGR colour of the housing (mirror holder) outside the rim.
HOUSING_COLOR = (18, 18, 18)
_BODY_COLOR = (58, 56, 54)  # camera body seen in the mirror
_LENS_COLOR = (14, 6, 4)  # its lens (dark bluish glass), facing the mirror
_LENS_COS = 0.6  # lens = the part of the ball within ~53 deg of the optical axis
_CHUNK_RAYS = 1 << 18  # rays traced per chunk (memory stays at a few tens of MB)


def default_mirror():
    """A HyperOmni-style mirror: ``a = 23.4``, ``b = 28.1``, rim radius 30 mm.

    Seen from the lower focus it shows elevations from -90 deg up to about +17 deg.
    """
    return HyperbolicMirror(23.4, 28.1, 30.0)


def _default_K(image_size, mirror, fill):
    """Pinhole whose aligned rim image spans ``fill`` of the shorter image side."""
    w, h = image_size
    # aligned rim: radius r at depth z_rim + c from the camera
    f = 0.5 * fill * min(w, h) * (mirror.z_rim + mirror.c) / mirror.rim_radius
    return np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])


def aligned_rig(image_size=(500, 500), mirror=None, fill=0.85):
    """The aligned HyperOmni rig (eqs. 2-5): camera at the lower focus, axes parallel."""
    mirror = mirror or default_mirror()
    K = _default_K(image_size, mirror, fill)
    return MisalignedHyperbolicCamera.aligned(mirror, K[0, 0], K[0, 2], K[1, 2], image_size)


def misaligned_rig(
    tilt_deg=3.0,
    tilt_azimuth_deg=30.0,
    offset_mm=(1.5, -1.0, 1.0),
    image_size=(500, 500),
    mirror=None,
    fill=0.85,
    D=None,
):
    """A misaligned rig: the mirror axis tilted by ``tilt_deg`` towards ``tilt_azimuth_deg``
    (in the camera's x-y plane) and its origin moved by ``offset_mm`` (camera frame) from the
    aligned position ``(0, 0, c)``.
    """
    mirror = mirror or default_mirror()
    K = _default_K(image_size, mirror, fill)
    phi = np.deg2rad(tilt_azimuth_deg)
    rvec = np.deg2rad(tilt_deg) * np.array([-np.sin(phi), np.cos(phi), 0.0])
    tvec = np.array([0.0, 0.0, mirror.c]) + np.asarray(offset_mm, dtype=np.float64)
    return MisalignedHyperbolicCamera(K, mirror, rvec, tvec, D=D, image_size=image_size)


def random_misaligned_rig(
    rng, max_tilt_deg=5.0, max_offset_mm=5.0, image_size=(500, 500), mirror=None, fill=0.85
):
    """A random rig with tilt up to ``max_tilt_deg`` and offset norm up to ``max_offset_mm``."""
    tilt = rng.uniform(0.0, max_tilt_deg)
    az = rng.uniform(0.0, 360.0)
    v = rng.normal(size=3)
    offset = v / np.linalg.norm(v) * rng.uniform(0.0, max_offset_mm)
    return misaligned_rig(tilt, az, offset, image_size=image_size, mirror=mirror, fill=fill)


# -- the equirectangular mapping -----------------------------------------------------------
def _check_size(size, name="size"):
    try:
        w, h = (int(v) for v in size)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be (width, height), got {size!r}") from None
    if w < 2 or h < 2:
        raise ValueError(f"{name} must be at least (2, 2), got {size!r}")
    return w, h


def equirect_directions(size):
    """Unit directions of the pixels of an equirectangular image (the module's mapping).

    Parameters
    ----------
    size : (int, int)
        ``(W, H)`` of the image.

    Returns
    -------
    directions : (H, W, 3) float64 ndarray
        Column ``x``: azimuth ``-2 pi x / W``; row ``y``: elevation ``pi/2 - pi y / (H - 1)``;
        mirror frame, ``(cos el cos az, cos el sin az, sin el)``.
    """
    w, h = _check_size(size)
    az = -2.0 * np.pi * np.arange(w) / w
    el = 0.5 * np.pi - np.pi * np.arange(h) / (h - 1)
    ce = np.cos(el)[:, None]
    return np.stack(
        [
            ce * np.cos(az)[None, :],
            ce * np.sin(az)[None, :],
            np.broadcast_to(np.sin(el)[:, None], (h, w)),
        ],
        axis=-1,
    )


def equirect_coords(directions, size):
    """Pixel coordinates ``(x, y)`` of directions in an equirectangular image of ``size``.

    The inverse of :func:`equirect_directions`: ``x = (-az * W / 2 pi) mod W`` in ``[0, W)``,
    ``y = (pi/2 - el) * (H - 1) / pi`` in ``[0, H - 1]``.

    Parameters
    ----------
    directions : (..., 3) array_like
        Directions in the mirror frame (need not be unit; zero or NaN rows give NaN).
    size : (int, int)
        ``(W, H)``.

    Returns
    -------
    x, y : (...) float64 ndarrays
    """
    w, h = _check_size(size)
    d = np.asarray(directions, dtype=np.float64)
    if d.shape[-1:] != (3,):
        raise ValueError(f"directions must have shape (..., 3), got {d.shape}")
    horiz = np.hypot(d[..., 0], d[..., 1])
    with np.errstate(invalid="ignore"):
        bad = ~(horiz + np.abs(d[..., 2]) > 0)
    az = np.arctan2(d[..., 1], d[..., 0])
    el = np.arctan2(d[..., 2], horiz)
    x = np.mod(-az * (w / (2.0 * np.pi)), w)
    x = np.where(x >= w, 0.0, x)  # mod can round up to w
    y = (0.5 * np.pi - el) * ((h - 1) / np.pi)
    return np.where(bad, np.nan, x), np.where(bad, np.nan, y)


def _sample_equirect(env, d):
    """Bilinear lookup of ``env`` ((H, W, 3) float32) at unit directions ``d`` (N, 3)."""
    h, w = env.shape[:2]
    x, y = equirect_coords(d, (w, h))
    x0 = np.floor(x)
    fx = (x - x0).astype(np.float32)[:, None]
    x0 = x0.astype(np.intp) % w
    x1 = (x0 + 1) % w  # azimuth wraps around
    y0 = np.minimum(np.floor(y), h - 2)
    fy = (y - y0).astype(np.float32)[:, None]
    y0 = y0.astype(np.intp)
    flat = env.reshape(-1, 3)
    r0 = y0 * w
    r1 = r0 + w
    top = flat[r0 + x0] * (1.0 - fx) + flat[r0 + x1] * fx
    bot = flat[r1 + x0] * (1.0 - fx) + flat[r1 + x1] * fx
    return top * (1.0 - fy) + bot * fy


# -- the procedural environment ---------------------------------------------------------------
def make_environment(
    size=(2048, 1024),
    pole_spacing_deg=30.0,
    line_elevations_deg=(10.0, 0.0, -15.0, -30.0, -50.0, -70.0),
    checker_deg=(15.0, 10.0),
    line_width_deg=0.6,
):
    """A procedural scene at infinity whose distortion is easy to see in a panorama.

    Sky gradient above the horizon; below it a checker of ``checker_deg = (azimuth, elevation)``
    cells in two earthy tones; thin dark horizontal lines (constant elevation, straight rows in
    a panorama) at ``line_elevations_deg``; vertical poles every ``pole_spacing_deg`` of azimuth
    from -85 to +15 deg elevation, the one at azimuth 0 red and wider, the others alternately
    near-black and white, so the orientation of a panorama can be read off.

    Far straight lines (section 3.2): the poles (vertical great circles, the pole at azimuth
    ``phi`` holds the directions ``(cos el cos phi, cos el sin phi, sin el)``) and the horizon
    line at elevation 0 are images of straight lines at infinity; the other horizontal lines
    are circles of constant elevation, straight only in a panorama.

    Parameters
    ----------
    size : (int, int)
        ``(W, H)``; the mapping is the module's (column ``x``: azimuth ``-360 x / W`` deg, row
        ``y``: elevation ``90 - 180 y / (H - 1)`` deg).
    pole_spacing_deg : float
    line_elevations_deg : sequence of float
    checker_deg : (float, float)
    line_width_deg : float
        Width of lines and poles (the red pole is twice as wide).

    Returns
    -------
    environment : (H, W, 3) uint8 ndarray, BGR
    """
    w, h = _check_size(size)
    if not (pole_spacing_deg > 0 and line_width_deg > 0 and min(checker_deg) > 0):
        raise ValueError("pole_spacing_deg, line_width_deg and checker_deg must be positive")
    az = np.mod(-360.0 * np.arange(w) / w, 360.0)  # azimuth of each column
    el = 90.0 - 180.0 * np.arange(h) / (h - 1)  # elevation of each row
    img = np.empty((h, w, 3), np.float32)
    # sky: pale near the horizon, deeper blue at the zenith (BGR)
    t = np.clip(el / 90.0, 0.0, 1.0)[:, None, None]
    img[:] = (1 - t) * np.float32([250, 225, 200]) + t * np.float32([200, 120, 60])
    # ground: checker in azimuth x elevation cells, two earthy tones
    below = el < 0.0
    parity = (
        np.floor(az[None, :] / checker_deg[0]) + np.floor(-el[below, None] / checker_deg[1])
    ).astype(np.int64) & 1
    img[below] = np.where(
        parity[..., None] == 1, np.float32([90, 140, 160]), np.float32([60, 95, 120])
    )
    half = 0.5 * line_width_deg
    # horizontal lines: straight rows of a panorama
    for e in line_elevations_deg:
        img[np.abs(el - e) <= half] = (30, 30, 30)
    # vertical poles: columns within half a width of a multiple of the spacing
    rows = np.flatnonzero((el >= -85.0) & (el <= 15.0))
    n_poles = max(1, int(round(360.0 / pole_spacing_deg)))
    k = np.round(az / pole_spacing_deg).astype(np.int64)
    dist = np.abs(az - k * pole_spacing_deg)
    k %= n_poles
    red = (k == 0) & (dist <= 2 * half)
    other = (k != 0) & (dist <= half)
    pole = np.where((k % 2 == 1)[:, None], np.float32([245, 245, 245]), np.float32([25, 25, 25]))
    pole[red] = (30, 30, 220)
    cols = np.flatnonzero(red | other)
    img[np.ix_(rows, cols)] = pole[cols][None, :, :]
    return np.round(img).astype(np.uint8)


# -- the room ---------------------------------------------------------------------------------
def _bgr(value, name):
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape[-1:] != (3,) or not np.isfinite(arr).all() or (arr < 0).any() or (arr > 255).any():
        raise ValueError(f"{name} must hold BGR colours (3 numbers in [0, 255]), got {value!r}")
    return arr


@dataclasses.dataclass(frozen=True)
class Room:
    """A box-shaped room with checker surfaces and a cube, in the mirror frame (mm).

    The defaults suit :func:`default_mirror` rigs, whose viewpoint is near the outer focus
    ``(0, 0, 36.6)``: a 5 x 5 x 2.5 m room whose floor is 850 mm below the mirror origin, and a
    300 mm cube standing on the floor inside one floor square, its centre ``(1250, 250, -700)``
    about 1.47 m from the viewpoint (29.5 deg below the horizon, azimuth 11.3 deg), turned about
    the vertical so that its two visible side faces are seen at 45 deg; from the mirror three
    faces are visible (``+Z`` on top, pale yellow; ``-X``, near-black navy; ``+Y``, green;
    cube frame): :meth:`cube_faces` and :meth:`face_normals` give the ground truth.

    Attributes
    ----------
    box_min, box_max : (3,) floats
        Opposite corners of the room (axis-aligned in the mirror frame).
    checker_size : float
        Side of the checker squares on walls, floor and ceiling; squares have corners on the
        multiples of ``checker_size`` in the mirror frame.
    cube_center : (3,) floats
    cube_size : float
        Edge length.
    cube_rvec : (3,) floats
        Rotation of the cube: ``X_mirror = R(cube_rvec) X_cube + cube_center``, the cube frame
        having its faces at ``+-cube_size / 2``.
    wall_colors : (6, 2, 3) BGR
        The checker's two colours for the surfaces ``-X, +X, -Y, +Y`` walls, floor ``-Z`` and
        ceiling ``+Z``.
    cube_colors : (6, 3) BGR
        Flat colours of the cube faces ``+X, -X, +Y, -Y, +Z, -Z`` (cube frame).
    """

    box_min: tuple = (-2500.0, -2500.0, -850.0)
    box_max: tuple = (2500.0, 2500.0, 1650.0)
    checker_size: float = 500.0
    cube_center: tuple = (1250.0, 250.0, -700.0)
    cube_size: float = 300.0
    cube_rvec: tuple = (0.0, 0.0, math.radians(45.0) + math.atan2(250.0, 1250.0))
    wall_colors: tuple = (
        ((150, 160, 120), (120, 130, 95)),  # -X: teal-grey
        ((120, 150, 170), (95, 120, 140)),  # +X: beige
        ((160, 140, 140), (130, 112, 112)),  # -Y: lilac-grey
        ((130, 165, 140), (105, 135, 112)),  # +Y: sage
        ((185, 195, 200), (160, 172, 178)),  # floor: light
        ((215, 215, 215), (195, 195, 195)),
    )  # ceiling
    cube_colors: tuple = (
        (60, 60, 200),
        (30, 20, 10),
        (40, 170, 60),
        (110, 40, 200),
        (140, 245, 255),
        (90, 90, 90),
    )

    def __post_init__(self):
        lo = np.asarray(self.box_min, np.float64)
        hi = np.asarray(self.box_max, np.float64)
        if (
            lo.shape != (3,)
            or hi.shape != (3,)
            or not (np.isfinite(lo).all() and np.isfinite(hi).all())
        ):
            raise ValueError("box_min and box_max must be 3 finite numbers each")
        if not (lo < hi).all():
            raise ValueError(
                f"box_min must be below box_max on every axis, got {self.box_min}, {self.box_max}"
            )
        if not (self.checker_size > 0 and self.cube_size > 0):
            raise ValueError("checker_size and cube_size must be positive")
        c = np.asarray(self.cube_center, np.float64)
        r = np.asarray(self.cube_rvec, np.float64)
        if c.shape != (3,) or r.shape != (3,) or not np.isfinite(np.r_[c, r]).all():
            raise ValueError("cube_center and cube_rvec must be 3 finite numbers each")
        if _bgr(self.wall_colors, "wall_colors").shape != (6, 2, 3):
            raise ValueError(
                "wall_colors must be (6, 2, 3): two BGR colours for -X, +X, -Y, +Y, floor, ceiling"
            )
        if _bgr(self.cube_colors, "cube_colors").shape != (6, 3):
            raise ValueError(
                "cube_colors must be (6, 3): BGR colours of faces +X, -X, +Y, -Y, +Z, -Z"
            )
        corners = self.cube_corners()
        tol = 1e-6 * float(np.abs(hi - lo).max())
        if (corners < lo - tol).any() or (corners > hi + tol).any():
            raise ValueError("the cube must lie inside the room box")

    @property
    def cube_R(self):
        """(3, 3) rotation cube frame -> mirror frame, ``cv2.Rodrigues(cube_rvec)``."""
        return cv2.Rodrigues(np.asarray(self.cube_rvec, np.float64).reshape(3, 1))[0]

    def cube_corners(self):
        """The 8 corners of the cube, ``(8, 3)``, mirror frame.

        Corner ``i`` has cube-frame coordinates ``s/2 * (+-1, +-1, +-1)`` with the signs of bits
        0 (x), 1 (y) and 2 (z) of ``i`` (bit set = ``+``).
        """
        i = np.arange(8)
        local = (
            0.5
            * self.cube_size
            * np.stack(
                [
                    np.where(i & 1, 1.0, -1.0),
                    np.where(i & 2, 1.0, -1.0),
                    np.where(i & 4, 1.0, -1.0),
                ],
                axis=1,
            )
        )
        return local @ self.cube_R.T + np.asarray(self.cube_center, np.float64)

    def cube_faces(self):
        """Corners of the six faces ``+X, -X, +Y, -Y, +Z, -Z``, ``(6, 4, 3)``, mirror frame.

        Each face's corners go counter-clockwise seen from outside the cube (so its outward
        normal is ``(p1 - p0) x (p2 - p1)``); :meth:`face_normals` gives the unit normals.
        """
        idx = np.array(
            [[1, 3, 7, 5], [0, 4, 6, 2], [2, 6, 7, 3], [0, 1, 5, 4], [4, 5, 7, 6], [0, 2, 3, 1]]
        )
        return self.cube_corners()[idx]

    def face_normals(self):
        """Outward unit normals of the faces ``+X, -X, +Y, -Y, +Z, -Z``, ``(6, 3)``, mirror
        frame."""
        R = self.cube_R
        return np.concatenate([R.T, -R.T], axis=0)[[0, 3, 1, 4, 2, 5]]

    def visible_faces(self, viewpoint):
        """Indices of the faces whose outer side faces ``viewpoint`` ((3,), mirror frame)."""
        p = np.asarray(viewpoint, np.float64)
        centres = self.cube_faces().mean(axis=1)
        return np.flatnonzero(np.einsum("ij,ij->i", self.face_normals(), p - centres) > 0)


def _shade_room(room, P, d):
    """Colours ((N, 3) float32) of rays ``P + t d`` inside ``room``: box surfaces, then the cube."""
    n = len(P)
    rows = np.arange(n)
    lo = np.asarray(room.box_min, np.float64)
    hi = np.asarray(room.box_max, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        # exit through the box: per axis the plane ahead of the ray (inf if parallel)
        t_axis = (np.where(d > 0, hi, lo) - P) / d
    t_axis[~(d != 0)] = np.inf
    axis = np.argmin(t_axis, axis=1)
    t_exit = t_axis[rows, axis]
    X = P + t_exit[:, None] * d
    surface = 2 * axis + (d[rows, axis] > 0)  # -X, +X, -Y, +Y, floor, ceiling
    # in-plane coordinates: walls x (y, z), walls y (x, z), floor/ceiling (x, y)
    u = np.where(axis == 0, X[:, 1], X[:, 0])
    v = np.where(axis == 2, X[:, 1], X[:, 2])
    cs = room.checker_size
    parity = (np.floor(u / cs) + np.floor(v / cs)).astype(np.int64) & 1
    table = np.asarray(room.wall_colors, np.float32).reshape(12, 3)
    colours = table[2 * surface + parity]
    # the cube: rays that pass its bounding sphere, then the slab test in the cube frame
    c = np.asarray(room.cube_center, np.float64)
    h = 0.5 * room.cube_size
    w = c - P
    tc = np.einsum("ij,ij->i", w, d)
    near = np.flatnonzero(
        (np.einsum("ij,ij->i", w, w) - tc * tc <= 3.0 * h * h) & (tc > -math.sqrt(3.0) * h)
    )
    if len(near):
        R = room.cube_R
        Pl = (P[near] - c) @ R
        dl = d[near] @ R
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-h - Pl) / dl
            t2 = (h - Pl) / dl
        tmin = np.fmin(t1, t2)
        tmax = np.fmax(t1, t2)
        # a ray parallel to a slab: inside it (any t) or outside it (never)
        inside = np.abs(Pl) <= h
        par = dl == 0
        tmin[par] = np.where(inside[par], -np.inf, np.inf)
        tmax[par] = np.where(inside[par], np.inf, -np.inf)
        k = np.arange(len(near))
        face_axis = np.argmax(tmin, axis=1)
        t_near = tmin[k, face_axis]
        hit = (t_near <= tmax.min(axis=1)) & (t_near > 0) & (t_near < t_exit[near])
        # entering through the + face when moving towards -axis: faces +X, -X, +Y, -Y, +Z, -Z
        face = 2 * face_axis[hit] + (dl[k[hit], face_axis[hit]] > 0)
        colours[near[hit]] = np.asarray(room.cube_colors, np.float32)[face]
    return colours


# -- rendering --------------------------------------------------------------------------------
def check_camera(camera):
    """The camera's image size; ``ValueError`` unless it is a camera with one."""
    if not isinstance(camera, MisalignedCatadioptricCamera):
        raise ValueError(
            f"camera must be a MisalignedHyperbolicCamera (or MisalignedCatadioptricCamera), "
            f"got {type(camera).__name__}"
        )
    if camera.image_size is None:
        raise ValueError("camera has no image_size; construct it with image_size=(width, height)")
    return camera.image_size


def _check_supersample(supersample):
    if (
        isinstance(supersample, bool)
        or not isinstance(supersample, (int, np.integer))
        or not 1 <= supersample <= 16
    ):
        raise ValueError(f"supersample must be an integer from 1 to 16, got {supersample!r}")
    return int(supersample)


def _body_hits(camera, P, d, radius):
    """Rays that hit the camera's ball (radius ``radius`` about the camera centre): colours."""
    C = camera.camera_center
    w = P - C
    b = np.einsum("ij,ij->i", w, d)
    disc = b * b - (np.einsum("ij,ij->i", w, w) - radius * radius)
    with np.errstate(invalid="ignore"):
        t = -b - np.sqrt(disc)
    hit = (disc >= 0) & (t > 0)
    axis = camera.R[2]  # camera +z (optical axis) in the mirror frame
    cosang = ((w[hit] + t[hit, None] * d[hit]) @ axis) / radius
    col = np.where((cosang > _LENS_COS)[:, None], np.float32(_LENS_COLOR), np.float32(_BODY_COLOR))
    return hit, col.astype(np.float32)


def _render(camera, shade, supersample, noise, seed, housing_color, body_radius, background):
    """Shared loop: trace subpixels in chunks of rows, shade, average, add noise, round.

    A pixel is ``sum(mirror samples) / s^2 + (1 - coverage) * housing``, so pixels wholly
    outside the rim keep the housing (or ``background``) value exactly.
    """
    w, h = check_camera(camera)
    s = _check_supersample(supersample)
    housing = _bgr(housing_color, "housing_color").astype(np.float32)
    if housing.shape != (3,):
        raise ValueError("housing_color must be one BGR colour")
    if not (np.isfinite(noise) and noise >= 0):
        raise ValueError(f"noise must be a non-negative number (grey levels), got {noise!r}")
    if body_radius is not None and not (np.isfinite(body_radius) and body_radius > 0):
        raise ValueError(f"body_radius must be positive or None, got {body_radius!r}")
    if background is None:
        img = np.empty((h, w, 3), np.float32)
        img[:] = housing
    else:
        img = np.array(background, dtype=np.float32)
        if img.shape != (h, w, 3) or not np.isfinite(img).all():
            raise ValueError(
                f"background must be a finite ({h}, {w}, 3) image (the camera's "
                f"image_size), got shape {img.shape}"
            )
    # only the rim's bounding box can see the mirror
    rim = camera.rim_image_points(1440)
    x_lo = max(0, int(np.floor(np.nanmin(rim[:, 0]))) - 2)
    x_hi = min(w - 1, int(np.ceil(np.nanmax(rim[:, 0]))) + 2)
    y_lo = max(0, int(np.floor(np.nanmin(rim[:, 1]))) - 2)
    y_hi = min(h - 1, int(np.ceil(np.nanmax(rim[:, 1]))) + 2)
    if x_lo <= x_hi and y_lo <= y_hi:
        off = (np.arange(s) + 0.5) / s - 0.5  # subpixel offsets about the centre
        xs = (np.arange(x_lo, x_hi + 1)[:, None] + off[None, :]).ravel()
        nx = x_hi - x_lo + 1
        rows_per_chunk = max(1, _CHUNK_RAYS // (nx * s * s))
        for y0 in range(y_lo, y_hi + 1, rows_per_chunk):
            y1 = min(y_hi + 1, y0 + rows_per_chunk)
            ny = y1 - y0
            ys = (np.arange(y0, y1)[:, None] + off[None, :]).ravel()
            pix = np.empty((len(ys), len(xs), 2))
            pix[..., 0] = xs
            pix[..., 1] = ys[:, None]
            P, d = camera.unproject(pix.reshape(-1, 2))
            seen = np.isfinite(d[:, 0])
            if not seen.any():
                continue
            col = np.zeros((len(P), 3), np.float32)
            ok = np.flatnonzero(seen)
            Pk, dk = P[ok], d[ok]
            if body_radius is not None:
                hit, body_col = _body_hits(camera, Pk, dk, body_radius)
                col[ok[hit]] = body_col
                ok, Pk, dk = ok[~hit], Pk[~hit], dk[~hit]
            if len(ok):
                col[ok] = shade(Pk, dk)
            mirror = col.reshape(ny, s, nx, s, 3).sum(axis=(1, 3)) / (s * s)
            coverage = seen.reshape(ny, s, nx, s).sum(axis=(1, 3)) / (s * s)
            block = img[y0:y1, x_lo : x_hi + 1]
            block *= (1.0 - coverage)[..., None].astype(np.float32)
            block += mirror
    if noise > 0:
        img += np.random.default_rng(seed).normal(0.0, noise, img.shape).astype(np.float32)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def render_environment(
    camera,
    environment=None,
    supersample=4,
    noise=0.0,
    seed=None,
    housing_color=HOUSING_COLOR,
    body_radius=10.0,
    background=None,
):
    """What the rig sees of a scene at infinity (paper Fig. 6).

    Every subpixel is traced to its reflected ray (:meth:`MisalignedHyperbolicCamera.unproject`)
    and takes the environment's colour in the ray's direction (bilinear, azimuth wrapping
    around); the ray's origin plays no part (the scene is at infinity).

    Parameters
    ----------
    camera : MisalignedHyperbolicCamera
        Must have ``image_size``; the image is ``image_size`` (w, h).
    environment : (H, W, 3) array_like or None
        Equirectangular BGR image (values in 0..255, any numeric dtype; results are clipped to
        uint8) with the module's mapping: column ``x`` at azimuth ``-360 x / W`` deg (azimuth
        from +X towards +Y, mirror frame), row ``y`` at elevation ``90 - 180 y / (H - 1)`` deg.
        ``None`` uses :func:`make_environment`.
    supersample : int
        ``s``: ``s x s`` samples per pixel, averaged (1 = pixel centres only).
    noise : float
        Standard deviation of Gaussian noise added before rounding, in grey levels.
    seed : int, numpy.random.Generator or None
        Seed of the noise (``numpy.random.default_rng(seed)``).
    housing_color : BGR
        Colour of pixels whose ray misses the mirror (outside the rim).
    body_radius : float or None
        Radius (mirror units) of the dark ball about :attr:`camera_center` standing for the
        camera: reflected rays that hit it show the camera body, with a near-black lens on the
        side facing the mirror. ``None``: no camera reflection.
    background : (h, w, 3) array_like or None
        An image shown where rays miss the mirror, in place of the flat ``housing_color``
        (a textured holder, clutter around the mirror); rim pixels mix it by coverage.

    Returns
    -------
    image : (h, w, 3) uint8 ndarray, BGR
    """
    check_camera(camera)
    if environment is None:
        environment = make_environment()
    env = np.asarray(environment)
    if env.ndim != 3 or env.shape[2] != 3 or env.shape[0] < 2 or env.shape[1] < 2:
        raise ValueError(f"environment must be an (H, W, 3) BGR image, got shape {env.shape}")
    if not (np.issubdtype(env.dtype, np.integer) or np.issubdtype(env.dtype, np.floating)):
        raise ValueError(f"environment must be a numeric image, got dtype {env.dtype}")
    env = np.ascontiguousarray(env, dtype=np.float32)
    if not np.isfinite(env).all():
        raise ValueError("environment must be finite")
    return _render(
        camera,
        lambda P, d: _sample_equirect(env, d),
        supersample,
        noise,
        seed,
        housing_color,
        body_radius,
        background,
    )


def render_room(
    camera,
    room=None,
    supersample=4,
    noise=0.0,
    seed=None,
    housing_color=HOUSING_COLOR,
    body_radius=10.0,
    background=None,
):
    """What the rig sees of a room at finite distance: checker box and a cube (:class:`Room`).

    Every subpixel is traced to its reflected ray ``P + t d`` (mirror point ``P``, unit
    direction ``d``, :meth:`MisalignedHyperbolicCamera.unproject`); it takes the flat colour of
    the first surface hit: the cube (exact ray-box slab test in the cube frame) or the room's
    wall, floor or ceiling (checker). No lighting: colour boundaries are exactly the geometric
    edges, so the cube's corners can be located in unwarped views.

    Parameters
    ----------
    camera : MisalignedHyperbolicCamera
        Must have ``image_size``.
    room : Room or None
        ``None`` uses ``Room()``. The mirror and the camera must be inside the room box.
    supersample, noise, seed, housing_color, body_radius, background
        As for :func:`render_environment`.

    Returns
    -------
    image : (h, w, 3) uint8 ndarray, BGR
    """
    check_camera(camera)
    room = Room() if room is None else room
    if not isinstance(room, Room):
        raise ValueError(f"room must be a Room, got {type(room).__name__}")
    m = camera.mirror
    # the camera and the whole mirror cap (rim circle and apex) must be inside the box
    rig = np.vstack([camera.camera_center, m.rim_points(16), [0.0, 0.0, m.b]])
    if not ((rig > np.asarray(room.box_min)) & (rig < np.asarray(room.box_max))).all():
        raise ValueError(
            "the camera and the mirror must be inside the room box "
            f"(box_min={room.box_min}, box_max={room.box_max})"
        )
    return _render(
        camera,
        lambda P, d: _shade_room(room, P, d),
        supersample,
        noise,
        seed,
        housing_color,
        body_radius,
        background,
    )


def line_pixels(camera, start, end, n=30):
    """Pixels of ``n`` points evenly spaced on the 3-D segment ``start``-``end`` (mirror frame).

    Exact non-central projection (:meth:`MisalignedHyperbolicCamera.project`); points the rig
    cannot see are left out, so fewer than ``n`` rows may come back.

    Returns
    -------
    pixels : (M, 2) float64 ndarray
    """
    t = np.linspace(0.0, 1.0, int(n))[:, None]
    start = np.asarray(start, dtype=np.float64)
    pts = start + t * (np.asarray(end, dtype=np.float64) - start)
    px = camera.project(pts)
    return px[np.isfinite(px).all(axis=1)]


def far_line_pixels(
    camera, n_lines=3, n_points=30, distance=(10e3, 50e3), elevation_deg=(-60.0, 5.0), rng=0
):
    """Pixels of far straight lines, as a user would click them for section 3.2's selection.

    Each line passes at a random distance in ``distance`` (mm) from the mirror origin, at a
    random azimuth and an elevation in ``elevation_deg``, along a random direction across the
    line of sight; its ``n_points`` points span a stretch as long as that distance. Lines with
    fewer than 5 visible points are drawn again. ``rng`` is a seed or a ``numpy`` Generator.

    Returns
    -------
    list of (N_i, 2) float64 ndarray
        One array per line, the ``far_lines`` argument of ``calibrate``.
    """
    rng = np.random.default_rng(rng)
    lines = []
    while len(lines) < n_lines:
        dist = rng.uniform(*distance)
        az = rng.uniform(0.0, 2.0 * np.pi)
        el = np.deg2rad(rng.uniform(*elevation_deg))
        p = dist * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        d = rng.normal(size=3)
        d -= d @ p / (p @ p) * p
        d *= 0.5 * dist / np.linalg.norm(d)
        px = line_pixels(camera, p - d, p + d, n_points)
        if len(px) >= 5:
            lines.append(px)
    return lines
