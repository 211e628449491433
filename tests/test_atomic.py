"""omnicam._atomic: a file is replaced whole or not at all, and failures say so."""

import errno
import os
import subprocess
import sys

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
