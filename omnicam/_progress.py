"""Progress of the steps that take long, told to the caller's ``progress`` callback.

A route that takes ``progress`` (:func:`omnicam.calibrate_pattern`) is wrapped by
:func:`reports_progress`: for the length of the call, its steps' :func:`say` reach
``progress(None, text)`` (``None``: no image's; a line per image is ``progress(index, text)``).
Silent by default (no callback). A nested call made without one (the held-out check's
calibration of each fold, which the check reports fold by fold) is quiet but for the lines
of a fit that runs long (:class:`Meter`, every :data:`PERIOD_S` seconds), so no stretch of a
long run goes without a line. A context variable carries the callback, so the steps below
the route need no parameter.
"""

from __future__ import annotations

import contextvars
import functools
import time
from collections.abc import Callable
from typing import Any, TypeVar

__all__ = ["PERIOD_S", "Meter", "reports_progress", "say"]

_CURRENT: contextvars.ContextVar[Callable[[int | None, str], Any] | None] = contextvars.ContextVar(
    "omnicam_progress", default=None
)
#: Inside a nested call without its own callback: only the long fits' periodic lines pass.
_NESTED: contextvars.ContextVar[bool] = contextvars.ContextVar("omnicam_nested", default=False)
#: Seconds between two lines of one long step (the adjustment's evaluations).
PERIOD_S = 2.0

F = TypeVar("F", bound=Callable[..., Any])


def reports_progress(func: F) -> F:
    """``func``, whose keyword ``progress`` (a callable or None) hears its steps' :func:`say`."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        own = kwargs.get("progress")
        outer = _CURRENT.get()
        token = _CURRENT.set(own if own is not None else outer)
        nested = _NESTED.set(own is None and outer is not None)
        try:
            return func(*args, **kwargs)
        finally:
            _NESTED.reset(nested)
            _CURRENT.reset(token)

    return wrapper  # type: ignore[return-value]


def say(text: str, long: bool = False) -> None:
    """Tell the current route's ``progress`` callback ``text`` (one line), if it has one;
    inside a nested call without its own, only the lines of a fit that runs ``long``."""
    tell = _CURRENT.get()
    if tell is not None and (long or not _NESTED.get()):
        tell(None, text)


class Meter:
    """The evaluations of one iterative fit: a line every :data:`PERIOD_S` seconds while it
    runs (``what: evaluation N, cost C``) and one when it ends (:meth:`done`)."""

    def __init__(self, what: str) -> None:
        self.what, self.n = what, 0
        self.first: float | None = None
        self.start = self.last = time.monotonic()
        self.on = _CURRENT.get() is not None

    def __call__(self, cost: float) -> None:
        if not self.on:
            return
        self.n += 1
        if self.first is None:
            self.first = cost
        now = time.monotonic()
        if now - self.last >= PERIOD_S:
            self.last = now
            say(
                f"{self.what}: evaluation {self.n}, cost {cost:.6g} "
                f"({now - self.start:.0f} s so far)",
                long=True,
            )

    def done(self, cost: float) -> None:
        if self.on:
            say(
                f"{self.what}: {self.n} evaluations in {time.monotonic() - self.start:.1f} s, "
                f"cost {self.first if self.first is not None else cost:.6g} -> {cost:.6g}"
            )
