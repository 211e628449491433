"""Another tool's camera file where omnicam's calibration file is expected is named for what it
is, with the option that reads it (issue 29 item 7): CALIB of unwarp, maps, info, export,
report and calibrate --from."""

import warnings

import cv2
import numpy as np
import pytest
from test_intrinsics_formats import KALIBR, ROS

from omnicam import synthetic
from omnicam.cli import main
from omnicam.formats.central_export import export

RIG = synthetic.misaligned_rig()


def _exported(path, fmt):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        export(RIG, fmt, path)
    return path


KINDS = {  # name: (make the file, what the message says it is, what it says to do)
    "kalibr-pinhole": (
        lambda d: d / "camchain.yaml",
        "is a Kalibr camchain (a pinhole camera), not an omnicam calibration",
        "--intrinsics",
    ),
    "kalibr-omni": (
        lambda d: _exported(d / "camchain.yaml", "kalibr"),
        "is a Kalibr camchain (camera_model omni), not an omnicam calibration",
        "no option of omnicam reads",
    ),
    "ros": (
        lambda d: d / "camera_info.yaml",
        "is a ROS camera_info, not an omnicam calibration",
        "--intrinsics",
    ),
    "ocamcalib": (
        lambda d: _exported(d / "calib_results.txt", "ocamcalib"),
        "is an OCamCalib calib_results.txt, not an omnicam calibration",
        "--chessboard",
    ),
    "omnidir": (
        lambda d: _exported(d / "omnidir.yaml", "omnidir"),
        "is a cv2.omnidir calibration (it has an xi), not an omnicam calibration",
        "no option of omnicam reads",
    ),
}
COMMANDS = {  # where omnicam's calibration file is expected
    "unwarp": lambda c, d: [
        "unwarp",
        str(d / "in.png"),
        "-c",
        c,
        "--panorama",
        "64x16",
        "-o",
        str(d / "o.png"),
    ],
    "maps": lambda c, d: ["maps", c, "--panorama", "64x16", "--npy", "-o", str(d / "m")],
    "info": lambda c, d: ["info", c],
    "export": lambda c, d: ["export", c, "--to", "omnidir", "-o", str(d / "x.yaml")],
    "report": lambda c, d: ["report", c, str(d / "in.png"), "-o", str(d / "r.html")],
    "from": lambda c, d: ["calibrate", str(d / "in.png"), "--from", c, "-o", str(d / "n.yaml")],
}


@pytest.mark.parametrize("kind", sorted(KINDS))
@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_another_tools_file_given_as_the_calibration_is_named_with_its_option(
    tmp_path, capsys, kind, command
):
    make, what, todo = KINDS[kind]
    path = make(tmp_path)
    if kind == "kalibr-pinhole":
        path.write_text(KALIBR)
    elif kind == "ros":
        path.write_text(ROS)
    cv2.imwrite(str(tmp_path / "in.png"), np.zeros((500, 500, 3), np.uint8))
    assert main(COMMANDS[command](str(path), tmp_path)) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert f"{path} {what}" in err[0] and todo in err[0], err[0]
