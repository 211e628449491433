"""Exceptions of the calibration: bad input versus an estimate that cannot be made."""

from __future__ import annotations

__all__ = ["EstimationError"]


class EstimationError(ValueError):
    """Valid input from which the requested quantity cannot be estimated.

    Raised when, for example, no rim ellipse is found in an image, the camera's reflection is
    required but not found, or none of the rim's postures is physically possible. Bad input
    (wrong shapes, non-finite values, a singular ``K``) raises a plain :class:`ValueError`
    instead; being a subclass, ``except ValueError`` catches both.
    """
