"""read_intrinsics also reads ROS camera_info, Kalibr camchains and OpenCV's other layouts;
it refuses central models (cv2.omnidir, Kalibr omni, OCamCalib) saying what they are, and
read_central_model imports the unified ones as the start of a chessboard calibration."""

import cv2
import numpy as np
import pytest

from omnicam import read_intrinsics, synthetic
from omnicam.chessboard.central import hyperbolic_start
from omnicam.cli import main
from omnicam.formats.central_export import export
from omnicam.formats.intrinsics import read_central_model
from omnicam.formats.other_tools import MAX_NESTING, parse_yaml

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


# A two-camera chain with an IMU as kalibr_calibrate_imu_camera writes it (PyYAML's style: the
# T_* matrices are block sequences at their key's own indentation, which cv2.FileStorage refuses)
KALIBR_IMU_CHAIN = """\
cam0:
  T_cam_imu:
  - [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975]
  - [0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768]
  - [-0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949]
  - [0.0, 0.0, 0.0, 1.0]
  cam_overlaps: [1]
  camera_model: pinhole
  distortion_coeffs: [-0.1, 0.02, 0.001, -0.002]
  distortion_model: radtan
  intrinsics: [582.5, 580.25, 319.5, 239.75]
  resolution: [640, 480]
  rostopic: /cam0/image_raw
  timeshift_cam_imu: 5.63114e-05
cam1:
  T_cn_cnm1:
  - [0.999997256478, 0.00231206719995, 0.000376008102320, -0.110073808127]
  - [-0.00231713572425, 0.999898048507, 0.0140898358431, 0.000399121547014]
  - [-0.000343393120525, -0.0140906685209, 0.999900662638, -0.000853702503357]
  - [0.0, 0.0, 0.0, 1.0]
  cam_overlaps: [0]
  camera_model: pinhole
  intrinsics: [1.0, 1.0, 1.0, 1.0]
"""

KALIBR_OMNI = """\
cam0:
  camera_model: omni
  intrinsics: [0.9641, 250.5, 251.25, 160.0, 159.5]
  distortion_model: radtan
  distortion_coeffs: [-0.01, 0.002, 0.0003, -0.0004]
  resolution: [320, 320]
  rostopic: /cam0/image_raw
"""

ALIGNED = synthetic.aligned_rig(image_size=(320, 320))


