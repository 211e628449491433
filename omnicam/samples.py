"""Sample calibration files shipped with omnicam (copies of the top-level ``calib_files/``).

>>> cam = omnicam.samples.load("hyperomni_misaligned")            # doctest: +SKIP
"""

from __future__ import annotations

from contextlib import AbstractContextManager
from importlib import resources
from pathlib import Path

from .hyperbolic_camera import MisalignedHyperbolicCamera

__all__ = ["names", "path", "load"]


def names() -> list[str]:
    """Names of the shipped calibration files, without extension."""
    files = resources.files("omnicam") / "data"
    return sorted(p.name.rsplit(".", 1)[0] for p in files.iterdir() if p.name.endswith(".yaml"))


def path(name: str) -> AbstractContextManager[Path]:
    """Context manager giving a real filesystem path of a shipped file (for ``cv2.FileStorage``).

    >>> with omnicam.samples.path("hyperomni_aligned") as p:      # doctest: +SKIP
    ...     cam = MisalignedHyperbolicCamera.load(p)
    """
    if name not in names():
        raise ValueError(f"unknown sample calibration {name!r}; choose one of {names()}")
    return resources.as_file(resources.files("omnicam") / "data" / f"{name}.yaml")


def load(name: str) -> MisalignedHyperbolicCamera:
    """Load a shipped calibration file as a :class:`MisalignedHyperbolicCamera`."""
    with path(name) as p:
        return MisalignedHyperbolicCamera.load(p)
