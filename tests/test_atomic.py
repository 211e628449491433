"""omnicam._atomic: a file is replaced whole or not at all, and failures say so."""

import errno
import os
import signal
import subprocess
import sys
import time

import pytest

from omnicam._atomic import TEMP_MARK, OutputError, atomic_output, remove_stale, write_bytes


def test_write_bytes_replaces_the_file_whole(tmp_path):
    target = tmp_path / "a.json"
    target.write_text("old")
    write_bytes(target, "new")
    assert target.read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json"]


def test_a_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path):
    target = tmp_path / "a.yaml"
    target.write_text("old")
    with pytest.raises(OutputError, match="no space left"):
        with atomic_output(target) as tmp:
            with open(tmp, "w") as f:
                f.write("half")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.yaml"]


def test_an_empty_result_is_an_error_not_a_new_file(tmp_path):
    target = tmp_path / "a.yaml"
    target.write_text("old")
    with pytest.raises(OutputError, match="nothing was written"):
        with atomic_output(target):
            pass  # the writer silently wrote nothing, as cv2.FileStorage does on a full disk
    assert target.read_text() == "old"


def test_a_write_that_does_not_read_back_is_refused(tmp_path):
    target = tmp_path / "a.txt"
    with pytest.raises(OutputError, match="does not read back"):
        write_bytes(target, "x", verify=lambda tmp: False)
    assert list(tmp_path.iterdir()) == []


def test_interrupt_propagates_and_cleans_up(tmp_path):
    target = tmp_path / "a.txt"
    target.write_text("old")
    with pytest.raises(KeyboardInterrupt):
        with atomic_output(target) as tmp:
            with open(tmp, "w") as f:
                f.write("partial")
            raise KeyboardInterrupt
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"]


def test_no_overwrite_refuses_an_existing_target(tmp_path):
    target = tmp_path / "a.txt"
    target.write_text("old")
    with pytest.raises(OutputError, match="exists"):
        write_bytes(target, "new", overwrite=False)
    assert target.read_text() == "old"


def test_new_files_get_the_mode_the_umask_gives(tmp_path):
    old = os.umask(0o027)
    try:
        write_bytes(tmp_path / "a.txt", "x")
    finally:
        os.umask(old)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o640


def test_missing_folder_is_named(tmp_path):
    with pytest.raises(OutputError, match="does not exist"):
        write_bytes(tmp_path / "no" / "a.txt", "x")


def test_temporaries_of_dead_writers_are_removed_by_the_next_write(tmp_path):
    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        capture_output=True,
        text=True,
        check=True,
    )
    litter = tmp_path / f".a{TEMP_MARK}{int(dead.stdout)}-deadbeef.yaml"
    litter.write_text("half")
    mine = tmp_path / f".b{TEMP_MARK}{os.getpid()}-00000000.yaml"
    mine.write_text("in use")
    write_bytes(tmp_path / "c.txt", "x")
    assert not litter.exists()
    assert mine.exists()  # this process's own temporaries are never touched
    assert remove_stale(tmp_path) == 0


def test_a_name_that_is_not_utf8_is_refused_before_any_writer_sees_it(tmp_path):
    bad = os.fsdecode(os.path.join(os.fsencode(tmp_path), b"out\xff.avi"))
    with pytest.raises(OutputError, match="not valid UTF-8"):
        write_bytes(bad, b"data")
    assert os.listdir(tmp_path) == []


# A child that saves a camera and is slow, deterministically, where the finished temporary file
# waits to be flushed: it says so and sleeps until killed.
SLOW_SAVE = """
import sys, time
from omnicam import _atomic, synthetic
fsync = _atomic._fsync
def slow(path, directory=False):
    if not directory:
        print("written", flush=True)
        time.sleep(120)
    fsync(path, directory)
_atomic._fsync = slow
synthetic.misaligned_rig().save(sys.argv[1])
"""


def _temporaries(folder):
    return sorted(p.name for p in folder.iterdir() if TEMP_MARK in p.name)


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs POSIX signals")
def test_a_save_killed_by_sigkill_leaves_a_temporary_the_next_save_removes(tmp_path):
    from omnicam import MisalignedHyperbolicCamera, synthetic

    target = tmp_path / "rig.yaml"
    cam = synthetic.misaligned_rig()
    cam.save(target)
    before = target.read_bytes()
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    child = subprocess.Popen(
        [sys.executable, "-c", SLOW_SAVE, str(target)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
    )
    try:
        assert child.stdout.readline() == b"written\n", child.stderr.read()
        left = _temporaries(tmp_path)
        assert left == [f".rig{TEMP_MARK}{child.pid}-{left[0][-13:-5]}.yaml"]
        cam.replace(D=[0.1, 0, 0, 0, 0]).save(tmp_path / "other.yaml")
        assert _temporaries(tmp_path) == left  # a live writer's temporary is never touched
    finally:
        child.kill()  # SIGKILL: no handler, no atexit, no finally runs in the child
        child.communicate()
    assert child.returncode == -signal.SIGKILL
    assert _temporaries(tmp_path) == left  # what a killed writer leaves
    assert target.read_bytes() == before  # ... beside the untouched old file
    cam.save(target)  # the next save into the folder removes it
    assert _temporaries(tmp_path) == []
    assert MisalignedHyperbolicCamera.load(target) == cam


def test_only_temporaries_named_as_ours_are_removed(tmp_path):
    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        capture_output=True,
        text=True,
        check=True,
    )
    pid = int(dead.stdout)
    others = [  # files that hold the mark but are not named as temp_beside names its files
        f"a{TEMP_MARK}{pid}-deadbeef.yaml",  # not hidden
        f".a{TEMP_MARK}{pid}-deadbeef.yaml.bak",
        f".a{TEMP_MARK}{pid}-notes.yaml",
        f".a{TEMP_MARK}{pid}.yaml",
        f".a{TEMP_MARK}99999999999999999999-deadbeef.yaml",  # no pid: must not crash a save
    ]
    for name in others:
        (tmp_path / name).write_text("someone else's")
    (tmp_path / f".a{TEMP_MARK}{pid}-deadbeef.yaml").write_text("ours")
    (tmp_path / f".b{TEMP_MARK}{pid}-0123abcd").write_text("ours, no extension")
    assert remove_stale(tmp_path) == 2
    assert sorted(os.listdir(tmp_path)) == sorted(others)


def _state(pid):
    with open(f"/proc/{pid}/stat", "rb") as f:
        return f.read().rsplit(b")", 1)[1].split()[0]


@pytest.mark.skipif(not os.path.exists("/proc/self/stat"), reason="needs Linux's /proc")
def test_a_temporary_of_a_killed_writer_not_yet_reaped_is_removed(tmp_path):
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    try:
        while _state(child.pid) != b"Z":
            time.sleep(0.01)  # exited, not waited for: a zombie, whose pid kill() still finds
        litter = tmp_path / f".a{TEMP_MARK}{child.pid}-deadbeef.yaml"
        litter.write_text("half")
        assert remove_stale(tmp_path) == 1
    finally:
        child.wait()


def test_a_live_writers_temporary_is_litter_only_when_long_untouched(tmp_path):
    from omnicam._atomic import STALE_AFTER_S

    live = tmp_path / f".a{TEMP_MARK}1-deadbeef.yaml"  # pid 1 lives
    live.write_text("a long video, say")
    assert remove_stale(tmp_path) == 0
    assert remove_stale(tmp_path, now=live.stat().st_mtime + STALE_AFTER_S + 1) == 1
