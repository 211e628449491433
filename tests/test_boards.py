"""Board renders (omnicam.synthetic.boards) by the independent tracer of synthetic.realistic."""

import numpy as np

from omnicam import synthetic
from omnicam.calibration.reflection import detect_reflection, outline_pixels
from omnicam.calibration.rim import detect_rim
from omnicam.synthetic import boards
from omnicam.synthetic import realistic as rl

PATTERN, SQUARE = (7, 5), 60.0
SIZE = (500, 500)
RIG = synthetic.misaligned_rig(3.0, 30.0, (1.5, -2.0, 1.9), image_size=SIZE)
POSES = boards.random_board_poses(
    RIG, 3, PATTERN, SQUARE, distance=(300.0, 900.0), max_tilt_deg=50.0, rng=2
)


def test_independent_tracer_rays_of_the_truth_corners_pass_through_the_corners():
    obj = boards.board_object_points(PATTERN, SQUARE)
    for rvec, tvec in POSES:
        px = boards.board_corners(RIG, PATTERN, SQUARE, rvec, tvec).reshape(-1, 2)
        labels, _, P, d = rl.trace(RIG, px, rl.Rig(body=boards.BOARD_BODY))
        assert (labels == rl.LABELS["scene"]).all()  # nothing of the body in the way
        X = boards._to_mirror(obj, rvec, tvec)
        w = X - P
        miss = np.linalg.norm(w - d * np.einsum("ij,ij->i", w, d)[:, None], axis=1)
        assert miss.max() < 1e-6  # mm, at 300-900 mm


def test_board_render_shows_the_board_at_its_corners_and_the_checker_around_them():
    rvec, tvec = POSES[0]
    board = rl.Chessboard(PATTERN, SQUARE, tuple(rvec), tuple(tvec))
    px = boards.board_corners(RIG, PATTERN, SQUARE, rvec, tvec).reshape(-1, 2)
    labels, *_ = rl.trace(RIG, px, rl.Rig(body=boards.BOARD_BODY, boards=(board,)))
    assert (labels == rl.LABELS["board"]).all()
    img = boards.render_board(RIG, PATTERN, SQUARE, rvec, tvec, supersample=2, photometric=None)
    grey = img.mean(axis=2)
    # around an inner corner the four squares alternate black and white
    c = np.round(px[PATTERN[0] + 1]).astype(int)
    g = boards.board_corners(RIG, PATTERN, SQUARE, rvec, tvec).reshape(PATTERN[1], PATTERN[0], 2)
    u = g[1, 2] - g[1, 1]
    v = g[2, 1] - g[1, 1]
    quads = [np.round(c + 0.3 * (su * u + sv * v)).astype(int) for su in (-1, 1) for sv in (-1, 1)]
    vals = np.array([grey[q[1], q[0]] for q in quads])
    assert abs(vals[0] - vals[3]) < 40 and abs(vals[1] - vals[2]) < 40
    assert abs(vals[0] - vals[1]) > 120


def test_scene_render_shows_the_barrel_whose_reflection_outline_is_detected():
    scene = boards.render_board(RIG, PATTERN, SQUARE, None, None, supersample=2)
    rim = detect_rim(scene)
    found = np.asarray(detect_reflection(scene, rim).points, np.float64)
    body = boards.BOARD_BODY
    truth = outline_pixels(RIG, body.r_barrel, body.z_barrel, 2000)[0]
    truth = truth[np.isfinite(truth).all(axis=1)]
    dist = np.min(np.linalg.norm(found[:, None, :] - truth[None], axis=2), axis=1)
    assert len(found) >= 30
    assert np.median(dist) < 0.3


def test_poses_avoid_the_camera_body():
    for rvec, tvec in POSES:
        pts = RIG.project(boards._to_mirror(boards.board_outline(PATTERN, SQUARE, 16), rvec, tvec))
        labels, *_ = rl.trace(RIG, pts, rl.Rig(body=boards.BOARD_BODY))
        assert (labels == rl.LABELS["scene"]).all()


def test_reflection_outline_pooled_over_images_leaves_out_one_that_disagrees():
    from omnicam.chessboard.calibrate import pooled_reflection

    imgs = [
        boards.render_board(RIG, PATTERN, SQUARE, None, None, supersample=2, seed=s) for s in (1, 2)
    ]
    rim = detect_rim(imgs[0])
    one = detect_reflection(imgs[0], rim)
    # a third image whose reflection sits 3 px off (its surroundings moved): detected, but
    # away from the others'
    odd = imgs[1].copy()
    x, y = (int(v) for v in np.round(one.center))
    h = int(2 * one.radius)
    odd[y - h : y + h, x - h + 3 : x + h + 3] = imgs[1][y - h : y + h, x - h : x + h]
    assert np.linalg.norm(detect_reflection(odd, rim).center - one.center - (3, 0)) < 0.5
    pts, note = pooled_reflection([*imgs, odd], 0, rim)
    assert note.startswith("used:") and " in 2 of 3 image(s)" in note
    assert len(pts) == len(one.points) + len(detect_reflection(imgs[1], rim).points)
