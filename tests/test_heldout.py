"""The held-out check: what a chessboard calibration predicts on views it did not fit."""

import warnings

import cv2
import numpy as np
import pytest

import omnicam
from omnicam import synthetic
from omnicam.chessboard import heldout
from omnicam.chessboard.board_pose import object_points
from omnicam.synthetic import boards

PATTERN, SQUARE = (7, 5), 60.0
SIZE = (800, 800)
RIG = synthetic.misaligned_rig(3.0, 30.0, (1.5, -2.0, 1.9), image_size=SIZE)
POSES = boards.random_board_poses(
    RIG, 9, PATTERN, SQUARE, distance=(250.0, 1200.0), max_tilt_deg=50.0, rng=7
)
OBJ = object_points(PATTERN, SQUARE)
CORNERS = {i: boards.board_corners(RIG, PATTERN, SQUARE, *p) for i, p in enumerate(POSES)}


def test_folds_split_the_views_once_each():
    folds = heldout.fold_of(7, 3)
    assert folds == [[0, 3, 6], [1, 4], [2, 5]]
    assert sorted(sum(folds, [])) == list(range(7))


def test_the_true_camera_predicts_every_view_exactly():
    project, directions = heldout.omnicam_predictor(RIG)
    for i in (0, 4, 8):
        assert heldout.heldout_rms(project, directions, CORNERS[i], OBJ) < 1e-6


def test_the_unified_model_predicts_its_own_projections_exactly():
    K = np.array([[300.0, 0.0, 400.0], [0.0, 310.0, 390.0], [0.0, 0.0, 1.0]])
    xi, D = 0.9, np.array([[-0.05, 0.01, 1e-3, -5e-4]])
    rng = np.random.default_rng(0)
    views = []
    for _ in range(6):
        rvec = rng.normal(0.0, 0.3, 3)
        tvec = np.r_[rng.uniform(-150, 150, 2), rng.uniform(350, 500)]
        q, _ = cv2.omnidir.projectPoints(OBJ.reshape(-1, 1, 3), rvec, tvec, K, xi, D)
        views.append(q.reshape(-1, 2))
    project, directions = heldout.unified_predictor(K, xi, D)
    for v in views:
        assert heldout.heldout_rms(project, directions, v, OBJ) < 1e-6
    # and cv2.omnidir.calibrate fitted to them predicts them to a small fraction of a pixel
    project, directions = heldout.omnidir_predictor(views, OBJ, SIZE)
    assert heldout.heldout_rms(project, directions, views[2], OBJ) < 0.2


def test_pixels_past_the_unified_models_horizon_have_no_direction_and_raise_no_warning():
    """With ``xi > 1`` no point of the sphere projects beyond ``r^2 = 1 / (xi^2 - 1)``: NaN
    there, as the NaN rules say, not numpy's "invalid value" warning."""
    K = np.array([[100.0, 0.0, 200.0], [0.0, 100.0, 200.0], [0.0, 0.0, 1.0]])
    _, directions = heldout.unified_predictor(K, 1.5, np.zeros(4))
    px = np.array([[200.0, 200.0], [200.0 + 100.0 * 0.8, 200.0], [200.0 + 100.0 * 0.9, 200.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        d = directions(px)[1]
    assert np.isfinite(d[:2]).all() and np.isnan(d[2]).all()  # horizon at r = 0.894


def test_cross_validation_of_the_truth_is_exact_and_omnidir_errs_on_a_misaligned_rig():
    held = heldout.cross_validate(lambda train: RIG, CORNERS, OBJ, SIZE, k=3)
    assert held.folds == 3 and sorted(held.rms) == sorted(CORNERS)
    assert held.max < 1e-6
    # a central model cannot place boards at every depth on a misaligned rig
    assert np.median(list(held.omnidir.values())) > 0.05
    assert "held-out corner RMS (3-fold" in held.summary() and "cv2.omnidir" in held.summary()


def test_too_few_views_for_the_folds_raise():
    few = {i: CORNERS[i] for i in range(3)}
    with pytest.raises(ValueError, match="3 training views"):
        heldout.cross_validate(lambda train: RIG, few, OBJ, SIZE, k=3)


def test_calibrate_pattern_reports_its_heldout_check_better_than_omnidir_here():
    rim = RIG.rim_image_points(720)
    cam, report = omnicam.calibrate_pattern(
        None,
        PATTERN,
        SQUARE,
        RIG.mirror,
        image_size=SIZE,
        image_points=[CORNERS[i] for i in range(len(POSES))],
        boundary_points=rim,
        heldout=3,
    )
    assert sorted(report.heldout.rms) == sorted(report.view_rms)
    assert report.heldout.max < 1e-3  # exact corners: every held-out view predicted
    assert report.heldout.max < min(report.heldout.omnidir.values())


def test_a_fold_that_cannot_be_calibrated_is_reported_not_fatal():
    def fit(train):
        if 0 not in train:
            raise ValueError("only 2 usable views")
        return RIG

    held = heldout.cross_validate(fit, CORNERS, OBJ, SIZE, k=3)
    assert sorted(held.failed) == [0, 3, 6] and held.failed[0] == "only 2 usable views"
    assert sorted(held.rms) == [1, 2, 4, 5, 7, 8] and held.max < 1e-6
    assert "3 view(s) not predicted" in held.summary()
