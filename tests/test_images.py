"""omnicam.images: one reader of image files and one grey conversion, on two scales."""

from __future__ import annotations

import os

import cv2
import numpy as np
import pytest

from omnicam.images import check_image, read_image, to_bgr8, to_gray

RNG = np.random.default_rng(7)
BGR8 = (RNG.random((40, 50, 3)) * 255).astype(np.uint8)
CV_GREY = cv2.cvtColor(BGR8, cv2.COLOR_BGR2GRAY)


def test_levels_of_an_8_bit_image_are_opencvs_grey():
    assert np.array_equal(to_gray(BGR8), cv2.cvtColor(BGR8.astype(np.float32), cv2.COLOR_BGR2GRAY))
    assert np.array_equal(to_gray(BGR8, dtype=np.uint8), CV_GREY)
    bgra = np.dstack([BGR8, np.full(BGR8.shape[:2], 9, np.uint8)])
    assert np.array_equal(to_gray(bgra, dtype=np.uint8), CV_GREY)  # alpha ignored


@pytest.mark.parametrize(
    "image",
    [BGR8.astype(np.uint16) * 257, BGR8.astype(np.float32) / 255.0, BGR8.astype(np.float64)],
    ids=["uint16", "float in [0, 1]", "float in [0, 255]"],
)
def test_levels_put_every_dtype_on_the_8_bit_scale(image):
    g = to_gray(image)
    assert g.dtype == np.float32 and g.shape == BGR8.shape[:2]
    assert np.abs(g - CV_GREY).max() <= 0.51  # OpenCV's 8-bit grey: fixed-point, rounded
    assert np.abs(to_gray(image, dtype=np.uint8).astype(int) - CV_GREY).max() <= 1
    assert np.abs(to_bgr8(image).astype(int) - BGR8).max() <= 1


def test_range_stretches_min_to_max_and_reads_nan_as_zero():
    img = np.full((40, 40), 1000.0)
    img[5:10, 5:10] = 3000.0
    img[0, 0] = np.nan
    g = to_gray(img, "range")
    assert g[7, 7] == 1.0 and g[0, 0] == 0.0 and g[20, 20] == pytest.approx(1000 / 3000)
    twelve_bits = np.nan_to_num(img).astype(np.uint16)
    assert to_gray(twelve_bits, "range", np.uint8)[7, 7] == 255  # not nearly black
    assert not to_gray(np.full((40, 40), 5.0), "range").any()  # uniform: all 0


@pytest.mark.parametrize(
    ("image", "match"),
    [
        ([[1, 2], [3, 4]], "numpy array"),
        (np.zeros((4, 4, 2)), "shape"),
        (np.zeros((0, 4)), "empty"),
        (np.zeros((4, 4), bool), "dtype bool"),
        (np.zeros((4, 4), complex), "dtype complex"),
    ],
)
def test_what_is_no_image_is_refused_by_name(image, match):
    with pytest.raises(ValueError, match=match):
        check_image(image, "images[2]")
    with pytest.raises(ValueError, match=r"images\[2\]"):
        to_gray(image, name="images[2]")


def test_a_bad_scale_or_dtype_is_named():
    with pytest.raises(ValueError, match="scale"):
        to_gray(BGR8, "linear")
    with pytest.raises(ValueError, match="dtype"):
        to_gray(BGR8, dtype=np.float64)


def test_read_image_reads_what_imread_reads(tmp_path):
    path = tmp_path / "a.png"
    cv2.imwrite(str(path), BGR8)
    assert np.array_equal(read_image(path), BGR8)
    assert read_image(path, cv2.IMREAD_GRAYSCALE).shape == BGR8.shape[:2]


def test_read_image_says_why_it_cannot(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        read_image(tmp_path / "none.png")
    with pytest.raises(ValueError, match="not a regular file"):
        read_image(tmp_path)
    (tmp_path / "empty.png").write_bytes(b"")
    with pytest.raises(ValueError, match="empty"):
        read_image(tmp_path / "empty.png")
    (tmp_path / "notes.png").write_text("not an image")
    with pytest.raises(ValueError, match=r"images\[1\] .*notes.png.*a text file, not an image"):
        read_image(tmp_path / "notes.png", name="images[1]")


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="needs a normal user")
def test_read_image_names_a_missing_permission(tmp_path):
    path = tmp_path / "a.png"
    cv2.imwrite(str(path), BGR8)
    path.chmod(0)
    with pytest.raises(ValueError, match="permission denied"):
        read_image(path)
