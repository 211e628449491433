"""Renders that look like real rigs: an independent forward renderer for stress tests.

This module shares **nothing** with the estimator: it does not call :mod:`omnicam.raytrace`,
:mod:`omnicam._kernels`, the :class:`~omnicam.mirror.HyperbolicMirror` methods, the camera's
``project``/``unproject`` or any calibration code. It reads a truth
:class:`~omnicam.camera.MisalignedHyperbolicCamera` only as numbers (``K, D, R, tvec`` and the
mirror's ``a, b, rim_radius``) and traces every subpixel itself:

1. camera ray: ``V_C = K^-1 (x, y, 1)`` (eq. 6, after undoing ``D`` with
   ``cv2.undistortPointsIter`` on an identity camera, so skew counts), into the mirror frame
   ``V_M = R^T V_C`` from ``F_M = -R^T tvec`` (eqs. 16-17);
2. the first hit on the sheet ``(X^2 + Y^2)/a^2 - Z^2/b^2 = -1, Z > 0`` (eqs. 1, 8-12) inside
   the rim; before it, struts (thin rods) may occlude the mirror; a ray that misses the mirror
   may hit the holder plate in the rim plane, else it shows the background;
3. the reflection ``V_out = V - 2 N (N, V)`` with the unit normal ``N`` of eq. 14 (eq. 15);
4. the reflected ray meets, nearest first, the camera's own body (a lens barrel coaxial with
   the optical axis with a glass front disc, in front of a wider box), a strut or a chessboard
   (:class:`Chessboard`, a plane at a finite distance, for pattern calibration); otherwise it
   sees a room at infinity (:class:`RoomScene`, looked up by direction only).

Hostile elements (:data:`VARIANTS`), each switchable: the camera body, a holder ring around the
rim, struts across the mirror, a dark floor, a clipped rim, Gaussian blur, vignetting, sensor
noise, JPEG compression and mild lens distortion. The ground truth comes back with the image:
the truth camera, the coaxial circles ``(r, z)`` (camera frame, docs/conventions.md "The
camera's own reflection") whose reflections make the outermost round dark silhouette, far-line
pixels of the room's straight edges (:func:`far_line_pixels`, own bisection) and a label per pixel.

Typical use (the stress benchmark ``benchmarks/bench_stress.py``)::

    for case in stress_cases(100, seed=0):
        r = render_case(case)
        cam, report = MisalignedHyperbolicCamera.calibrate(r.camera.K, r.camera.mirror,
                                                           image=r.image, D=r.camera.D)

Supersampling: pixel ``(x, y)`` covers ``[x - 1/2, x + 1/2]^2``; its ``s x s`` samples sit at
offsets ``(k + 1/2)/s - 1/2`` and their colours are averaged (linear), so edges are area-true.
Samples are taken only near edges (where the centres of a 3x3 neighbourhood disagree);
per-pixel labels are those of the pixel centre.

The renderer is a package, one concern per module: :mod:`.scene` (what a render holds),
:mod:`.optics` (camera rays, the mirror, the reflection), :mod:`.surfaces` (what a ray meets and
its colour), :mod:`.tracer`, :mod:`.render` (images and their degradations), :mod:`.far_lines`
and :mod:`.stress` (random rigs and the stress cases). Its public names are all here.
"""

from __future__ import annotations

from .far_lines import far_line_pixels
from .optics import camera_rays, intersect_mirror, mirror_normal, reflect
from .render import Rendering, degrade, render_rig
from .scene import (
    LABELS,
    VARIANTS,
    BodyGeometry,
    Chessboard,
    Holder,
    Photometric,
    Rig,
    RoomScene,
    Strut,
)
from .stress import (
    RealisticRender,
    StressCase,
    random_body,
    random_room,
    random_struts,
    render_case,
    stress_cases,
)
from .tracer import trace

__all__ = [
    "LABELS",
    "VARIANTS",
    "BodyGeometry",
    "Chessboard",
    "Holder",
    "Photometric",
    "RealisticRender",
    "Rendering",
    "Rig",
    "RoomScene",
    "StressCase",
    "Strut",
    "camera_rays",
    "degrade",
    "far_line_pixels",
    "intersect_mirror",
    "mirror_normal",
    "random_body",
    "random_room",
    "random_struts",
    "reflect",
    "render_case",
    "render_rig",
    "stress_cases",
    "trace",
]
