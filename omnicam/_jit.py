"""How omnicam runs its numba kernels: the decorator, the first-compile notice and threads.

* :func:`kernel` is ``numba.njit(cache=True, nogil=True, error_model="numpy")`` when numba can
  write its cache for this package, else the same without ``cache`` after one line on stderr
  saying so (numba raises "cannot cache function ...: no locator available" when neither the
  package's ``__pycache__`` nor the user cache folder is writable and ``NUMBA_CACHE_DIR`` is
  unset). A cached kernel's index is stamped with every ``.py`` file of its folder (numba
  stamps it with its own file only, and would load a stale kernel after an edit to a helper
  it inlines from a sibling module).
* :func:`notice_if_cold` prints, once per process, "omnicam: compiling kernels once (about N s);
  later runs start fast" before a kernel whose cache index is missing or stale is first called.
* :func:`run_chunks` runs a ``nogil`` kernel over ``range(n)`` in chunks on a small thread pool
  (the kernels take ``lo, hi`` first), in place of ``parallel=True``: numba's parallel loops
  cost several times the compile time of the serial kernel.
"""

from __future__ import annotations

import inspect
import os
import sys
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numba

#: Cold compile time of everything the demo and a first unwarp use, seconds, rounded up from
#: what ``benchmarks/bench_first_run.py`` measures on 2 cores (it prints the demo's and the
#: first unwarp's cold and warm times); quoted by the first-compile notice.
COMPILE_SECONDS = 15

#: ``numba.config``, whose settings it makes from the environment at import (so numba's type
#: information does not list them)
_CONFIG: Any = numba.config

_state: dict[str, Any] = {"noticed": False, "pool": None}


def _say(text: str) -> None:
    print(f"omnicam: {text}", file=sys.stderr, flush=True)


def cache_available(probe: Callable[[], object] | None = None) -> bool:
    """Whether numba finds a writable cache folder for functions of this package.

    ``probe`` is the function whose source file decides (numba looks next to it first); the
    default is a function of this module, which lives beside ``omnicam._kernels``.
    """

    def _probe() -> int:  # pragma: no cover - never called, only located
        return 0

    try:
        numba.njit(cache=True)(probe or _probe)
    except RuntimeError as e:
        if "no locator available" in str(e):
            return False
        raise
    return True


def _cache_flag() -> bool:
    if cache_available():
        return True
    _say(
        "numba cannot write its cache (package folder and user cache folder read-only); "
        "kernels compile in every process. Set NUMBA_CACHE_DIR to a writable folder to keep them"
    )
    return False


CACHE = _cache_flag()


def folder_stamp(path: str) -> tuple[float, int, int]:
    """``(latest mtime, total size, count)`` of the ``.py`` files in the folder of ``path``."""
    folder = os.path.dirname(os.path.abspath(path))
    stats = [os.stat(os.path.join(folder, f)) for f in os.listdir(folder) if f.endswith(".py")]
    return max(s.st_mtime for s in stats), sum(s.st_size for s in stats), len(stats)


def stamp_with_folder(dispatcher: Any, path: str) -> Any:
    """Make ``dispatcher``'s cache index stale whenever any ``.py`` file beside ``path``
    changes (:func:`folder_stamp` in place of numba's stamp of ``path`` alone)."""
    cache = getattr(dispatcher, "_cache", None)
    cache_file = getattr(cache, "_cache_file", None)
    if cache_file is not None and hasattr(cache_file, "_source_stamp"):
        cache_file._source_stamp = folder_stamp(path)
    return dispatcher


def kernel(func: Callable[..., Any] | None = None, **options: Any) -> Any:
    """``numba.njit`` with ``cache`` (when possible) and ``nogil``; ``options`` are passed on.
    A cached kernel is stamped with its whole folder (:func:`stamp_with_folder`)."""
    options.setdefault("cache", CACHE)
    options.setdefault("nogil", True)
    # IEEE division (x / 0 is inf or NaN) as in numpy and in numba's parallel loops, not
    # Python's ZeroDivisionError: no test-and-raise branch in every division
    options.setdefault("error_model", "numpy")

    def make(f: Callable[..., Any]) -> Any:
        dispatcher = numba.njit(**options)(f)
        if options["cache"]:
            stamp_with_folder(dispatcher, inspect.getfile(f))
        return dispatcher

    if func is None:
        return make
    return make(func)


def _is_cold(dispatcher: Any) -> bool:
    """Whether calling ``dispatcher`` would compile: no fresh cache index for its function."""
    if _CONFIG.DISABLE_JIT or not hasattr(dispatcher, "_cache"):
        return False
    if dispatcher.overloads:
        return False
    try:
        return not dispatcher._cache._cache_file._load_index()
    except Exception:  # numba internals moved: say nothing rather than fail
        return False


def notice_if_cold(*dispatchers: Any) -> None:
    """Print the first-compile notice once per process if any of ``dispatchers`` is cold."""
    if _state["noticed"]:
        return
    if any(_is_cold(d) for d in dispatchers):
        _state["noticed"] = True
        _say(f"compiling kernels once (about {COMPILE_SECONDS} s); later runs start fast")


def n_threads() -> int:
    """Threads for kernels: numba's thread count (``NUMBA_NUM_THREADS``, default all cores)."""
    return max(1, int(_CONFIG.NUMBA_NUM_THREADS))


def _pool() -> ThreadPoolExecutor:
    if _state["pool"] is None:
        _state["pool"] = ThreadPoolExecutor(max_workers=n_threads(), thread_name_prefix="omnicam")
    return _state["pool"]


def run_chunks(
    func: Callable[..., object],
    n: int,
    *args: Any,
    min_chunk: int = 256,
    chunks_per_thread: int = 4,
) -> None:
    """Call ``func(lo, hi, *args)`` over ``range(n)`` in chunks, on the calling thread and the
    pool's.

    ``func`` must release the GIL (:func:`kernel` does) and write disjoint slices. Small ``n``
    runs in the calling thread alone. Each thread takes the next chunk when it is done with
    one, so uneven work balances, and the calling thread works too: on a busy machine a pool
    thread that is not scheduled delays at most the chunk it holds.
    """
    threads = n_threads()
    n_chunks = min(threads * chunks_per_thread, n // min_chunk) if threads > 1 else 1
    if n_chunks <= 1 or _CONFIG.DISABLE_JIT:  # pure Python holds the GIL: no gain
        func(0, n, *args)
        return
    bounds = [n * c // n_chunks for c in range(n_chunks + 1)]
    chunks = iter(range(n_chunks))  # next() on it is atomic under the GIL

    def work() -> None:
        for c in chunks:
            func(bounds[c], bounds[c + 1], *args)

    helpers = [_pool().submit(work) for _ in range(min(threads, n_chunks) - 1)]
    work()
    for f in helpers:
        f.result()
