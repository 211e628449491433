"""read_intrinsics also reads ROS camera_info, Kalibr camchains and OpenCV's other layouts."""

import cv2
import numpy as np
import pytest

from omnicam import read_intrinsics
from omnicam.intrinsics_formats import parse_yaml

K_REF = np.array([[582.5, 0.0, 319.5], [0.0, 580.25, 239.75], [0.0, 0.0, 1.0]])

ROS = """\
image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [582.5, 0, 319.5, 0, 580.25, 239.75, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.1, 0.02, 0.001, -0.002, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0,
         0, 1, 0,
         0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [582.5, 0, 319.5, 0, 0, 580.25, 239.75, 0, 0, 0, 1, 0]
"""

KALIBR = """\
# a camchain as kalibr_calibrate_cameras writes it
cam0:
  cam_overlaps: []
  camera_model: pinhole
  distortion_coeffs: [-0.1, 0.02, 0.001, -0.002]
  distortion_model: radtan
  intrinsics: [582.5, 580.25, 319.5, 239.75]
  resolution: [640, 480]
  rostopic: /cam0/image_raw
cam1:
  camera_model: pinhole
  intrinsics: [1, 1, 1, 1]
"""

# OpenCV's samples/cpp/calibration.cpp output (out_camera_data.yml), abridged
OPENCV_SAMPLE = """\
%YAML:1.0
---
calibration_time: "Mon 01 Dec 2026"
nframes: 12
image_width: 640
image_height: 480
board_width: 9
board_height: 6
square_size: 25.
flags: 0
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 582.5, 0., 319.5, 0., 580.25, 239.75, 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 5
   cols: 1
   dt: d
   data: [ -0.1, 0.02, 0.001, -0.002, 0. ]
avg_reprojection_error: 0.3
"""


def test_ros_camera_info_yaml(tmp_path):
    p = tmp_path / "camera_info.yaml"
    p.write_text(ROS)
    K, D, size = read_intrinsics(p)
    np.testing.assert_array_equal(K, K_REF)
    np.testing.assert_array_equal(D, [-0.1, 0.02, 0.001, -0.002, 0.0])
    assert size == (640, 480)


def test_ros_fisheye_model_is_refused_naming_the_field(tmp_path):
    p = tmp_path / "camera_info.yaml"
    p.write_text(ROS.replace("plumb_bob", "equidistant"))
    with pytest.raises(ValueError, match="distortion_model"):
        read_intrinsics(p)


def test_kalibr_pinhole_radtan_camchain_reads_cam0(tmp_path):
    p = tmp_path / "camchain.yaml"
    p.write_text(KALIBR)
    K, D, size = read_intrinsics(p)
    np.testing.assert_array_equal(K, K_REF)
    np.testing.assert_array_equal(D, [-0.1, 0.02, 0.001, -0.002])
    assert size == (640, 480)


def test_kalibr_omni_camera_is_refused_naming_the_field(tmp_path):
    p = tmp_path / "camchain.yaml"
    p.write_text(KALIBR.replace("camera_model: pinhole", "camera_model: omni", 1))
    with pytest.raises(ValueError, match="camera_model"):
        read_intrinsics(p)


def test_kalibr_missing_intrinsics_names_the_field(tmp_path):
    p = tmp_path / "camchain.yaml"
    p.write_text(KALIBR.replace("  intrinsics: [582.5, 580.25, 319.5, 239.75]\n", ""))
    with pytest.raises(ValueError, match="intrinsics"):
        read_intrinsics(p)


def test_opencv_calibration_sample_output(tmp_path):
    p = tmp_path / "out_camera_data.yml"
    p.write_text(OPENCV_SAMPLE)
    K, D, size = read_intrinsics(p)
    np.testing.assert_array_equal(K, K_REF)
    np.testing.assert_array_equal(D, [-0.1, 0.02, 0.001, -0.002, 0.0])
    assert tuple(size) == (640, 480)


@pytest.mark.parametrize("ext", [".yaml", ".xml", ".json"])
def test_filestorage_with_image_size_as_a_matrix(tmp_path, ext):
    p = str(tmp_path / f"k{ext}")
    fs = cv2.FileStorage(p, cv2.FILE_STORAGE_WRITE)
    fs.write("K", K_REF)
    fs.write("D", np.array([-0.1, 0.02, 0.001, -0.002, 0.0]))
    fs.write("image_size", np.array([640, 480], dtype=np.int32))
    fs.release()
    K, _D, size = read_intrinsics(p)
    np.testing.assert_array_equal(K, K_REF)
    assert size == (640, 480)


def test_image_size_matrix_of_three_values_is_refused(tmp_path):
    p = str(tmp_path / "k.yaml")
    fs = cv2.FileStorage(p, cv2.FILE_STORAGE_WRITE)
    fs.write("K", K_REF)
    fs.write("image_size", np.array([640, 480, 3], dtype=np.int32))
    fs.release()
    with pytest.raises(ValueError, match="image_size"):
        read_intrinsics(p)


def test_parse_yaml_subset():
    doc = parse_yaml(
        "a: 1\nb:\n  - x: 2\n    y: [1, 2.5, 'q']\n  - 3\nc: {d: true, e: null}\n"
        "f: 'hi # not a comment'  # a comment\n"
    )
    assert doc == {
        "a": 1,
        "b": [{"x": 2, "y": [1, 2.5, "q"]}, 3],
        "c": {"d": True, "e": None},
        "f": "hi # not a comment",
    }
    with pytest.raises(ValueError):
        parse_yaml("a: [1, 2\n")


@pytest.mark.parametrize(
    "body",
    [
        "camera_matrix: " + "[" * 5000 + "]" * 5000,
        "camera_matrix:\n" + "".join(" " * i + f"k{i}:\n" for i in range(3000)),
    ],
    ids=["flow", "indentation"],
)
def test_deeply_nested_ros_yaml_is_a_value_error_not_a_crash(tmp_path, body):
    p = tmp_path / "camera_info.yaml"
    p.write_text(body)
    with pytest.raises(ValueError, match="camera_info.yaml"):
        read_intrinsics(p)
