"""The quick subset of the fuzz harness (a few hundred cases): every outcome must be ok.

The full run is ``python tests/fuzz/run.py`` (>= 1500 cases); see its docstring.
"""

import os
import subprocess
import sys

RUN = os.path.join(os.path.dirname(os.path.abspath(__file__)), "run.py")


def test_quick_fuzz_run_has_no_bad_outcome():
    r = subprocess.run(
        [sys.executable, RUN, "--quick"], capture_output=True, text=True, timeout=900
    )
    assert "omnicam fuzz:" in r.stdout, r.stdout + r.stderr
    total = [ln for ln in r.stdout.splitlines() if ln.strip().startswith("total")]
    assert total and int(total[0].split()[2]) >= 300, r.stdout  # a few hundred cases ran
    listed = r.stdout.split("bad outcomes:", 1)[1] if "bad outcomes:" in r.stdout else ""
    bad = [ln.strip() for ln in listed.splitlines() if ln.strip().startswith("[")]
    assert r.returncode == 0 and not bad, "\n".join(bad) or r.stdout[-6000:] + r.stderr[-2000:]
