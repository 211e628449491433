"""find_pattern: chessboard corners in omnidirectional renders, mapped back to the source image."""
import math

import numpy as np
import pytest

import omnicam
from omnicam import synthetic
from omnicam.synthetic import boards

PATTERN, SQUARE = (7, 5), 60.0
SIZE = (700, 700)
RIG = synthetic.misaligned_rig(3.0, 30.0, (1.5, -2.0, 1.9), image_size=SIZE)
# a first calibration as rough as the start of calibrate_pattern: the aligned model
ROUGH = synthetic.aligned_rig(SIZE)


def _board_at(elevation_deg, azimuth_deg, distance, seed):
    """A board facing the rig at the given elevation, tilted a little (mirror frame)."""
    rng = np.random.default_rng(seed)
    for _ in range(200):
        poses = boards.random_board_poses(
            RIG, 1, PATTERN, SQUARE, distance=(distance, distance * 1.1),
            elevation=(elevation_deg - 3.0, elevation_deg + 3.0), max_tilt_deg=30.0, rng=rng)
        t = poses[0][1]
        az = math.degrees(math.atan2(t[1], t[0]))
        if abs((az - azimuth_deg + 180.0) % 360.0 - 180.0) < 60.0:
            return poses[0]
    raise AssertionError("no pose")


def _match(found, truth):
    """Largest corner error, allowing OpenCV's 180-degree ambiguity of the board."""
    f = found.reshape(-1, 2).astype(np.float64)
    t = truth.reshape(-1, 2)
    return min(np.abs(f - t).max(), np.abs(f[::-1] - t).max())


@pytest.mark.parametrize("elevation, azimuth, distance", [
    (5.0, 40.0, 500.0),     # next to the rim
    (-25.0, 160.0, 450.0),  # the middle of the annulus
    (-55.0, 250.0, 350.0),  # towards the centre
], ids=["rim", "middle", "centre"])
def test_board_is_found_from_the_rim_to_the_centre_of_the_annulus(elevation, azimuth, distance):
    rvec, tvec = _board_at(elevation, azimuth, distance, seed=int(distance))
    img = boards.render_board(RIG, PATTERN, SQUARE, rvec, tvec, supersample=3, noise=1.0, seed=1)
    truth = boards.board_corners(RIG, PATTERN, SQUARE, rvec, tvec)
    found = omnicam.find_pattern(img, PATTERN, ROUGH)
    assert found is not None
    assert found.shape == (PATTERN[0] * PATTERN[1], 1, 2) and found.dtype == np.float32
    assert _match(found, truth) < 0.3  # px, through a rough calibration


def test_corners_come_row_by_row_as_opencv_orders_them():
    rvec, tvec = _board_at(-20.0, 90.0, 450.0, seed=7)
    img = boards.render_board(RIG, PATTERN, SQUARE, rvec, tvec, supersample=3)
    found = omnicam.find_pattern(img, PATTERN, ROUGH).reshape(PATTERN[1], PATTERN[0], 2)
    truth = boards.board_corners(RIG, PATTERN, SQUARE, rvec, tvec).reshape(PATTERN[1],
                                                                           PATTERN[0], 2)
    if np.abs(found - truth).max() > 1.0:
        truth = truth[::-1, ::-1]  # the board turned by 180 degrees: the same grid
    assert np.abs(found - truth).max() < 0.3


def test_image_without_a_board_gives_none():
    img = boards.render_board(RIG, PATTERN, SQUARE, None, None, supersample=2)
    assert omnicam.find_pattern(img, PATTERN, ROUGH) is None


def test_a_board_of_another_size_gives_none():
    rvec, tvec = _board_at(-20.0, 300.0, 450.0, seed=3)
    img = boards.render_board(RIG, PATTERN, SQUARE, rvec, tvec, supersample=2)
    assert omnicam.find_pattern(img, (PATTERN[0] + 2, PATTERN[1] + 1), ROUGH) is None


def test_image_of_another_size_than_the_camera_raises():
    with pytest.raises(ValueError, match="image_size"):
        omnicam.find_pattern(np.zeros((300, 300), np.uint8), PATTERN, ROUGH)