def test_kalibr_chain_with_imu_and_a_second_camera_reads_cam0(tmp_path):
    p = tmp_path / "camchain-imucam.yaml"
    p.write_text(KALIBR_IMU_CHAIN)
    K, D, size = read_intrinsics(p)
    np.testing.assert_array_equal(K, K_REF)
    np.testing.assert_array_equal(D, [-0.1, 0.02, 0.001, -0.002])
    assert size == (640, 480)
    doc = parse_yaml(KALIBR_IMU_CHAIN)
    assert doc["cam1"]["T_cn_cnm1"][0] == [
        0.999997256478,
        0.00231206719995,
        0.00037600810232,
        -0.110073808127,
    ]
    assert doc["cam0"]["timeshift_cam_imu"] == 5.63114e-05 and doc["cam1"]["cam_overlaps"] == [0]
    # why parse_yaml and not cv2.FileStorage: OpenCV's YAML reader refuses this file
    with pytest.raises((cv2.error, SystemError)):
        fs = cv2.FileStorage(KALIBR_IMU_CHAIN, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
        assert not fs.isOpened()
        raise cv2.error("not opened")


@pytest.mark.parametrize(
    "text, value",
    [  # each value is what PyYAML's safe_load gives
        ("a:\n- - 1\n  - 2\n- - 3\n", {"a": [[1, 2], [3]]}),
        ("a:\n  - [1, 2]\n  - [3.5, -4.0e-05]\n", {"a": [[1, 2], [3.5, -4.0e-05]]}),
        ("a:\n- 'x: y'\n- \"q # r\"\n", {"a": ["x: y", "q # r"]}),
        ("a: [1,\n    2, [3,\n  4]]\nb: 5\n", {"a": [1, 2, [3, 4]], "b": 5}),
        ("- x: 1\n  y: [2]\n- 3\n", [{"x": 1, "y": [2]}, 3]),
        (
            "m: !!opencv-matrix\n   rows: 1\n   data: [ 1., 2. ]\n",
            {"m": {"rows": 1, "data": [1.0, 2.0]}},
        ),
        (
            "a: !!float 2\nb: ~\nc:\nd: /cam0/image_raw\n",
            {"a": 2.0, "b": None, "c": None, "d": "/cam0/image_raw"},
        ),
        ("%YAML 1.1\n---\na: {b: [1, {c: 2}], d: e}\n...\n", {"a": {"b": [1, {"c": 2}], "d": "e"}}),
        ("a:\n  b:\n    - 1\n  c: 2\n", {"a": {"b": [1], "c": 2}}),
    ],
    ids=[
        "nested-sequences",
        "flow-rows",
        "quoted-items",
        "multi-line-flow",
        "sequence-of-maps",
        "opencv-tag",
        "scalars",
        "directives",
        "nested-map",
    ],
)
def test_parse_yaml_reads_what_pyyaml_reads(text, value):
    assert parse_yaml(text) == value


@pytest.mark.parametrize(
    "text, message",
    [
        ("a: 1\n  b: 2\n", "at line 2, column 4"),
        ("a: 1\n- 2\n", "at line 2, column 1"),
        ("a: [1, 2}\n", "expected ',' or ']'.* at line 1"),
        ("camera_matrix: {rows: 3]\n", "expected ',' or '}'.* at line 1"),
        ("a: [1] x\n", "at line 1, column 8"),
        ("a: " + "[" * (MAX_NESTING + 2) + "]" * (MAX_NESTING + 2) + "\n", "nested too deeply"),
        (
            "".join(" " * i + f"k{i}:\n" for i in range(MAX_NESTING + 2)) + " " * 99 + "v: 1\n",
            "nested too deeply",
        ),
    ],
    ids=[
        "indentation",
        "item-after-map",
        "bracket",
        "brace",
        "trailing-text",
        "deep-flow",
        "deep-blocks",
    ],
)
def test_parse_yaml_refuses_what_it_does_not_read(text, message):
    with pytest.raises(ValueError, match=message):
        parse_yaml(text)


def _omnidir_sample(path, K, D, xi):
    """A file as OpenCV's omni_calibration sample writes it (camera_matrix, ..., xi)."""
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("calibration_time", "Mon 01 Dec 2026")
    fs.write("flags", 0)
    fs.write("camera_matrix", K)
    fs.write("distortion_coefficients", np.asarray(D, np.float64).reshape(1, 4))
    fs.write("xi", xi)
    fs.write("rms", 0.25)
    fs.release()
    return path


@pytest.mark.parametrize("ext", [".yaml", ".xml", ".json"])
def test_cv2_omnidir_calibration_is_refused_as_intrinsics_and_read_as_central(tmp_path, ext):
    D = [-0.01, 0.002, 0.0003, -0.0004]
    p = _omnidir_sample(tmp_path / f"omni{ext}", K_REF, D, 0.9641)
    with pytest.raises(ValueError, match=r"cv2\.omnidir calibration .*xi = 0\.9641.*not pinhole"):
        read_intrinsics(p)
    m = read_central_model(p)
    assert set(m) == {"K", "xi", "D", "image_size"}
    np.testing.assert_array_equal(m["K"], K_REF)
    np.testing.assert_array_equal(m["D"], D)
    assert m["xi"] == 0.9641 and m["image_size"] is None


def test_the_refusal_says_why_and_what_to_do(tmp_path):
    p = _omnidir_sample(tmp_path / "omni.yaml", K_REF, np.zeros(4), 0.9)
    with pytest.raises(ValueError) as e:
        read_intrinsics(p)
    text = str(e.value)
    assert str(p) in text and "the unified model's" in text and "f sqrt(1 - xi^2)" in text
    assert "read_central_model" in text


@pytest.mark.parametrize("fmt", ["omnidir", "kalibr"])
def test_omnicams_own_exports_are_refused_as_intrinsics(tmp_path, fmt):
    p = tmp_path / "x.yaml"
    export(ALIGNED, fmt, p)
    with pytest.raises(ValueError, match="not pinhole intrinsics"):
        read_intrinsics(p)


@pytest.mark.parametrize("fmt", ["omnidir", "kalibr"])
def test_a_central_export_starts_the_aligned_rig_again(tmp_path, fmt):
    """read_central_model's dict is what chessboard.central starts from: the aligned rig's
    unified model and rim give back its K and mirror."""
    p = tmp_path / "x.yaml"
    fit = export(ALIGNED, fmt, p)
    m = read_central_model(p)
    assert m["xi"] == pytest.approx(fit.xi, abs=1e-12) and m["image_size"] == (320, 320)
    np.testing.assert_allclose(m["K"], fit.K, atol=1e-9)
    rim = ALIGNED.rim_image_points(360)
    r_px = float(np.linalg.norm(rim - ALIGNED.K[:2, 2], axis=1).mean())
    K, mirror = hyperbolic_start(m["K"], m["xi"], r_px, ALIGNED.mirror.rim_radius)
    np.testing.assert_allclose(K, ALIGNED.K, atol=1e-6 * ALIGNED.K[0, 0])
    assert mirror.a == pytest.approx(ALIGNED.mirror.a, rel=1e-6)
    assert mirror.b == pytest.approx(ALIGNED.mirror.b, rel=1e-6)


def test_kalibr_omni_camchain_is_refused_as_intrinsics_and_read_as_central(tmp_path):
    p = tmp_path / "camchain.yaml"
    p.write_text(KALIBR_OMNI)
    with pytest.raises(ValueError, match=r"camera_model 'omni'.*xi = 0\.9641.*read_central_model"):
        read_intrinsics(p)
    m = read_central_model(p)
    np.testing.assert_array_equal(m["K"], [[250.5, 0.0, 160.0], [0.0, 251.25, 159.5], [0, 0, 1]])
    np.testing.assert_array_equal(m["D"], [-0.01, 0.002, 0.0003, -0.0004])
    assert m["xi"] == 0.9641 and m["image_size"] == (320, 320)


def test_ocamcalib_file_is_refused_with_its_reason(tmp_path):
    p = tmp_path / "calib_results.txt"
    export(ALIGNED, "ocamcalib", p)
    for read in (read_intrinsics, read_central_model):
        with pytest.raises(ValueError, match=r"calib_results\.txt: an OCamCalib .*no K or D"):
            read(p)


@pytest.mark.parametrize(
    "name, text, message",
    [
        ("camera_info.yaml", ROS, "ROS camera_info: pinhole intrinsics"),
        ("camchain.yaml", KALIBR, "'pinhole', not a central model"),
        ("camchain.yaml", KALIBR_OMNI.replace("0.9641", "-0.5"), "xi must be a finite number >= 0"),
        ("camchain.yaml", KALIBR_OMNI.replace("radtan", "equidistant"), "distortion_model"),
        ("camchain.yaml", KALIBR_OMNI.replace("0.9641, ", ""), "'intrinsics' must have 5"),
    ],
)
def test_read_central_model_refuses_what_holds_none(tmp_path, name, text, message):
    p = tmp_path / name
    p.write_text(text)
    with pytest.raises(ValueError, match=message):
        read_central_model(p)


def test_read_central_model_names_the_missing_xi_and_a_bad_D(tmp_path):
    ALIGNED.save(tmp_path / "rig.yaml")
    with pytest.raises(ValueError, match=r"rig\.yaml: field 'xi' is missing"):
        read_central_model(tmp_path / "rig.yaml")
    fs = cv2.FileStorage(str(tmp_path / "o.yaml"), cv2.FILE_STORAGE_WRITE)
    fs.write("K", K_REF)
    fs.write("D", np.zeros(5))
    fs.write("xi", 0.9)
    fs.release()
    with pytest.raises(ValueError, match=r"o\.yaml: D must be 4 numbers"):
        read_central_model(tmp_path / "o.yaml")


def test_cli_refuses_an_omnidir_file_as_intrinsics_in_one_line(tmp_path, capsys):
    k = _omnidir_sample(tmp_path / "omni.yaml", K_REF, np.zeros(4), 0.9)
    image = tmp_path / "x.png"
    cv2.imwrite(str(image), np.zeros((32, 32, 3), np.uint8))
    argv = [
        "calibrate",
        str(image),
        "--mirror",
        "28.1",
        "23.4",
        "30",
        "--intrinsics",
        str(k),
        "-o",
        str(tmp_path / "rig.yaml"),
    ]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("omnicam: error: intrinsics file") and "\n" not in err
    assert "cv2.omnidir calibration" in err and not (tmp_path / "rig.yaml").exists()


def test_a_mismatched_bracket_in_a_ros_file_is_an_error_not_a_hang(tmp_path):
    # the earlier reader looped for ever (and without bound in memory) on "[1, 2}"
    p = tmp_path / "camera_info.yaml"
    p.write_text(ROS.replace("data: [582.5, 0, 319.5, 0, 580.25, 239.75, 0, 0, 1]", "data: [1, 2}"))
    with pytest.raises(ValueError, match=r"camera_info\.yaml: not YAML omnicam can read"):
        read_intrinsics(p)


def test_parse_yaml_refuses_aliases_at_once():
    bomb = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"{c}: &{c} [{', '.join(['*' + p] * 9)}]\n" for p, c in zip("abcdefgh", "bcdefghi")
    )
    with pytest.raises(ValueError, match="aliases"):
        parse_yaml(bomb)
