"""calibrate_intrinsics: OpenCV chessboard calibration of the camera alone (K, D of eq. 24)."""

import cv2
import numpy as np
import pytest

from omnicam import calibrate_intrinsics
from omnicam.chessboard.intrinsics import find_chessboard

K_TRUE = np.array([[820.0, 0.0, 331.5], [0.0, 815.0, 236.0], [0.0, 0.0, 1.0]])
SIZE = (640, 480)
PATTERN = (9, 6)  # inner corners
SQUARE = 25.0  # mm
SS = 4  # supersampling of the renders


def _board_texture(px=40, margin=40):
    """Chessboard of (9+1) x (6+1) squares, ``px`` texture pixels each, with a white margin."""
    cols, rows = PATTERN[0] + 1, PATTERN[1] + 1
    tex = np.full((rows * px + 2 * margin, cols * px + 2 * margin), 255, np.uint8)
    for r in range(rows):
        for c in range(cols):
            if (r + c) % 2 == 0:
                y, x = margin + r * px, margin + c * px
                tex[y : y + px, x : x + px] = 0
    # texture pixel (u, v) centre <-> board point ((u + 0.5 - margin - px) / px * SQUARE, ...):
    # the first inner corner is the board origin
    T = np.array(
        [
            [SQUARE / px, 0, (0.5 - margin - px) * SQUARE / px],
            [0, SQUARE / px, (0.5 - margin - px) * SQUARE / px],
            [0, 0, 1.0],
        ]
    )
    return tex, T


