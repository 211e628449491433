"""How kernels are compiled and run: cache fallback, first-compile notice, chunked threads."""

import importlib.util
import os
import subprocess
import sys

import numba
import numpy as np
import pytest

from omnicam import _jit

NO_LOCATOR = "ZipCacheLocator"  # finds no cache folder for a plain .py file
needs_jit = pytest.mark.skipif(numba.config.DISABLE_JIT, reason="nothing is cached without the JIT")


def load_module(path, name):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@needs_jit
@pytest.mark.skipif(
    not hasattr(numba.config, "CACHE_LOCATOR_CLASSES"),
    reason="numba without NUMBA_CACHE_LOCATOR_CLASSES",
)
def test_cache_is_unavailable_when_numba_finds_no_locator(monkeypatch):
    assert _jit.cache_available()
    monkeypatch.setattr(numba.config, "CACHE_LOCATOR_CLASSES", NO_LOCATOR)
    assert not _jit.cache_available()


@needs_jit
@pytest.mark.skipif(
    not hasattr(numba.config, "CACHE_LOCATOR_CLASSES"),
    reason="numba without NUMBA_CACHE_LOCATOR_CLASSES",
)
def test_import_and_kernels_work_without_a_writable_cache_with_one_line_saying_so(tmp_path):
    code = (
        "import numpy as np, omnicam\n"
        "from omnicam import synthetic\n"
        "xy = synthetic.aligned_rig().project_directions(np.array([[1.0, 0.0, -0.5]]))\n"
        "assert np.isfinite(xy).all()\n"
    )
    env = dict(os.environ, NUMBA_CACHE_LOCATOR_CLASSES=NO_LOCATOR)
    env.pop("NUMBA_CACHE_DIR", None)
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, cwd=tmp_path
    )
    assert out.returncode == 0, out.stderr
    lines = [ln for ln in out.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("omnicam: numba cannot write its cache")
    assert "no locator" not in out.stderr


def test_cache_flag_falls_back_with_one_line(monkeypatch, capsys):
    monkeypatch.setattr(_jit, "cache_available", lambda probe=None: False)
    assert _jit._cache_flag() is False
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "NUMBA_CACHE_DIR" in err[0]


@needs_jit
def test_cold_cache_is_detected_and_announced_once(tmp_path, monkeypatch, capsys):
    src = tmp_path / "tiny_kernels.py"
    src.write_text("from numba import njit\n\n@njit(cache=True)\ndef f(x):\n    return x + 1\n")
    first = load_module(src, "tiny_kernels_a")
    assert _jit._is_cold(first.f)
    monkeypatch.setitem(_jit._state, "noticed", False)
    _jit.notice_if_cold(first.f)
    _jit.notice_if_cold(first.f)
    err = capsys.readouterr().err.splitlines()
    assert err == [
        f"omnicam: compiling kernels once (about {_jit.COMPILE_SECONDS} s); later runs start fast"
    ]
    assert first.f(1) == 2  # compiles and writes the cache
    assert not _jit._is_cold(first.f)
    second = load_module(src, "tiny_kernels_b")  # a fresh process would see this
    assert not _jit._is_cold(second.f)


def test_run_chunks_covers_the_range_once_in_disjoint_chunks():
    hits = np.zeros(10_000, np.int64)

    def mark(lo, hi, out):
        out[lo:hi] += 1

    _jit.run_chunks(mark, len(hits), hits, min_chunk=100)
    assert (hits == 1).all()
    _jit.run_chunks(mark, 0, hits)  # empty range: nothing
    assert (hits == 1).all()


@needs_jit
def test_a_kernel_goes_cold_when_a_sibling_module_it_inlines_changes(tmp_path):
    """numba stamps a cache index with the kernel's own file; omnicam's kernels inline the
    mirror seam from a sibling module, so :func:`_jit.kernel` stamps them with the folder."""
    helper = tmp_path / "helper.py"
    helper.write_text("from omnicam._jit import kernel\n\n@kernel\ndef h(x):\n    return x + 1\n")
    (tmp_path / "kern.py").write_text(
        "import sys\nfrom omnicam._jit import kernel\nh = sys.modules['helper'].h\n\n"
        "@kernel\ndef f(x):\n    return h(x) * 2\n"
    )
    sys.modules["helper"] = load_module(helper, "helper")
    try:
        first = load_module(tmp_path / "kern.py", "kern_a")
        assert first.f(1) == 4  # compiles and writes the cache
        assert not _jit._is_cold(load_module(tmp_path / "kern.py", "kern_b").f)
        stamp = os.stat(helper).st_mtime
        helper.write_text(helper.read_text().replace("x + 1", "x + 2"))
        os.utime(helper, (stamp + 10, stamp + 10))
        sys.modules["helper"] = load_module(helper, "helper")
        again = load_module(tmp_path / "kern.py", "kern_c")
        assert _jit._is_cold(again.f)
        assert again.f(1) == 6
    finally:
        sys.modules.pop("helper", None)
