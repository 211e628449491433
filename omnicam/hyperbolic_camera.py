"""The design's class: :class:`MisalignedHyperbolicCamera`, the model with its entry points.

The model itself (``K``, ``D``, the mirror, the posture, ``project``/``unproject``) is
:class:`omnicam.camera.MisalignedCatadioptricCamera`, at the bottom of the house. This module
sits at the top: its methods are thin calls of the module-level functions that calibrate, load,
save and unwarp (``omnicam.calibrate``, ``omnicam.calibrate_pattern``, ``omnicam.recalibrate``,
``omnicam.load_camera``, ``omnicam.save_camera``, the views), each returning a camera of this
class. Every function that takes a camera takes either class.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, TypeVar, cast

import numpy as np

from . import views
from ._typing import ArrayLike, FloatArray, PathLike, Size
from ._validate import shown
from .camera import MisalignedCatadioptricCamera
from .formats.calibration_file import load_camera, save_camera
from .formats.central_fit import fit_omnidir
from .formats.verdict import Verdict
from .mirror import HyperbolicMirror

if TYPE_CHECKING:  # annotations only; the routes load when calibrating (below)
    from .calibration.report import CalibrationReport
    from .chessboard.report import PatternReport

__all__ = ["MisalignedHyperbolicCamera"]

_Report = TypeVar("_Report", "CalibrationReport", "PatternReport")


class MisalignedHyperbolicCamera(MisalignedCatadioptricCamera):
    """A perspective camera looking at a hyperboloidal mirror in any 5-DOF posture.

    The model of :class:`~omnicam.camera.MisalignedCatadioptricCamera` (its parameters,
    methods and validation) with a :class:`~omnicam.mirror.HyperbolicMirror` (eq. 1), and the
    entry points users call on it: :meth:`calibrate` (one image, paper section 3),
    :meth:`calibrate_pattern` (chessboards), :meth:`recalibrate`, :meth:`load`, :meth:`save`,
    :meth:`to_omnidir` and the view tables (:meth:`init_panorama_maps`,
    :meth:`init_perspective_maps`).

    Raises
    ------
    ValueError
        As the model does, and for a mirror that is not a ``HyperbolicMirror``.
    """

    __slots__ = ()

    def __init__(
        self,
        K: ArrayLike,
        mirror: HyperbolicMirror,
        rvec: ArrayLike,
        tvec: ArrayLike,
        D: ArrayLike | None = None,
        image_size: Size | None = None,
        camera_reflection: tuple[float, float] | None = None,
        verdict: Verdict | None = None,
    ) -> None:
        if not isinstance(mirror, HyperbolicMirror):
            raise ValueError(f"mirror must be a HyperbolicMirror, got {type(mirror).__name__}")
        super().__init__(K, mirror, rvec, tvec, D, image_size, camera_reflection, verdict)

    @classmethod
    def of(cls, camera: MisalignedCatadioptricCamera) -> MisalignedHyperbolicCamera:
        """``camera`` as this class (the same rig; ``ValueError`` if its mirror is no
        hyperboloid)."""
        if type(camera) is cls:
            return camera
        return cls(
            camera.K,
            cast(HyperbolicMirror, camera.mirror),  # a hyperboloid: checked by __init__
            camera.rvec,
            camera.tvec,
            camera.D,
            camera.image_size,
            camera.camera_reflection,
            camera.verdict,
        )

    # -- calibration ------------------------------------------------------------------------
    @classmethod
    def calibrate(
        cls,
        K: ArrayLike,
        mirror: HyperbolicMirror,
        image: np.ndarray | None = None,
        boundary_points: ArrayLike | None = None,
        far_lines: Sequence[ArrayLike] | None = None,
        D: ArrayLike | None = None,
        image_size: Size | None = None,
        refine: bool = True,
        lens: str | bool | ArrayLike | None = "auto",
        **options: Any,
    ) -> tuple[MisalignedHyperbolicCamera, CalibrationReport]:
        """Mirror posture from one image: rim, Chen's method, selection, refinement, checks.

        :func:`omnicam.calibrate` (its ``options``: ``lens_r``, ``lens_z``, ``rim_hint``,
        ``max_tilt_deg``, ``max_offset_mm``, ``check_plausibility``), returning a camera of
        this class and the report.
        """
        from .calibration import calibrate  # the route and scikit-image, only when calibrating

        camera, report = calibrate(
            K,
            mirror,
            image=image,
            boundary_points=boundary_points,
            far_lines=far_lines,
            D=D,
            image_size=image_size,
            refine=refine,
            lens=lens,
            **options,
        )
        return cls._with_report(camera, report)

    def recalibrate(
        self, image: np.ndarray | None = None, **options: Any
    ) -> tuple[MisalignedHyperbolicCamera, CalibrationReport]:
        """The mirror posture alone from one new image, with this rig's ``K``, ``D`` and mirror.

        :func:`omnicam.recalibrate` of this camera (its ``options`` and errors), returning a
        camera of this class and the report.
        """
        from .calibration import recalibrate

        camera, report = recalibrate(self, image, **options)
        return type(self)._with_report(camera, report)

    @classmethod
    def calibrate_pattern(
        cls,
        images: Sequence[np.ndarray | PathLike] | None,
        pattern_size: tuple[int, int],
        square_size: float,
        mirror: HyperbolicMirror | None = None,
        **kw: Any,
    ) -> tuple[MisalignedHyperbolicCamera, PatternReport]:
        """``K``, ``D`` and the posture (and, with ``mirror=None``, the mirror) from chessboards
        seen through the mirror.

        :func:`omnicam.calibrate_pattern` (its options, passed on as they are), returning a
        camera of this class and the report.
        """
        from .chessboard.calibrate import calibrate_pattern

        camera, report = calibrate_pattern(images, pattern_size, square_size, mirror, **kw)
        return cls._with_report(camera, report)

    @classmethod
    def _with_report(
        cls, camera: MisalignedCatadioptricCamera, report: _Report
    ) -> tuple[MisalignedHyperbolicCamera, _Report]:
        """``camera`` as this class, and the report holding that same camera."""
        own = cls.of(camera)
        if getattr(report, "camera", None) is camera:
            report = dataclasses.replace(report, camera=own)
        return own, report

    # -- views --------------------------------------------------------------------------------
    # the view tables take the camera first: the functions are the methods (one signature)
    init_panorama_maps = views.init_panorama_maps
    init_perspective_maps = views.init_perspective_maps

    def to_omnidir(
        self, depth: float | None = None
    ) -> tuple[FloatArray, float, FloatArray, FloatArray, FloatArray, float]:
        """The unified (Mei) model of ``cv2.omnidir`` closest to this rig, and its RMS error.

        Returns ``(K, xi, D, M, origin, rms_px)`` with ``X_omni = M (X_mirror - origin)``
        (``det M = -1``: the image of a mirror is mirror-reversed); see
        :func:`omnicam.formats.central_fit.fit_omnidir`, which also gives the maximum error.
        """
        return fit_omnidir(self, depth=depth).as_tuple()

    # -- files --------------------------------------------------------------------------------
    def save(self, path: PathLike, verdict: object = None) -> None:
        """Write the calibration with ``cv2.FileStorage`` (yaml, yml, xml or json), atomically.

        :func:`omnicam.save_camera` of this camera: the file is written beside ``path``, read
        back and compared, then renamed into place. ``cam.save(path, report)`` also records how
        far to trust it: the report's confidence, stated uncertainty and warnings (the file's
        ``verdict``, read by :func:`omnicam.read_verdict` and ``omnicam info``); a calibrated
        camera carries its report's verdict already, so ``cam.save(path)`` records it too.

        Parameters
        ----------
        path : str or os.PathLike
        verdict : CalibrationReport, PatternReport or omnicam.Verdict, optional
            What the calibration's report said (a report is taken as
            :meth:`omnicam.Verdict.from_report` of it); None records the verdict this camera
            carries (:attr:`verdict`: the calibration routes set it, :meth:`load` gives it
            back), none if it carries none.

        Raises
        ------
        ValueError
            Unknown extension, or the file cannot be written (missing or read-only folder, full
            disk, ...), naming the file; the old file at ``path`` is then unchanged.
        """
        save_camera(self, path, verdict)

    @classmethod
    def load(cls, path: PathLike) -> MisalignedHyperbolicCamera:
        """Read a calibration file written by :meth:`save`, validating every field.

        :func:`omnicam.load_camera`, as this class.

        Raises
        ------
        FileNotFoundError
            No file at ``path``.
        ValueError
            Anything else (see :func:`omnicam.formats.calibration_file.load_camera`), naming the
            file and the field; a file of a mirror that is no hyperboloid (format 2), saying to
            read it with :func:`omnicam.load_camera`.
        """
        camera = load_camera(path)
        if not isinstance(camera.mirror, HyperbolicMirror):
            raise ValueError(
                f"calibration file {shown(path)}: its mirror is an even asphere (format_version "
                f"2), not a hyperboloid; MisalignedHyperbolicCamera is the hyperboloid's: read "
                f"it with omnicam.load_camera, which returns a MisalignedCatadioptricCamera"
            )
        return cls.of(camera)
