"""A strip no camera's frame of a mirror has (8:1): the library's rim search says so, as
``omnicam calibrate`` does, in the same words and once (issue 29 item 7)."""

import cv2
import numpy as np
import pytest

import omnicam
from omnicam.cli import main
from omnicam.images import aspect_note

NOTE = "the image is {w}x{h} (8.0:1), no camera's frame of a mirror"


@pytest.mark.parametrize("shape", [(500, 4000), (4000, 500)], ids=["wide", "tall"])
def test_detect_rim_on_an_8_to_1_strip_says_what_calibrate_says(tmp_path, capsys, shape):
    h, w = shape
    strip = np.full((h, w, 3), 90, np.uint8)
    with pytest.raises(ValueError) as info:
        omnicam.detect_rim(strip)
    said = str(info.value)
    assert said.startswith("no ellipse found") and NOTE.format(w=w, h=h) in said
    assert said.endswith(aspect_note((w, h)))
    path = tmp_path / "strip.png"
    cv2.imwrite(str(path), strip)
    argv = ["calibrate", str(path), "--mirror", "23.4", "28.1", "30", "--guess-k"]
    assert main([*argv, "-o", str(tmp_path / "c.yaml")]) == 1
    (err,) = [ln for ln in capsys.readouterr().err.splitlines() if "error" in ln]
    assert err.count(NOTE.format(w=w, h=h)) == 1


def test_a_frame_of_a_camera_gets_no_note():
    assert aspect_note((1920, 1080)) == "" and aspect_note((500, 1500)) == ""
    with pytest.raises(ValueError) as info:
        omnicam.detect_rim(np.full((480, 640, 3), 90, np.uint8))
    assert "camera's frame" not in str(info.value)
