"""Physical validation of cameras and one error type (ValueError naming the argument)."""

import glob
import math
import os
import warnings

import numpy as np
import pytest
from conftest import RIGS

from omnicam import HyperbolicMirror, MisalignedHyperbolicCamera, synthetic

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _cam(**kw):
    c = synthetic.misaligned_rig()
    args = dict(K=c.K, mirror=c.mirror, rvec=c.rvec, tvec=c.tvec, D=c.D, image_size=c.image_size)
    args.update(kw)
    return MisalignedHyperbolicCamera(**args)


def test_every_canonical_rig_and_shipped_file_passes_validation():
    for cam in RIGS.values():
        assert cam.replace() == cam
    files = glob.glob(os.path.join(REPO, "calib_files", "*.yaml")) + glob.glob(
        os.path.join(REPO, "omnicam", "data", "*.yaml")
    )
    assert len(files) >= 4
    for path in files:
        MisalignedHyperbolicCamera.load(path)


@pytest.mark.parametrize(
    "rvec, tvec, field",
    [
        ((0, 0, 0), "upper_focus", "tvec"),  # the camera at the upper focus
        ((0, 0, 0), (0, 0, -100.0), "tvec"),  # above the mirror, looking away
        ((math.pi, 0, 0), None, "rvec"),  # turned round: the rim behind it
        ((0, math.pi / 2 + 0.3, 0), None, "rim"),  # looking sideways past the mirror
    ],
)
def test_impossible_postures_are_refused(rvec, tvec, field):
    c = synthetic.misaligned_rig()
    if tvec == "upper_focus":
        tvec = (0.0, 0.0, -c.mirror.c)
    with pytest.raises(ValueError, match=field):
        _cam(rvec=rvec, tvec=c.tvec if tvec is None else tvec)


def test_camera_at_the_lower_focus_is_the_aligned_rig_and_valid():
    cam = synthetic.aligned_rig()
    np.testing.assert_allclose(cam.camera_center, (0, 0, -cam.mirror.c), atol=1e-12)


def test_huge_rvec_is_refused_instead_of_a_nan_rotation():
    with pytest.raises(ValueError, match="rvec"):
        _cam(rvec=(1e300, 0, 0))


@pytest.mark.parametrize("value", [1e-300, 1e300, 1e-4, 2e6, 0, -1, float("nan"), "a", 1j, True])
@pytest.mark.parametrize("name", ["a", "b", "rim_radius"])
def test_mirror_parameters_outside_sane_magnitudes_are_refused(name, value):
    args = {"a": 28.0, "b": 23.0, "rim_radius": 30.0, name: value}
    with pytest.raises(ValueError, match=name):
        HyperbolicMirror(**args)


@pytest.mark.parametrize("fx, label", [(1e12, "fx"), (1e-3, "fx"), (-300.0, "fx")])
def test_focal_lengths_outside_the_stated_range_are_refused(fx, label):
    K = synthetic.misaligned_rig().K.copy()
    K[0, 0] = fx
    with pytest.raises(ValueError, match=label):
        _cam(K=K)


def test_rim_image_too_large_to_enumerate_is_refused():
    K = synthetic.misaligned_rig().K.copy()
    K[:2, :2] *= 100.0  # 100x the focal length: the rim spans tens of thousands of pixels
    with pytest.raises(ValueError, match="rim's image"):
        _cam(K=K)


@pytest.mark.parametrize("field", ["K", "rvec", "tvec", "D"])
def test_complex_parameters_are_refused_without_a_warning(field):
    c = synthetic.misaligned_rig()
    value = {
        "K": c.K.astype(complex),
        "rvec": np.array([0, 0, 0j]),
        "tvec": np.asarray(c.tvec) + 0j,
        "D": np.zeros(5, complex),
    }[field]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match=field):
            _cam(**{field: value})


@pytest.mark.parametrize(
    "size",
    [
        (float("inf"), 500),
        ("640", 480),
        "ab",
        (1e6, 1e6),
        (640.5, 480),
        (True, 480),
        (70000, 70000),
        (640,),
    ],
)
def test_bad_image_sizes_are_value_errors_naming_image_size(size):
    with pytest.raises(ValueError, match="image_size"):
        _cam(image_size=size)


@pytest.mark.parametrize("size", [(float("inf"), 128), ("ab", 5), (1j, 2), (True, 64)])
def test_view_sizes_that_are_not_integers_are_value_errors(size):
    with pytest.raises(ValueError, match="size"):
        synthetic.misaligned_rig().init_panorama_maps(size)


@pytest.mark.parametrize("n", ["a", 0, 1e12, float("inf"), 2.5])
def test_rim_point_count_is_bounded(n):
    with pytest.raises(ValueError, match="n must"):
        synthetic.misaligned_rig().rim_image_points(n)


@pytest.mark.parametrize(
    "kw, name",
    [
        ({"sigma": "a"}, "sigma"),
        ({"sigma": 1e6}, "sigma"),
        ({"sigma": 20.0}, "sigma"),
        ({"sigma": -1}, "sigma"),
        ({"threshold": "a"}, "threshold"),
        ({"threshold": 0}, "threshold"),
        ({"rng": "abc"}, "rng"),
        ({"rng": -1}, "rng"),
    ],
)
def test_detect_rim_refuses_bad_arguments_at_once(kw, name):
    import cv2

    from omnicam import detect_rim

    image = np.zeros((96, 96), np.uint8)  # sigma 20 exceeds 1/8 of its shorter side
    cv2.circle(image, (48, 48), 35, 200, -1)
    with pytest.raises(ValueError, match=name):
        detect_rim(image, **kw)


@pytest.mark.parametrize("content", [b"", b"\x89PNG\r\n\x1a\n" + b"\x00garbage" * 40])
def test_cli_unreadable_png_is_one_line_naming_it_without_opencv_noise(tmp_path, content):
    import subprocess
    import sys

    calib = tmp_path / "c.yaml"
    synthetic.misaligned_rig().save(calib)
    image = tmp_path / "in.png"
    image.write_bytes(content)
    r = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys; from omnicam.cli import main; sys.exit(main(sys.argv[1:]))",
            "unwarp",
            str(image),
            "-c",
            str(calib),
            "--panorama",
            "128x32",
            "-o",
            str(tmp_path / "out.png"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 1
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("omnicam: error: cannot read image"), lines
    assert str(image) in lines[0]
