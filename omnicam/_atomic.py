"""One way to write a file: a temporary file beside it, flushed, checked, then renamed into place.

Every file omnicam writes (calibration, intrinsics and far-line files, images, maps, exports)
goes through :func:`atomic_output`, and videos, written frame by frame, through the same steps
(:class:`omnicam.video.VideoOutput`), so a reader sees either the old file or the complete new
one, never a half-written one -- also on a full disk, Ctrl-C or a crash mid-write:

1. a new, empty temporary file is created next to the target with the same extension (OpenCV
   picks the format from it), named ``.<name>.omnicam-tmp-<pid>-<random><ext>``, created with
   ``os.open(..., 0o666)`` so the process umask applies as for any new file (no umask flips);
2. the caller writes it (by name: ``cv2.FileStorage``, ``cv2.imwrite``, ``cv2.VideoWriter``);
3. it is flushed to the disk (``fsync``), must be non-empty, and ``verify(tmp)`` (reading it
   back) must pass -- ``cv2.FileStorage`` and ``cv2.imwrite`` do not report every failed write;
4. only then :func:`publish` puts it in place (``os.replace``; ``overwrite=False``: a hard link
   that fails if the target appeared meanwhile) and the folder is flushed.

Any failure removes the temporary file, leaves the old target untouched and raises
:class:`OutputError` (a ``ValueError``) naming the file and the cause. Temporary files left by a
killed process are removed by the next write into the same folder (:func:`remove_stale`).
"""

from __future__ import annotations

import atexit
import contextlib
import errno
import os
import re
import secrets
import signal
import threading
import time

__all__ = [
    "OutputError",
    "atomic_output",
    "publish",
    "write_bytes",
    "temp_beside",
    "remove_quietly",
    "remove_stale",
    "TEMP_MARK",
]

TEMP_MARK = ".omnicam-tmp-"
# the whole name of a temporary file of temp_beside, the writer's pid in group 1: only these are
# ever removed as stale (a name that merely holds TEMP_MARK is someone else's file)
_TEMP_NAME = re.compile(r"\..*" + re.escape(TEMP_MARK) + r"(\d{1,9})-[0-9a-f]{8}(\.[^.]*)?", re.S)
# temporary files of this process not yet renamed or removed: a Ctrl-C can land between creating
# one and the ``with`` block that owns it (in contextlib's __enter__), where no ``finally`` runs;
# they are removed at exit
_LIVE: set[str] = set()
# a temporary file whose process lives is litter only this long after its last write (its pid was
# reused after the writer was killed); a live writer, even of a long video, touches it far sooner
STALE_AFTER_S = 3600.0


class OutputError(ValueError):
    """A file could not be written; the previous file at that path (if any) is unchanged."""


def _describe(e):
    if isinstance(e, OSError):
        text = e.strerror or str(e)
        if e.errno == errno.ENOSPC:
            text = "no space left on the device"
        return text
    return str(e)


def _pid_alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: someone else's live process
        pass
    try:  # a killed writer its parent has not reaped yet is a zombie: dead, as far as files go
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rsplit(b")", 1)[1].split()[0] != b"Z"
    except (OSError, IndexError):  # no /proc (macOS): alive, as kill said
        return True


def remove_stale(folder, now=None):
    """Remove temporary files of dead or long-gone writers in ``folder``; return how many.

    A process killed while writing (SIGKILL, a crash, the power) cannot remove its temporary
    file, so the next write into the folder does. A file named exactly as :func:`temp_beside`
    names them, ``.<name>.omnicam-tmp-<pid>-<8 hex digits><ext>``, is stale when process
    ``pid`` is gone (or a zombie), or when it was last written ``STALE_AFTER_S`` ago (``pid``
    reused); never while it is this process's. Errors are ignored: this is housekeeping, never
    a reason to fail a save.
    """
    now = time.time() if now is None else now
    removed = 0
    with contextlib.suppress(OSError):
        for entry in os.scandir(folder):
            ours = _TEMP_NAME.fullmatch(entry.name)
            if ours is None:
                continue
            pid = int(ours.group(1))
            if pid == os.getpid():
                continue
            with contextlib.suppress(OSError):
                old = now - entry.stat(follow_symlinks=False).st_mtime > STALE_AFTER_S
                if not _pid_alive(pid) or old:
                    os.remove(entry.path)
                    removed += 1
    return removed


