"""What a realistic render holds: the camera's body, the holder, struts, the room, the
photometric degradations, chessboards and the rig that gathers them; the labels of what a ray
meets and the switchable hostile elements (:data:`VARIANTS`)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

VARIANTS = (
    "body",
    "holder",
    "struts",
    "dark_floor",
    "clipped",
    "blur",
    "vignette",
    "noise",
    "jpeg",
    "distortion",
)

#: Per-sample / per-pixel labels: what the (reflected) ray finally meets.
LABELS = {
    "background": 0,  # primary ray misses mirror and holder
    "holder": 1,  # primary ray hits the holder plate around the rim
    "strut": 2,  # primary ray hits a strut before the mirror
    "scene": 3,  # reflected ray sees the room at infinity
    "dark_floor": 4,  # reflected ray sees the dark floor
    "glass": 5,  # reflected ray hits the barrel's front glass
    "front_ring": 6,  # ... the barrel's front ring (between glass and barrel edge)
    "barrel_side": 7,  # ... the barrel's side
    "box": 8,  # ... the camera box behind the barrel
    "strut_reflected": 9,  # ... a strut, seen in the mirror
    "board": 10,  # ... a chessboard (Rig.boards)
}
MIRROR_LABELS = (3, 4, 5, 6, 7, 8, 9, 10)
FRONT_LABELS = (5, 6)


# -- geometry descriptions ----------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class BodyGeometry:
    """The camera's body in the camera frame (z along the optical axis, towards the mirror).

    A lens barrel: the cylinder ``x^2 + y^2 = r_barrel^2`` from the box's front ``z = z_box`` to
    ``z_barrel``, closed by a front disc at ``z_barrel``: dark glass inside ``r_glass`` (with
    an aperture, inner rings of lens elements and specular highlights) and a dark knurled front
    ring outside it. Behind it a box (not a body of revolution): ``|x'| <= w_box``,
    ``|y'| <= h_box``, ``z_box - depth_box <= z <= z_box`` in axes turned by ``box_angle_deg``
    about the optical axis.

    Attributes
    ----------
    r_barrel, z_barrel, r_glass, r_aperture : float
    rings : tuple of float
        Radii of the inner rings (lens element edges) on the glass.
    highlights : tuple of (x, y, radius)
        Bright specular spots on the glass (camera frame, in the front plane).
    z_box, w_box, h_box, depth_box, box_angle_deg : float
    glass_color, ring_color, side_color, box_color : BGR tuples
    """

    r_barrel: float = 12.0
    z_barrel: float = 20.0
    r_glass: float = 10.0
    r_aperture: float = 2.5
    rings: tuple = (5.5, 8.0)
    highlights: tuple = ((3.0, -4.0, 0.8), (-2.0, 3.5, 0.5))
    z_box: float = -5.0
    w_box: float = 22.0
    h_box: float = 17.0
    depth_box: float = 40.0
    box_angle_deg: float = 0.0
    glass_color: tuple = (22.0, 12.0, 10.0)
    ring_color: tuple = (48.0, 46.0, 45.0)
    side_color: tuple = (105.0, 102.0, 100.0)
    box_color: tuple = (52.0, 52.0, 54.0)

    def circles(self):
        """Coaxial circles ``(r, z)`` whose reflections bound the round dark silhouette.

        The barrel's front edge ``(r_barrel, z_barrel)``; the back edge ``(r_barrel, z_box)`` joins
        (by :func:`render_rig`) only when the barrel's side is seen beside it.
        """
        return ((float(self.r_barrel), float(self.z_barrel)),)


@dataclasses.dataclass(frozen=True)
class Holder:
    """A plate in the rim plane around the rim (mirror frame), its outer edge an ellipse.

    Attributes
    ----------
    outer_axes : (float, float)
        Semi-axes of the outer edge (mirror units), each larger than the rim radius.
    angle_deg : float
        Orientation of the first semi-axis, from +X towards +Y.
    kind : {"white", "black", "metal"}
    """

    outer_axes: tuple = (36.0, 33.0)
    angle_deg: float = 0.0
    kind: str = "black"


@dataclasses.dataclass(frozen=True)
class Strut:
    """A thin rod (cylinder of ``radius``) from ``start`` to ``end``, mirror frame."""

    start: tuple
    end: tuple
    radius: float = 0.6
    color: tuple = (25.0, 25.0, 25.0)


@dataclasses.dataclass(frozen=True)
class RoomScene:
    """A room-like scene at infinity: an axis-aligned box seen from the origin (directions).

    The box ``[-half_x, half_x] x [-half_y, half_y] x [-floor, ceiling]`` (metres, in the mirror
    frame turned by ``yaw_deg`` about +Z) gives every direction a wall, floor or ceiling
    colour; its edges (wall-floor lines, vertical corners) and the edges of the rectangles on
    it (doors, posters, windows, rugs) are great circles of directions: straight lines at
    infinity.

    Attributes
    ----------
    half_x, half_y, floor, ceiling, yaw_deg : float
    wall_colors : tuple of 6 BGR
        Surfaces -X, +X, -Y, +Y walls, floor, ceiling.
    rects : tuple of (surface, u0, u1, v0, v1, BGR)
        Flat rectangles on a surface, in its (u, v) coordinates: X walls (y, z), Y walls
        (x, z), floor/ceiling (x, y).
    plank : float
        Floor plank width (m); 0 for a plain floor.
    dark_floor_deg : float or None
        Every direction below this elevation is near-black (a dark floor), or None.
    """

    half_x: float = 2.5
    half_y: float = 3.0
    floor: float = 1.3
    ceiling: float = 1.4
    yaw_deg: float = 0.0
    wall_colors: tuple = (
        (170.0, 180.0, 190.0),
        (140.0, 160.0, 175.0),
        (185.0, 175.0, 160.0),
        (150.0, 170.0, 150.0),
        (70.0, 110.0, 140.0),
        (225.0, 225.0, 225.0),
    )
    rects: tuple = ()
    plank: float = 0.18
    dark_floor_deg: object = None

    def edges(self):
        """The wall-floor edges as 3-D segments ``(p1, p2)`` in the mirror frame (metres)."""
        hx, hy, fl = self.half_x, self.half_y, -self.floor
        corners = [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)]
        c, s = math.cos(math.radians(self.yaw_deg)), math.sin(math.radians(self.yaw_deg))
        out = []
        for i in range(4):
            (x1, y1), (x2, y2) = corners[i], corners[(i + 1) % 4]
            p1 = np.array([c * x1 - s * y1, s * x1 + c * y1, fl])
            p2 = np.array([c * x2 - s * y2, s * x2 + c * y2, fl])
            out.append((p1, p2))
        return out


@dataclasses.dataclass(frozen=True)
class Photometric:
    """Image degradations, applied in this order; 0 / None switches one off.

    Attributes
    ----------
    vignette : float
        Gain ``1 - vignette * (r / r_corner)^2`` about the image centre.
    blur_sigma : float
        Gaussian blur, px.
    noise_sigma : float
        Sensor noise: Gaussian, ``sqrt(noise_sigma^2 + 0.05 * value)`` grey levels.
    jpeg_quality : int or None
        ``cv2.imencode`` JPEG quality (70-95 in the stress cases).
    """

    vignette: float = 0.0
    blur_sigma: float = 0.0
    noise_sigma: float = 0.0
    jpeg_quality: object = None


@dataclasses.dataclass(frozen=True)
class Chessboard:
    """A flat chessboard in the scene (mirror frame), as OpenCV describes one.

    ``pattern_size = (cols, rows)`` inner corners at ``(i s, j s, 0)`` of the board frame
    (``s = square_size``, docs/conventions.md "Pattern calibration"), placed by
    ``X_mirror = R(rvec) X_board + tvec``. The squares cover ``-s <= x <= cols s``,
    ``-s <= y <= rows s`` (the square at the origin's lower left, ``floor(x/s) + floor(y/s)``
    even, is black), inside a white margin of ``margin`` squares; both faces are printed.

    Attributes
    ----------
    pattern_size : (int, int)
    square_size : float
    rvec, tvec : (3,) tuple
    margin : float
        White border around the squares, in squares.
    black, white : BGR tuples
    """

    pattern_size: tuple
    square_size: float
    rvec: tuple
    tvec: tuple
    margin: float = 1.0
    black: tuple = (28.0, 28.0, 30.0)
    white: tuple = (226.0, 230.0, 232.0)


@dataclasses.dataclass(frozen=True)
class Rig:
    """Everything a render needs besides the camera: what sits around the mirror.

    Attributes
    ----------
    body : BodyGeometry or None
    holder : Holder or None
    struts : tuple of Strut
    room : RoomScene
    background : (h, w, 3) float32 ndarray or None
        What the camera sees beside the mirror and holder (None: near-black).
    mirror_gain : float
        Reflectance of the mirror coating.
    boards : tuple of Chessboard
        Chessboards at finite distances, seen in the mirror (none in the stress cases).
    """

    body: object = None
    holder: object = None
    struts: tuple = ()
    room: RoomScene = RoomScene()
    background: object = None
    mirror_gain: float = 0.92
    boards: tuple = ()
