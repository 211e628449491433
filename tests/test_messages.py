"""Messages that name the thing and what to do (issue: a newcomer's first hour, item 8)."""

import subprocess
import sys

import numpy as np
import pytest

from omnicam import synthetic
from omnicam.stream import Unwarper
from omnicam.views import PanoramaView

VIEWS = {"pano": PanoramaView((64, 16))}


@pytest.fixture(scope="module")
def unwarper():
    return Unwarper.from_camera(synthetic.misaligned_rig(), VIEWS)


@pytest.mark.parametrize("dtype", [np.bool_, np.int8, np.int32, np.float16, np.complex64])
def test_a_frame_of_a_dtype_remap_does_not_take_is_a_value_error_naming_it(unwarper, dtype):
    w, h = unwarper.source_size
    with pytest.raises(ValueError, match=f"frame has dtype {np.dtype(dtype)}"):
        unwarper(np.zeros((h, w), dtype))


def test_a_reader_that_goes_away_ends_the_command_quietly():
    info = [sys.executable, "-m", "omnicam", "info", "calib_files/hyperomni_aligned.yaml"]
    with subprocess.Popen(info, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=REPO) as p:
        p.stdout.close()  # as `| head -1` does once it has its line
        err = p.stderr.read().decode()
        assert p.wait() in (0, 141)
    assert "Error" not in err and "unexpected" not in err, err


def test_out_of_memory_is_one_line_with_advice(monkeypatch, capsys):
    from omnicam import cli

    def huge(args):
        raise MemoryError

    monkeypatch.setattr(cli.info, "cmd_info", huge)
    assert cli.main(["info", "calib_files/hyperomni_aligned.yaml"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "out of memory" in err[0] and "smaller" in err[0]


REPO = __file__.rsplit("/tests/", 1)[0]


def test_an_export_whose_own_error_is_large_warns_on_one_line_naming_the_better_format(
    tmp_path, capsys
):
    from omnicam.cli import main

    assert (
        main(
            [
                "export",
                "calib_files/hyperomni_misaligned.yaml",
                "--to",
                "ocamcalib",
                "-o",
                str(tmp_path / "oc.txt"),
            ]
        )
        == 0
    )
    captured = capsys.readouterr()
    assert captured.out.startswith(f"wrote {tmp_path / 'oc.txt'} (ocamcalib): world2cam RMS")
    warning = [line for line in captured.err.splitlines() if "warning" in line]
    assert len(warning) == 1  # the sample misaligned rig: 2.3 px RMS in OCamCalib's model
    assert "fits this camera best is omnidir" in warning[0] and "omnicam maps" in warning[0]


def test_an_output_under_a_file_says_it_is_a_file_not_a_missing_folder(tmp_path, capsys):
    from omnicam.cli import main

    (tmp_path / "notes.txt").write_text("x")
    out = tmp_path / "notes.txt" / "rig.yaml"
    assert (
        main(["export", "calib_files/hyperomni_aligned.yaml", "--to", "omnidir", "-o", str(out)])
        == 1
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "notes.txt is a file, not a folder" in err[0], err


def test_a_calibration_file_that_cannot_be_written_is_said_once(tmp_path, capsys):
    from omnicam.cli._common import CliError, _save_camera

    cam = synthetic.misaligned_rig()
    with pytest.raises(CliError) as e:
        _save_camera(cam, str(tmp_path / "missing" / "rig.yaml"), True)
    assert str(e.value).count("cannot write") == 1, str(e.value)
