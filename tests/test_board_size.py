"""A detected grid must be a chessboard's, and a pattern size the board contradicts is refused
with the size to give (omnicam.chessboard.detect.check_grid, omnicam.chessboard.board_size)."""

import warnings

import cv2
import numpy as np
import pytest

import omnicam
from omnicam import synthetic
from omnicam.chessboard import board_size, detect
from omnicam.synthetic import boards

BOARD, SQUARE = (7, 9), 40.0  # the board in the renders: 7x9 inner corners
SUB = (7, 5)  # a sub-board of it: OpenCV's SB detector returns a grid that skips rows
SIZE = (600, 600)
RIG = synthetic.misaligned_rig(3.0, 30.0, (1.5, -2.0, 1.9), image_size=SIZE)


@pytest.fixture(scope="module")
def renders():
    """Three renders of the 7x9 board, in the middle of the annulus on three sides."""
    out = []
    for k, az in enumerate((30.0, 150.0, 270.0)):
        rvec, tvec = boards.random_board_poses(
            RIG,
            1,
            BOARD,
            SQUARE,
            distance=(450.0, 500.0),
            elevation=(-23.0, -17.0),
            max_tilt_deg=20.0,
            rng=k,
            azimuth=(az - 20.0, az + 20.0),
        )[0]
        img = boards.render_board(RIG, BOARD, SQUARE, rvec, tvec, supersample=2, noise=1.0, seed=k)
        out.append((img, boards.board_corners(RIG, BOARD, SQUARE, rvec, tvec)))
    return out


def _flat_checker(n=8, cell=20, stripes=False):
    """A flat image of an n x n checker (or of vertical stripes) of ``cell`` px squares, with a
    margin of one cell, and its inner corners ``(n - 1, n - 1, 2)``."""
    i, j = np.mgrid[0 : (n + 2) * cell, 0 : (n + 2) * cell] // cell
    inside = (i >= 1) & (i <= n) & (j >= 1) & (j <= n)
    dark = (j % 2 == 0) if stripes else ((i + j) % 2 == 0)
    img = np.where(inside & dark, 30, 220).astype(np.uint8)
    g = (np.arange(2, n + 1) * cell - 0.5).astype(np.float64)
    gx, gy = np.meshgrid(g, g)
    return img, np.stack([gx, gy], axis=2)


# -- the parity check --------------------------------------------------------------------------
def test_a_real_boards_corners_pass_the_checkerboard_parity_check(renders):
    img, truth = renders[0]
    gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    assert detect.check_grid(gray, truth.reshape(BOARD[1], BOARD[0], 2)) == ""
    flat, grid = _flat_checker()
    assert detect.check_grid(flat, grid) == ""


def test_a_grid_that_skips_a_row_of_squares_is_rejected_by_parity(renders):
    img, truth = renders[0]
    gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    grid = truth.reshape(BOARD[1], BOARD[0], 2)
    skipping = grid[[0, 1, 2, 4, 5, 6, 7, 8]]  # still regular, but one row of cells is two tall
    assert detect._grid_is_regular(skipping)
    assert "do not alternate" in detect.check_grid(gray, skipping)


def test_a_grid_shifted_by_half_a_square_is_rejected_by_parity(renders):
    img, truth = renders[1]
    gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    grid = truth.reshape(BOARD[1], BOARD[0], 2)
    half = 0.5 * (grid[:, :-1] + grid[:, 1:])  # every corner on the edge between two corners
    assert "do not alternate" in detect.check_grid(gray, half)


def test_a_grid_over_a_pattern_that_is_no_chessboard_is_rejected_by_parity():
    flat, grid = _flat_checker()
    stripes, _ = _flat_checker(stripes=True)  # the same corners over vertical stripes
    assert detect.check_grid(flat, grid) == ""
    assert "do not alternate" in detect.check_grid(stripes, grid)
    blank = np.full_like(flat, 128)
    assert "do not alternate" in detect.check_grid(blank, grid)


def test_border_cells_must_alternate_too_when_inside_the_image():
    flat, grid = _flat_checker()
    inner = grid[1:-1, 1:-1]  # a sub-board: its border ring is squares of the board
    assert detect.check_grid(flat, inner) == ""
    # the same corners over a checker whose ring of squares around them is painted grey
    painted = flat.copy()
    lo, hi = np.floor(grid[0, 0]).astype(int), np.ceil(grid[-1, -1]).astype(int)
    painted[: lo[1], :] = painted[hi[1] :, :] = painted[:, : lo[0]] = painted[:, hi[0] :] = 128
    assert detect.check_grid(painted, grid).startswith("the squares around its corners")


def test_a_folding_grid_is_rejected_before_parity():
    flat, grid = _flat_checker()
    folded = grid.copy()
    folded[3, 3] = grid[3, 5]
    assert detect.check_grid(flat, folded).startswith("it folds")


# -- the detectors on the raw image --------------------------------------------------------------
def test_a_sub_board_grid_that_skips_rows_is_listed_as_rejected_not_returned(renders):
    img, _ = renders[0]
    grids = detect.detect_grids(img, SUB, methods=("raw", "raw-sb"))
    assert grids and all(g.rejected for g in grids)  # OpenCV's SB grid skips rows of squares
    assert {g.method for g in grids} <= {"raw", "raw-sb"}
    assert detect.detect_pattern(img, SUB, methods=("raw", "raw-sb")) is None