def temp_beside(path):
    """Create a new, empty temporary file next to ``path`` with the same extension; its name.

    Raises
    ------
    OutputError
        The folder does not exist or cannot be written, or the name is not valid UTF-8
        (OpenCV's writers crash on such names, so no omnicam output may have one).
    """
    path = os.fspath(path)
    if isinstance(path, bytes):
        path = os.fsdecode(path)
    try:
        path.encode("utf-8")
    except UnicodeEncodeError:  # OpenCV's writers crash (SIGSEGV) on such names
        shown = path.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
        raise OutputError(
            f"cannot write {shown}: the file name is not valid UTF-8; rename it"
        ) from None
    folder = os.path.dirname(os.path.abspath(path))
    base, ext = os.path.splitext(os.path.basename(path))
    if not os.path.isdir(folder):
        raise OutputError(f"cannot write {path}: folder {folder} does not exist")
    remove_stale(folder)
    for _ in range(100):
        tmp = os.path.join(folder, f".{base}{TEMP_MARK}{os.getpid()}-{secrets.token_hex(4)}{ext}")
        _LIVE.add(tmp)  # before it exists: a Ctrl-C from here on cannot leave it behind
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            _LIVE.discard(tmp)
            continue
        except OSError as e:
            _LIVE.discard(tmp)
            raise OutputError(f"cannot write {path}: {_describe(e)} (in {folder})") from None
        except BaseException:  # Ctrl-C as os.open returns: the name is ours, the file may be
            remove_quietly(tmp)
            _LIVE.discard(tmp)
            raise
        os.close(fd)
        return tmp
    raise OutputError(f"cannot write {path}: no free temporary name in {folder}")


@contextlib.contextmanager
def sigint_deferred():
    """Hold SIGINT back (POSIX, main thread) for the body; a Ctrl-C then arrives right after."""
    block = (
        hasattr(signal, "pthread_sigmask") and threading.current_thread() is threading.main_thread()
    )
    if block:
        old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        if block:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _fsync(path, directory=False):
    flags = os.O_RDONLY | (getattr(os, "O_DIRECTORY", 0) if directory else 0)
    fd = os.open(path, flags)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def remove_quietly(path):
    """Remove ``path`` if it is there; an error is no error here (it is a leftover)."""
    with contextlib.suppress(OSError):
        os.remove(path)


def publish(tmp, path, overwrite=True):
    """Put the finished temporary file ``tmp`` in place as ``path``, durably.

    ``tmp`` (beside ``path``, from :func:`temp_beside`) is flushed to the disk, renamed, and the
    folder flushed. ``overwrite=True`` replaces ``path`` (``os.replace``); ``overwrite=False``
    makes a hard link, which fails if ``path`` exists, so a file that appeared meanwhile is never
    replaced (on a file system without hard links: a check, then ``os.replace``).

    Raises
    ------
    OutputError
        ``overwrite`` is False and ``path`` exists; ``tmp`` is left for the caller to remove.
    OSError
        The rename failed (the caller names the file); ``path`` is unchanged.
    """
    _fsync(tmp)
    if overwrite:
        os.replace(tmp, path)
    else:
        try:
            os.link(tmp, path)  # atomic and exclusive: fails if ``path`` exists
        except FileExistsError:
            raise OutputError(
                f"cannot write {path}: it exists (it appeared while writing)"
            ) from None
        except OSError as e:
            if e.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV):
                raise
            if os.path.lexists(path):  # a file system without hard links
                raise OutputError(f"cannot write {path}: it exists") from None
            os.replace(tmp, path)
        else:
            os.remove(tmp)
    _LIVE.discard(tmp)
    with contextlib.suppress(OSError):
        _fsync(os.path.dirname(os.path.abspath(path)), directory=True)


