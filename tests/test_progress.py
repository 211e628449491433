"""The long steps' progress (omnicam._progress): silent by default, told to the route's
callback, and a nested call without its own quiet but for a fit that runs long."""

from omnicam import _progress


@_progress.reports_progress
def _inner(progress=None):
    _progress.say("inner step")
    meter = _progress.Meter("inner fit")
    for cost in (3.0, 2.0, 1.0):
        meter(cost)
    meter.done(1.0)


@_progress.reports_progress
def _outer(progress=None):
    _progress.say("outer step")
    _inner()


def test_silent_by_default_and_told_to_the_callback(monkeypatch):
    monkeypatch.setattr(_progress, "PERIOD_S", 0.0)  # every evaluation "runs long"
    _outer()  # no callback: nothing to tell, no error
    heard = []
    _outer(progress=lambda i, text: heard.append((i, text)))
    assert heard[0] == (None, "outer step")
    inner = [t for _, t in heard[1:]]
    assert inner and all(t.startswith("inner fit: evaluation") for t in inner)  # long lines
    heard.clear()
    _inner(progress=lambda i, text: heard.append(text))  # at the top: every line
    assert heard[0] == "inner step" and heard[-1].startswith("inner fit: 3 evaluations in")
