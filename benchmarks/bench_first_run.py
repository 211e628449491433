"""First run: numba compile time from an empty cache, and a fresh process with the cache warm.

Run: ``python benchmarks/bench_first_run.py [--warm-runs N] [--skip-demo]``

* Cold: ``omnicam demo`` then a first ``omnicam unwarp`` (perspective view of the demo's image),
  each a fresh process with ``NUMBA_CACHE_DIR`` pointing at a new, empty folder; then the same
  demo again with that cache warm. Wall and CPU (user + sys) time of each process; the demo's
  compile time is its cold minus its warm time.
* Warm: fresh processes from ``import omnicam`` to the first 2048x512 panorama table
  (``MisalignedHyperbolicCamera.load`` + ``init_panorama_maps``), the cache warm; the time inside
  the process (from before ``import omnicam``) and of the whole process, medians.

The first-compile notice (one line on stderr) is printed when it appears.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")

FIRST_TABLE = r"""
import time
t0 = time.perf_counter()
import sys
sys.path.insert(0, {root!r})
import omnicam
cam = omnicam.MisalignedHyperbolicCamera.load({path!r})
m1, m2 = cam.init_panorama_maps((2048, 512))
print(time.perf_counter() - t0)
"""

CLI = "import sys; sys.path.insert(0, {root!r}); from omnicam.cli import main; sys.exit(main())"


def run(argv, env):
    """Run a process; return (wall s, cpu s, stdout, stderr)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run(argv, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if out.returncode != 0:
        raise RuntimeError(f"{argv} failed:\n{out.stdout}\n{out.stderr}")
    return wall, cpu, out.stdout, out.stderr


def notice(stderr):
    lines = [ln for ln in stderr.splitlines() if ln.startswith("omnicam: compiling")]
    return lines[0] if lines else "(no first-compile notice)"


def cold_demo(tmp):
    print("== cold: empty NUMBA_CACHE_DIR, omnicam demo, then a first omnicam unwarp")
    env = dict(os.environ, NUMBA_CACHE_DIR=os.path.join(tmp, "numba-cache"))
    cli = [sys.executable, "-c", CLI.format(root=ROOT)]
    out = os.path.join(tmp, "demo")
    wall, cpu, _o, err = run([*cli, "demo", "-o", out], env)
    print(f"demo (cold)   wall {wall:6.2f} s  cpu {cpu:6.2f} s   {notice(err)}")
    view = os.path.join(tmp, "view.png")
    argv = [
        *cli,
        "unwarp",
        os.path.join(out, "mirror.png"),
        "-c",
        os.path.join(out, "calibration.yaml"),
        "--perspective",
        "640x480",
        "--fov",
        "70",
        "--yaw",
        "45",
        "-o",
        view,
    ]
    wall_u, cpu_u, _o, err = run(argv, env)
    print(f"unwarp (next) wall {wall_u:6.2f} s  cpu {cpu_u:6.2f} s   {notice(err)}")
    wall_w, cpu_w, _o, err = run([*cli, "demo", "-o", out + "2"], env)
    print(f"demo (warm)   wall {wall_w:6.2f} s  cpu {cpu_w:6.2f} s   {notice(err)}")
    print(
        f"compile time of the demo (cold - warm): wall {wall - wall_w:.2f} s, "
        f"cpu {cpu - cpu_w:.2f} s; load average {os.getloadavg()[0]:.2f}"
    )


def warm_first_table(tmp, n):
    print(f"== warm: fresh process, import omnicam .. first 2048x512 panorama, median of {n}")
    sys.path.insert(0, ROOT)
    from omnicam import synthetic

    path = os.path.join(tmp, "calib.yaml")
    synthetic.misaligned_rig().save(path)
    code = FIRST_TABLE.format(root=ROOT, path=path)
    env = dict(os.environ, NUMBA_CACHE_DIR=os.path.join(tmp, "numba-cache-warm"))
    _w, _c, _o, err = run([sys.executable, "-c", code], env)  # fills the cache
    print(f"first (cold) run: {notice(err)}")
    # as the environment runs Python, and with omnicam's .pyc files written (a pip install
    # compiles them; with PYTHONDONTWRITEBYTECODE=1 every process compiles omnicam's source);
    # the two interleaved
    with_pyc = {k: v for k, v in env.items() if k != "PYTHONDONTWRITEBYTECODE"}
    with_pyc["PYTHONPYCACHEPREFIX"] = os.path.join(tmp, "pycache")  # not into the source tree
    run([sys.executable, "-c", code], with_pyc)  # writes the .pyc files
    times = {"as run": ([], []), "with .pyc": ([], [])}
    for _ in range(n):
        for label, e in (("as run", env), ("with .pyc", with_pyc)):
            wall, _cpu, out, _err = run([sys.executable, "-c", code], e)
            times[label][1].append(wall)
            times[label][0].append(float(out.strip().splitlines()[-1]))
    for label, (inside, whole) in times.items():
        print(
            f"{label:9s}: import omnicam .. table: median {np.median(inside):.3f} s "
            f"(min {min(inside):.3f}); whole process median {np.median(whole):.3f} s"
        )
    print(f"load average {os.getloadavg()[0]:.2f}")
    print(f"PYTHONDONTWRITEBYTECODE={os.environ.get('PYTHONDONTWRITEBYTECODE', '')!r} here")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--warm-runs", type=int, default=7)
    ap.add_argument("--skip-demo", action="store_true", help="only the warm first table")
    args = ap.parse_args(argv)
    print(f"{os.cpu_count()} cpus")
    with tempfile.TemporaryDirectory() as tmp:
        if not args.skip_demo:
            cold_demo(tmp)
        warm_first_table(tmp, args.warm_runs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
