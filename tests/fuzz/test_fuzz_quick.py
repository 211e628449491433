"""The quick subset of the fuzz harness (a few hundred cases): every outcome must be ok.

The full run is ``python tests/fuzz/run.py`` (>= 1500 cases); see its docstring.

Bad outcomes that belong to work still open elsewhere (issue 10, item 3 and the ``Unwarper``'s
arguments: ``omnicam/stream.py`` and ``omnicam/cli/unwarp.py``'s video path) mark the test as an
expected failure naming each of them, so they stay visible; any other bad outcome fails it.
"""
import os
import re
import subprocess
import sys

import pytest

RUN = os.path.join(os.path.dirname(os.path.abspath(__file__)), "run.py")
OPEN_ELSEWHERE = re.compile(r"Unwarper\.|unwarp video|SIGINT during unwarp")


def test_quick_fuzz_run_has_no_bad_outcome():
    r = subprocess.run([sys.executable, RUN, "--quick"], capture_output=True, text=True,
                       timeout=900)
    assert "omnicam fuzz:" in r.stdout, r.stdout + r.stderr
    total = [ln for ln in r.stdout.splitlines() if ln.strip().startswith("total")]
    assert total and int(total[0].split()[2]) >= 300, r.stdout  # a few hundred cases ran
    if r.returncode == 0:
        return
    bad = [ln.strip() for ln in r.stdout.split("bad outcomes:", 1)[-1].splitlines()
           if ln.strip().startswith("[")]
    assert bad, r.stdout[-6000:] + r.stderr[-2000:]
    mine = [ln for ln in bad if not OPEN_ELSEWHERE.search(ln)]
    assert not mine, "\n".join(mine)
    pytest.xfail("open in stream.py / the video path: " + " | ".join(bad))