def _render_views(n=10, D=None, seed=0, with_corners=False):
    """Images of the board seen by the pinhole ``K_TRUE`` (and distortion ``D``) from ``n``
    known poses: homography ``K [r1 r2 t]`` of the supersampled board, area-averaged.
    With ``with_corners`` also the true pixels of the inner corners, (n, N, 2)."""
    rng = np.random.default_rng(seed)
    tex, T = _board_texture()
    A = np.array([[SS, 0, (SS - 1) / 2], [0, SS, (SS - 1) / 2], [0, 0, 1.0]])  # px -> subpx
    images, corners = [], []
    grid = np.zeros((PATTERN[0] * PATTERN[1], 3))
    grid[:, :2] = np.mgrid[0 : PATTERN[0], 0 : PATTERN[1]].T.reshape(-1, 2) * SQUARE
    for i in range(n):
        rvec = np.deg2rad(rng.uniform(-30, 30, 3)) * np.array([1, 1, 0.3])
        R = cv2.Rodrigues(rvec)[0]
        centre = np.array([4.0 * SQUARE, 2.5 * SQUARE, 0.0])  # middle of the inner corners
        # the board's middle over a 3x3 grid of image positions, so the views cover the frame
        target = np.array([(0.3 + 0.2 * (i % 3)) * SIZE[0], (0.3 + 0.2 * (i // 3 % 3)) * SIZE[1]])
        z = rng.uniform(560, 700)
        t = -R @ centre + z * np.linalg.solve(K_TRUE, np.r_[target + rng.uniform(-15, 15, 2), 1])
        H = K_TRUE @ np.c_[R[:, 0], R[:, 1], t] @ T
        big = cv2.warpPerspective(
            tex, A @ H, (SIZE[0] * SS, SIZE[1] * SS), flags=cv2.INTER_LINEAR, borderValue=128
        )
        img = cv2.resize(big, SIZE, interpolation=cv2.INTER_AREA)
        if D is not None:
            # each distorted pixel shows the ideal pixel it comes from
            xs, ys = np.meshgrid(
                np.arange(SIZE[0], dtype=np.float64), np.arange(SIZE[1], dtype=np.float64)
            )
            pts = np.stack([xs.ravel(), ys.ravel()], 1).reshape(-1, 1, 2)
            und = cv2.undistortPoints(
                pts,
                K_TRUE,
                np.asarray(D, float),
                R=None,
                P=K_TRUE,
                criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12),
            ).reshape(SIZE[1], SIZE[0], 2)
            img = cv2.remap(
                img,
                und[..., 0].astype(np.float32),
                und[..., 1].astype(np.float32),
                cv2.INTER_LINEAR,
                borderValue=128,
            )
        images.append(img)
        corners.append(cv2.projectPoints(grid, rvec, t, K_TRUE, D)[0].reshape(-1, 2))
    return (images, np.array(corners)) if with_corners else images


def _model_error(K, D, true_corners):
    """How well the calibrated (K, D) explains the *true* corner pixels of every view: the
    largest reprojection error after fitting each view's pose (``cv2.solvePnP``), px. This
    judges K and D together (k1, k2, k3 and the principal point trade off against each other
    and the poses)."""
    grid = np.zeros((PATTERN[0] * PATTERN[1], 3))
    grid[:, :2] = np.mgrid[0 : PATTERN[0], 0 : PATTERN[1]].T.reshape(-1, 2) * SQUARE
    worst = 0.0
    for c in true_corners:
        ok, rvec, tvec = cv2.solvePnP(grid, c, K, D)
        assert ok
        rvec, tvec = cv2.solvePnPRefineLM(grid, c, K, D, rvec, tvec)
        proj = cv2.projectPoints(grid, rvec, tvec, K, D)[0].reshape(-1, 2)
        worst = max(worst, float(np.linalg.norm(proj - c, axis=1).max()))
    return worst


def test_calibrate_intrinsics_recovers_known_pinhole():
    images, true_corners = _render_views(10, with_corners=True)
    rms, K, D = calibrate_intrinsics(images, PATTERN, SQUARE)
    assert rms < 0.1
    assert K.shape == (3, 3) and K.dtype == np.float64
    np.testing.assert_allclose(np.diag(K)[:2], np.diag(K_TRUE)[:2], rtol=0.005)
    np.testing.assert_allclose(K[:2, 2], K_TRUE[:2, 2], atol=1.5)
    assert D.shape == (5,)
    assert _model_error(K, D, true_corners) < 0.1


def test_calibrate_intrinsics_recovers_radial_distortion_bgr_and_paths(tmp_path):
    D_true = np.array([-0.12, 0.05, 0.0, 0.0, 0.0])
    images, true_corners = _render_views(10, D=D_true, seed=1, with_corners=True)
    images = [cv2.cvtColor(im, cv2.COLOR_GRAY2BGR) for im in images]
    paths = []
    for i, im in enumerate(images[:5]):
        paths.append(tmp_path / f"view{i}.png")
        cv2.imwrite(str(paths[-1]), im)
    rms, K, D = calibrate_intrinsics(paths + images[5:], PATTERN, SQUARE)
    assert rms < 0.15
    np.testing.assert_allclose(np.diag(K)[:2], np.diag(K_TRUE)[:2], rtol=0.005)
    np.testing.assert_allclose(K[:2, 2], K_TRUE[:2, 2], atol=1.5)
    assert D[0] < -0.05  # barrel distortion found
    assert _model_error(K, D, true_corners) < 0.1


def test_calibrate_intrinsics_uint16_and_float_images():
    images = _render_views(6, seed=2)
    mixed = [
        im.astype(np.uint16) * 257 if i % 2 else im.astype(np.float32) / 255
        for i, im in enumerate(images)
    ]
    rms, K, _ = calibrate_intrinsics(mixed, PATTERN, SQUARE)
    assert rms < 0.1
    np.testing.assert_allclose(np.diag(K)[:2], np.diag(K_TRUE)[:2], rtol=0.01)


def test_calibrate_intrinsics_accepts_a_stack_and_reports_a_single_image():
    views = _render_views(4, seed=3)
    rms, K, _ = calibrate_intrinsics(np.stack(views), PATTERN, SQUARE)
    assert rms < 0.1 and abs(K[0, 0] / K_TRUE[0, 0] - 1) < 0.02
    with pytest.raises(ValueError, match="found in 1 of 1 images, need at least 3"):
        calibrate_intrinsics(views[0], PATTERN, SQUARE)


def test_find_chessboard_subpixel_corners_match_projection():
    tex, T = _board_texture()
    R = cv2.Rodrigues(np.deg2rad([10.0, -15.0, 5.0]))[0]
    t = -R @ np.array([100.0, 62.5, 0.0]) + np.array([0.0, 0.0, 500.0])
    A = np.array([[SS, 0, (SS - 1) / 2], [0, SS, (SS - 1) / 2], [0, 0, 1.0]])
    H = K_TRUE @ np.c_[R[:, 0], R[:, 1], t] @ T
    big = cv2.warpPerspective(tex, A @ H, (SIZE[0] * SS, SIZE[1] * SS), borderValue=128)
    img = cv2.resize(big, SIZE, interpolation=cv2.INTER_AREA)
    corners = find_chessboard(img, PATTERN).reshape(-1, 2)
    grid = np.mgrid[0 : PATTERN[0], 0 : PATTERN[1]].T.reshape(-1, 2) * SQUARE
    proj = cv2.perspectiveTransform(
        grid.reshape(-1, 1, 2).astype(np.float64), K_TRUE @ np.c_[R[:, 0], R[:, 1], t]
    ).reshape(-1, 2)
    # OpenCV may start the ordering at either end of the board
    err = min(np.abs(corners - proj).max(), np.abs(corners[::-1] - proj).max())
    assert err < 0.1


@pytest.mark.parametrize(
    "images, pattern, square, match",
    [
        ([], PATTERN, SQUARE, "no images"),
        ([np.full((480, 640), 128, np.uint8)] * 4, PATTERN, SQUARE, "found in 0 of 4"),
        (None, (6, 9, 1), SQUARE, "pattern_size"),
        (None, (1, 9), SQUARE, "pattern_size"),
        (None, PATTERN, 0.0, "square_size"),
        (None, PATTERN, float("nan"), "square_size"),
        ([np.zeros((480, 640, 2), np.uint8)], PATTERN, SQUARE, "shape"),
        ([object()], PATTERN, SQUARE, "image array"),
    ],
)
def test_calibrate_intrinsics_bad_input_raises_value_error(images, pattern, square, match):
    if images is None:
        images = [np.zeros((480, 640), np.uint8)]
    with pytest.raises(ValueError, match=match):
        calibrate_intrinsics(images, pattern, square)


def test_calibrate_intrinsics_names_a_missing_image_file():
    with pytest.raises(FileNotFoundError, match=r"images\[0\] /nonexistent/board.png does not"):
        calibrate_intrinsics(["/nonexistent/board.png"], PATTERN, SQUARE)


def test_calibrate_intrinsics_board_in_too_few_images():
    views = _render_views(2) + [np.full((480, 640), 128, np.uint8)] * 3
    with pytest.raises(ValueError, match="found in 2 of 5 images, need at least 3"):
        calibrate_intrinsics(views, PATTERN, SQUARE)


def test_calibrate_intrinsics_images_of_different_sizes():
    views = _render_views(3)
    views[1] = cv2.resize(views[1], (320, 240))
    with pytest.raises(ValueError, match="different|same camera"):
        calibrate_intrinsics(views, PATTERN, SQUARE)