@contextlib.contextmanager
def atomic_output(path, *, what="file", overwrite=True, verify=None, allow_empty=False):
    """Write ``path`` through a temporary file: ``with atomic_output(p) as tmp: write(tmp)``.

    Parameters
    ----------
    path : str or os.PathLike
        The target. Its folder must exist.
    what : str
        How the file is named in error messages ("calibration file", "image", ...).
    overwrite : bool
        Replace an existing target; with False an existing target is an error (checked again,
        atomically, when the finished file is put in place).
    verify : callable, optional
        ``verify(tmp)`` after the data is on the disk: raise (any exception) or return False if
        the file is not what was meant to be written, e.g. by reading it back.
    allow_empty : bool
        An empty result is an error unless this is set.

    Raises
    ------
    OutputError
        The folder is missing or not writable, the disk is full, the write could not be
        verified, or the target exists and ``overwrite`` is False. The old target is unchanged
        and the temporary file removed. An ``OSError`` raised in the ``with`` body becomes
        this error too; ``KeyboardInterrupt`` and other exceptions propagate unchanged, also
        after removing the temporary file.
    """
    path = os.fspath(path)
    if os.path.isdir(path):
        raise OutputError(f"cannot write {what} {path}: it is a folder")
    if not overwrite and os.path.lexists(path):
        raise OutputError(f"cannot write {what} {path}: it exists")
    tmp = None
    try:
        with sigint_deferred():  # no Ctrl-C between creating the file and owning it
            tmp = temp_beside(path)
        try:
            yield tmp
        except OSError as e:  # the writer's own failure, e.g. ENOSPC from f.write
            raise OutputError(
                f"cannot write {what} {path}: {_describe(e)}; the previous file is unchanged"
            ) from None
        try:
            _fsync(tmp)
            size = os.path.getsize(tmp)
        except OSError as e:
            raise OutputError(
                f"cannot write {what} {path}: {_describe(e)}; the previous file is unchanged"
            ) from None
        if size == 0 and not allow_empty:
            raise OutputError(
                f"cannot write {what} {path}: nothing was written (is the disk "
                f"full?); the previous file is unchanged"
            )
        if verify is not None:
            try:
                ok = verify(tmp)
            except Exception as e:
                raise OutputError(
                    f"cannot write {what} {path}: the written file does not read "
                    f"back ({_describe(e)}); the previous file is unchanged"
                ) from None
            if ok is False:
                raise OutputError(
                    f"cannot write {what} {path}: the written file does not read "
                    f"back; the previous file is unchanged"
                )
        try:
            publish(tmp, path, overwrite)
        except OSError as e:
            raise OutputError(f"cannot write {what} {path}: {_describe(e)}") from None
    finally:
        if tmp is not None:
            remove_quietly(tmp)
            _LIVE.discard(tmp)


@atexit.register
def _remove_live():
    for tmp in list(_LIVE):
        remove_quietly(tmp)


def write_bytes(path, data, *, what="file", overwrite=True, verify=None):
    """Write ``data`` (bytes or str, UTF-8) to ``path`` atomically (:func:`atomic_output`)."""
    if isinstance(data, str):
        data = data.encode("utf-8")

    with atomic_output(
        path, what=what, overwrite=overwrite, verify=verify, allow_empty=len(data) == 0
    ) as tmp:
        try:
            with open(tmp, "wb") as f:
                f.write(data)
                f.flush()
        except OSError as e:
            raise OutputError(
                f"cannot write {what} {path}: {_describe(e)}; the previous file is unchanged"
            ) from None
        if os.path.getsize(tmp) != len(data):
            raise OutputError(
                f"cannot write {what} {path}: short write; the previous file is unchanged"
            )
