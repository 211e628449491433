"""The ``omnicam`` console script: Ctrl-C while the libraries load is one line and exit 130.

The handler is installed here, before numpy and OpenCV load (``omnicam.cli`` imports them),
and Python's own is put back once they have: the library itself installs nothing.
"""

import os
import signal


def _interrupted_while_loading(signum, frame):
    os.write(2, b"omnicam: error: interrupted\n")
    os._exit(130)


def main() -> int:
    """Run the ``omnicam`` command (``omnicam.cli.main``) and return its exit status."""
    signal.signal(signal.SIGINT, _interrupted_while_loading)
    from .cli import main as run  # the heavy import this module exists to guard

    signal.signal(signal.SIGINT, signal.default_int_handler)  # loaded: Ctrl-C as usual
    try:
        return run()
    finally:  # done: a Ctrl-C during the interpreter's shutdown changes nothing now
        signal.signal(signal.SIGINT, signal.SIG_IGN)