def test_both_raw_detectors_are_tried_and_the_one_whose_grid_passes_is_kept(renders, monkeypatch):
    img, truth = renders[1]
    grid = truth.reshape(BOARD[1], BOARD[0], 2)
    half = 0.5 * (grid[:-1] + grid[1:])  # half a square off: 8 rows, and one more beyond
    half = np.concatenate([half, 2 * half[-1:] - half[-2:-1]]).astype(np.float32)

    def shifted(gray, size, flags=0):  # the classic detector returns that grid
        return True, half.reshape(-1, 1, 2).copy()

    monkeypatch.setattr(cv2, "findChessboardCorners", shifted)
    grids = detect.detect_grids(img, BOARD, methods=("raw", "raw-sb"))
    assert [g.method for g in grids] == ["raw", "raw-sb"]
    assert "do not alternate" in grids[0].rejected and not grids[1].rejected
    f, t = grids[1].corners.reshape(-1, 2), truth.reshape(-1, 2)
    assert min(np.abs(f - t).max(), np.abs(f[::-1] - t).max()) < 0.5


# -- the board's true size ---------------------------------------------------------------------
def test_board_size_in_names_the_whole_board_around_a_sub_board(renders):
    img, _ = renders[0]
    assert board_size.board_size_in(img, SUB) == BOARD
    assert board_size.board_size_in(img, BOARD) == BOARD
    assert omnicam.board_size_in is board_size.board_size_in


def test_board_size_in_finds_the_inner_corners_when_the_squares_are_given(renders):
    img, _ = renders[1]
    assert board_size.board_size_in(img, (BOARD[0] + 1, BOARD[1] + 1)) == BOARD


def test_board_size_in_gives_none_without_a_board():
    empty = boards.render_board(RIG, BOARD, SQUARE, None, None, supersample=1)
    assert board_size.board_size_in(empty, BOARD) is None


def test_the_size_to_give_keeps_the_orientation_of_the_size_given():
    assert board_size._oriented((11, 7), (7, 6)) == (7, 11)  # a side kept in place
    assert board_size._oriented((11, 7), (8, 12)) == (7, 11)  # the squares counted
    assert board_size._oriented((7, 11), (10, 6)) == (11, 7)  # containing the one given


# -- the policy of calibrate_pattern -------------------------------------------------------------
def test_calibrate_pattern_refuses_a_sub_board_size_naming_the_size_to_give(renders):
    images = [img for img, _ in renders]
    with pytest.raises(
        ValueError, match=r"has 7x9 inner corners, not 7x5: give pattern_size=\(7, 9\)"
    ):
        omnicam.calibrate_pattern(images, SUB, SQUARE, RIG.mirror, lens=None)


def test_squares_counted_are_refused_naming_the_inner_corners(renders):
    images = [img for img, _ in renders[:2]]  # (each failed search costs seconds)
    with pytest.raises(
        ValueError, match=r"give the inner corners, pattern_size=\(7, 9\), not the 8x10 squares"
    ):
        board_size.raw_boards(images, (8, 10))


def test_the_right_size_finds_every_board_with_no_warning(renders):
    images = [img for img, _ in renders]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        points, found_by = board_size.raw_boards(images, BOARD)
    assert all(p is not None for p in points) and set(found_by) <= {"raw", "raw-sb"}


def test_a_single_inconsistent_grid_is_dropped_with_a_warning_naming_the_image(
    renders, monkeypatch
):
    images = [img for img, _ in renders]
    real = board_size.detect_grids

    def one_bad(image, pattern_size, *args, **kwargs):
        found = real(image, pattern_size, *args, **kwargs)
        if image is images[1]:
            return [detect.PatternDetection(found[-1].corners, "raw-sb", "its cells do not …")]
        return found

    monkeypatch.setattr(board_size, "detect_grids", one_bad)
    with pytest.warns(RuntimeWarning, match=r"images\[1\]: no board on the raw image \(the grid"):
        points, found_by = board_size.raw_boards(images, BOARD)
    assert points[1] is None and found_by[1] is None
    assert points[0] is not None and points[2] is not None


def test_cli_names_the_option_and_the_file_for_a_sub_board_size(renders, tmp_path, capsys):
    from omnicam.cli import main

    paths = []
    for k, (img, _) in enumerate(renders):
        paths.append(str(tmp_path / f"board{k}.png"))
        cv2.imwrite(paths[-1], img)
    code = main(
        [
            "calibrate",
            "--chessboard",
            "7x5",
            "--square",
            "40",
            *paths,
            "-o",
            str(tmp_path / "r.yaml"),
        ]
    )
    err = capsys.readouterr().err
    assert code != 0
    assert "give --chessboard 7x9" in err and "board0.png" in err


def test_a_larger_board_in_a_minority_of_the_images_is_no_refusal(monkeypatch):
    sizes = iter([(7, 9), (7, 5), (7, 5), (7, 5)])
    monkeypatch.setattr(board_size, "board_size_in", lambda image, pattern_size: next(sizes))
    assert board_size._whole_board([None] * 4, SUB, [0, 1, 2, 3]) == (None, [])
    sizes = iter([(7, 9), (7, 5), (7, 9), (7, 9)])
    assert board_size._whole_board([None] * 4, SUB, [0, 1, 2, 3]) == ((7, 9), [0, 2, 3])


def test_the_refusal_names_the_size_to_give_for_a_sub_board_squares_or_another_board():
    msg = board_size.wrong_size_message((7, 11), (7, 6), [2, 4, 5])
    assert msg == (
        "the board in images[2] (and 2 more images) has 7x11 inner corners, not 7x6: give "
        "pattern_size=(7, 11)"
    )
    msg = board_size.wrong_size_message((7, 11), (8, 12), [0], grids_found=False)
    assert msg.endswith("give the inner corners, pattern_size=(7, 11), not the 8x12 squares")
    msg = board_size.wrong_size_message((11, 7), (9, 6), [0, 1], grids_found=False)
    assert msg == (
        "no board of 9x6 inner corners is found, but the board in images[0] (and 1 more image) "
        "has 11x7 inner corners: give pattern_size=(11, 7)"
    )
