"""find_pattern: chessboard corners in omnidirectional renders, mapped back to the source image."""

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
    """A board facing the rig at about the given elevation and azimuth (mirror frame)."""
    return boards.random_board_poses(
        RIG,
        1,
        PATTERN,
        SQUARE,
        distance=(distance, distance * 1.1),
        elevation=(elevation_deg - 3.0, elevation_deg + 3.0),
        max_tilt_deg=30.0,
        rng=seed,
        azimuth=(azimuth_deg - 20.0, azimuth_deg + 20.0),
    )[0]


def _match(found, truth):
    """Largest corner error, allowing OpenCV's 180-degree ambiguity of the board."""
    f = found.reshape(-1, 2).astype(np.float64)
    t = truth.reshape(-1, 2)
    return min(np.abs(f - t).max(), np.abs(f[::-1] - t).max())


@pytest.mark.parametrize(
    "elevation, azimuth, distance",
    [
        (-8.0, 40.0, 1000.0),  # next to the rim
        (-25.0, 160.0, 450.0),  # the middle of the annulus
        (-50.0, 250.0, 500.0),  # towards the centre, next to the camera's reflection
    ],
    ids=["rim", "middle", "centre"],
)
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
    truth = boards.board_corners(RIG, PATTERN, SQUARE, rvec, tvec).reshape(
        PATTERN[1], PATTERN[0], 2
    )
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


def test_cli_calibrates_from_chessboard_images_without_intrinsics(tmp_path, capsys):
    import cv2

    from omnicam.cli import main

    poses = [  # one board in each quadrant: views on every side of the mirror
        boards.random_board_poses(
            RIG,
            1,
            PATTERN,
            SQUARE,
            distance=(350.0, 700.0),
            max_tilt_deg=40.0,
            rng=11 + q,
            azimuth=(90.0 * q, 90.0 * q + 60.0),
        )[0]
        for q in range(4)
    ]
    paths = []
    for i, p in enumerate(poses):
        path = tmp_path / f"board{i}.png"
        cv2.imwrite(str(path), boards.render_board(RIG, PATTERN, SQUARE, *p, supersample=2))
        paths.append(str(path))
    calib = tmp_path / "rig.yaml"
    code = main(
        [
            "calibrate",
            "--chessboard",
            "7x5",
            "--square",
            "60",
            *paths,
            "--mirror",
            "23.4",
            "28.1",
            "30",
            "--dist-model",
            "none",
            "-o",
            str(calib),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0, out
    assert "rms px" in out and calib.exists()
    assert len(list((tmp_path / "rig_views").glob("*.png"))) == 4
    cam = omnicam.MisalignedHyperbolicCamera.load(str(calib))
    assert abs(cam.K[0, 0] / RIG.K[0, 0] - 1.0) < 0.02


def test_cli_chessboard_needs_square_and_one_image_without_it(tmp_path, capsys):
    from omnicam.cli import main

    args = [
        "calibrate",
        "a.png",
        "b.png",
        "--mirror",
        "23.4",
        "28.1",
        "30",
        "-o",
        str(tmp_path / "r.yaml"),
    ]
    assert main(args) == 2
    assert "one IMAGE" in capsys.readouterr().err
    assert main([*args, "--chessboard", "7x5"]) == 2
    assert "--square" in capsys.readouterr().err
    assert (
        main(
            ["calibrate", "a.png", "--mirror", "23.4", "28.1", "30", "-o", str(tmp_path / "r.yaml")]
        )
        == 2
    )
    assert "--intrinsics" in capsys.readouterr().err


def test_board_in_a_degraded_render_of_a_furnished_room_is_found_and_an_empty_one_is_not():
    from omnicam.synthetic import realistic

    room = realistic.random_room(np.random.default_rng(5))  # doors, posters, a rug
    photo = realistic.Photometric(vignette=0.3, blur_sigma=1.0, noise_sigma=3.0, jpeg_quality=80)
    rvec, tvec = _board_at(-25.0, 100.0, 500.0, seed=4)
    img = boards.render_board(
        RIG, PATTERN, SQUARE, rvec, tvec, supersample=3, seed=2, room=room, photometric=photo
    )
    truth = boards.board_corners(RIG, PATTERN, SQUARE, rvec, tvec)
    found = omnicam.find_pattern(img, PATTERN, ROUGH)
    assert found is not None
    assert _match(found, truth) < 0.4  # px, blurred, noisy and compressed
    empty = boards.render_board(
        RIG, PATTERN, SQUARE, None, None, supersample=2, seed=3, room=room, photometric=photo
    )
    assert omnicam.find_pattern(empty, PATTERN, ROUGH) is None


# -- no camera first ---------------------------------------------------------------------------
def test_opencv_detectors_on_the_raw_image_need_no_camera_and_give_the_boards_order():
    """OpenCV's detectors on the image as it is: the corners the mirror shows mirrored are put
    back in the board's own order (what a rigid pose explains), up to its 180-degree turn."""
    from omnicam.chessboard.detect import detect_pattern

    rvec, tvec = _board_at(-20.0, 90.0, 450.0, seed=7)
    img = boards.render_board(RIG, PATTERN, SQUARE, rvec, tvec, supersample=3, noise=1.0, seed=2)
    truth = boards.board_corners(RIG, PATTERN, SQUARE, rvec, tvec)
    found = detect_pattern(img, PATTERN)  # no camera at all
    assert found is not None and found.method in ("raw", "raw-sb")
    assert _match(found.corners, truth) < 0.3
    assert omnicam.find_pattern(img, PATTERN) is not None
    empty = boards.render_board(RIG, PATTERN, SQUARE, None, None, supersample=2)
    assert detect_pattern(empty, PATTERN) is None


def test_views_are_skipped_without_a_camera_and_unknown_methods_are_refused():
    from omnicam.chessboard.detect import detect_pattern

    img = boards.render_board(RIG, PATTERN, SQUARE, None, None, supersample=1)
    assert detect_pattern(img, PATTERN, methods=("views",)) is None
    with pytest.raises(ValueError, match="methods"):
        detect_pattern(img, PATTERN, methods=("hough",))


def test_calibrate_pattern_from_images_says_how_each_board_was_found():
    poses = [_board_at(-22.0, az, 500.0, seed=k) for k, az in enumerate(range(0, 360, 60))]
    images = [
        boards.render_board(RIG, PATTERN, SQUARE, rv, tv, supersample=2, noise=1.0, seed=k)
        for k, (rv, tv) in enumerate(poses)
    ]
    images.append(boards.render_board(RIG, PATTERN, SQUARE, None, None, supersample=1))
    with pytest.warns(RuntimeWarning, match="view 6 dropped: no board found"):
        cam, report = omnicam.calibrate_pattern(
            images,
            PATTERN,
            SQUARE,
            RIG.mirror,
            boundary_points=RIG.rim_image_points(360),
            lens=None,
        )
    assert sorted(report.found_by) == list(range(6))  # the empty image: no board, no method
    assert set(report.found_by.values()) <= {"raw", "raw-sb", "views", "views (fitted camera)"}
    assert report.dropped == {6: "no board found"}
    assert report.rms < 0.5
    assert "found by" in report.table()
    for i, (rv, tv) in enumerate(poses):
        truth = boards.board_corners(RIG, PATTERN, SQUARE, rv, tv)
        assert _match(report.image_points[i], truth) < 0.4
