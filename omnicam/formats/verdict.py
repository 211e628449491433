"""How far to trust a calibration: the :class:`Verdict` a calibration file records.

Each report gives its own (:meth:`omnicam.CalibrationReport.verdict`,
:meth:`omnicam.PatternReport.verdict`); this module sits below both (and below the calibration
file, :mod:`.calibration_file`, which writes and reads it), so the record has one home and no
import runs upwards.
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np

from .._validate import file_path, shown
from .filestorage import LONG_INT, MAX_VALUES

__all__ = ["K_SOURCES", "METHODS", "Verdict", "judged", "split_findings"]

#: Where a calibration's ``K`` came from (:attr:`Verdict.K_source`).
K_SOURCES = ("given", "file", "guessed", "chessboard")
#: How the posture was found (:attr:`Verdict.method`).
METHODS = ("image", "chessboard")
_VERDICT_FLOATS = (
    "confidence",
    "axis_std_deg",
    "origin_std_mm",
    "rim_rms_px",
    "rms_px",
    "heldout_median_px",
    "heldout_max_px",
)
#: The verdict's fields that are sequences of texts.
TEXTS = ("warnings", "implausible", "notes")
_MAX_TEXT = 2000  # characters of one warning or note


def _file_text(text, name):
    """``text`` on one line, as the reader takes it back from every format.

    The pre-scan refuses YAML and XML holding a bare ``true``/``false`` or an integer beyond 32
    bits, wherever they are (:mod:`.filestorage`); OpenCV writes the strings ``true`` and
    ``null`` unquoted, and a string that starts with a quote as if it were quoted already (a
    file it cannot read back). So such words get backticks, a leading quote one before it, and
    long integers are grouped (``4_294_967_297``).
    """
    if not isinstance(text, str):
        raise ValueError(f"{name} must be a string, got {type(text).__name__}")
    text = " ".join(text.split())[:_MAX_TEXT]
    text = re.sub(r"(^|[:\[,>-][ \t]*)(true|false|null)(?=[ \t]*(?:$|[,\]#<]))", r"\1`\2`", text)
    if text[:1] in ("'", '"'):
        text = "`" + text
    return LONG_INT.sub(lambda m: f"{int(m.group()):_}", text)


@dataclasses.dataclass(frozen=True)
class Verdict:
    """How far to trust a calibration: what its report said when the file was written.

    The ``verdict`` map of a calibration file (:func:`.calibration_file.save_camera`,
    :func:`.calibration_file.read_verdict`).
    ``camera.save(path, report)`` records the report's own (``report.verdict()``,
    :meth:`from_report`); the command line
    adds where ``K`` came from and ``--force``. Numbers that do not apply or are unknown are
    None (never NaN).

    Attributes
    ----------
    method : str
        ``"image"`` (one image of the mirror: the rim, Chen's method, the choice of posture) or
        ``"chessboard"`` (chessboards seen through the mirror).
    K_source : str
        Where ``K`` came from: ``"given"`` (typed or passed in), ``"file"`` (read from
        :attr:`K_file`), ``"guessed"`` (from the rim and the mirror, as if the rig were
        aligned) or ``"chessboard"`` (fitted to the boards).
    K_file : str or None
        The file ``K`` was read from (``--intrinsics``, ``--from``), as given.
    K_note : str
        How ``K`` was made, in words (the guess's recipe and numbers).
    confidence : float or None
        The choice among the physical postures, 0 to 1 (``CalibrationReport.confidence``;
        None for chessboards).
    ambiguous : bool
        The choice could not separate the physical postures.
    forced : bool
        Written although implausible (``--force``).
    axis_std_deg, origin_std_mm : float or None
        The stated RMS uncertainty of the mirror axis (deg) and of the camera centre (the
        mirror's length unit).
    rim_rms_px : float or None
        RMS distance of the rim points to the rim's image, px.
    rms_px : float or None
        Chessboards: RMS corner reprojection error, px.
    heldout_median_px, heldout_max_px : float or None
        Chessboards: the held-out corner RMS (median and worst view), px.
    heldout_folds : int or None
        Chessboards: the folds of the held-out check.
    ray_std_deg : (float, float) or None
        Chessboards: the viewing directions' standard deviation over the mirror's image, deg
        (median, worst).
    warnings : tuple of str
        The report's warnings, the implausible findings left out.
    implausible : tuple of str
        The implausible findings: what makes ``omnicam calibrate`` refuse without ``--force``.
    notes : tuple of str
        What the data cannot fix by nature, said and not doubted: the mirror's scale without
        a rim radius, ``fx`` against the mirror's size when the mirror is not given (only
        their ratio is fixed; the viewing directions are not affected).
    """

    method: str = "image"
    K_source: str = "given"
    K_file: str | None = None
    K_note: str = ""
    confidence: float | None = None
    ambiguous: bool = False
    forced: bool = False
    axis_std_deg: float | None = None
    origin_std_mm: float | None = None
    rim_rms_px: float | None = None
    rms_px: float | None = None
    heldout_median_px: float | None = None
    heldout_max_px: float | None = None
    heldout_folds: int | None = None
    ray_std_deg: tuple | None = None
    warnings: tuple = ()
    implausible: tuple = ()
    notes: tuple = ()

    def __post_init__(self):
        def put(name, value):
            object.__setattr__(self, name, value)

        if self.method not in METHODS:
            raise ValueError(f"method must be one of {', '.join(METHODS)}, got {self.method!r}")
        if self.K_source not in K_SOURCES:
            raise ValueError(
                f"K_source must be one of {', '.join(K_SOURCES)}, got {self.K_source!r}"
            )
        if self.K_file is not None:
            put("K_file", _file_text(shown(file_path(self.K_file, "K_file")), "K_file"))
        put("K_note", _file_text(self.K_note, "K_note"))
        for name in ("ambiguous", "forced"):
            value = getattr(self, name)
            if value not in (0, 1):  # True, False, 0, 1 (the file's flags)
                raise ValueError(f"{name} must be 0 or 1 (False or True), got {value!r}")
            put(name, bool(value))
        for name in _VERDICT_FLOATS:
            put(name, _optional_number(getattr(self, name), name))
        if self.confidence is not None and not 0.0 <= self.confidence <= 1.0:
            raise ValueError(f"confidence must be within 0..1, got {self.confidence!r}")
        folds = self.heldout_folds
        if folds is not None and (
            not isinstance(folds, (int, np.integer)) or isinstance(folds, bool) or folds < 2
        ):
            raise ValueError(f"heldout_folds must be an integer of at least 2, got {folds!r}")
        put("heldout_folds", None if folds is None else int(folds))
        ray = self.ray_std_deg
        if ray is not None:
            if np.ndim(ray) != 1 or len(ray) != 2:
                raise ValueError(f"ray_std_deg must be (median, worst), got {ray!r}")
            ray = tuple(_optional_number(v, "ray_std_deg") for v in ray)
            put("ray_std_deg", None if None in ray else ray)
        for name in TEXTS:
            texts = getattr(self, name)
            if isinstance(texts, str) or not isinstance(texts, (list, tuple)):
                raise ValueError(f"{name} must be a sequence of strings")
            if len(texts) > MAX_VALUES:
                raise ValueError(f"{name} has more than {MAX_VALUES} entries")
            put(name, tuple(_file_text(w, name) for w in texts))

    @classmethod
    def from_report(
        cls,
        report,
        *,
        K_source: str | None = None,
        K_file: str | None = None,
        K_note: str = "",
        forced: bool = False,
        implausible=None,
    ) -> Verdict:
        """The verdict of a :class:`~omnicam.calibration.CalibrationReport` (one image) or a
        :class:`~omnicam.chessboard.PatternReport` (chessboards): ``report.verdict(...)``.

        Parameters
        ----------
        report : CalibrationReport or PatternReport
        K_source : str, optional
            Default ``"given"`` for one image (``calibrate`` takes ``K``), ``"chessboard"`` for
            chessboards (``K`` is fitted).
        K_file, K_note, forced
            As the attributes.
        implausible : sequence of str, optional
            The findings that made the result implausible; default the report's
            ``plausibility`` (one image), none for chessboards. They are left out of
            ``warnings``.

        Raises
        ------
        ValueError
            ``report`` is not a calibration report, or a bad argument (naming it).
        """
        make = getattr(report, "verdict", None)
        if not callable(make):
            raise ValueError(
                f"verdict must be a Verdict or a calibration report (CalibrationReport, "
                f"PatternReport), got {type(report).__name__}"
            )
        return make(
            K_source=K_source, K_file=K_file, K_note=K_note, forced=forced, implausible=implausible
        )

    def doubts(self) -> tuple[str, ...]:
        """What makes the calibration doubtful, each a short phrase (empty: no doubt recorded).

        A guessed ``K``, an ambiguous choice of posture, implausible findings (written with
        ``--force`` or from the library), the report's warnings, e.g. ``("with a guessed K",
        "ambiguous (confidence 0.00)", "with 2 warnings")``. The notes (what the data cannot
        fix by nature) are no doubt.
        """
        out = []
        if self.K_source == "guessed":
            out.append("with a guessed K")
        if self.ambiguous:
            c = "" if self.confidence is None else f" (confidence {self.confidence:.2f})"
            out.append(f"ambiguous{c}")
        n = len(self.implausible)
        found = f"{n} implausibility warning{'s' if n != 1 else ''}"
        if self.forced:
            out.append(f"forced past {found}" if n else "forced")
        elif n:
            out.append(f"with {found}")
        n = len(self.warnings)
        if n:
            out.append(f"with {n} warning{'s' if n != 1 else ''}")
        return tuple(out)

    def status(self, refused: bool = False) -> str:
        """The verdict in one line: ``ok: no doubt recorded``, ``DOUBTFUL: calibrated ...``
        (:meth:`doubts`), ``IMPLAUSIBLE: ...`` (what ``omnicam calibrate`` refuses without
        ``--force``) or, with ``refused``, ``REFUSED: ...`` (it did)."""
        n = len(self.implausible)
        if n and not self.forced:
            rest = [d for d in self.doubts() if "implausibility" not in d]
            found = f"{n} implausible finding{'s' if n != 1 else ''}"
            return (
                f"REFUSED: {found} (--force writes it anyway)"
                if refused
                else f"IMPLAUSIBLE: {found} (omnicam calibrate refuses it without --force)"
            ) + (f"; calibrated {', '.join(rest)}" if rest else "")
        doubts = self.doubts()
        return f"DOUBTFUL: calibrated {', '.join(doubts)}" if doubts else "ok: no doubt recorded"

    def serious(self) -> bool:
        """A doubt about the views themselves: a guessed ``K``, an ambiguous posture or an
        implausible finding (the warnings alone say what to check)."""
        return self.K_source == "guessed" or self.ambiguous or bool(self.implausible)


def _optional_number(value, name):
    """``value`` as a finite float, None for None or NaN; ValueError naming ``name``."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    value = float(value)
    if math.isnan(value):
        return None
    if not math.isfinite(value) or value < 0:
        raise ValueError(f"{name} must be finite and not negative, got {value!r}")
    return value


def split_findings(warnings, implausible) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """``(warnings, implausible)`` of a report as texts, the implausible findings left out of
    the warnings (a verdict keeps the two apart: what a refusal rests on, and the rest)."""
    implausible = tuple(str(w) for w in implausible)
    return tuple(str(w) for w in warnings if str(w) not in implausible), implausible


def judged(camera, report):
    """``(camera, report)`` with the camera carrying the report's verdict.

    What each calibration route returns (``camera.verdict == report.verdict()``, and
    ``report.camera`` the same camera), so that ``camera.save(path)`` records what the report
    said without being handed the report again.
    """
    carried = camera.replace(verdict=report.verdict())
    if getattr(report, "camera", None) is camera:
        report = dataclasses.replace(report, camera=carried)
    return carried, report
