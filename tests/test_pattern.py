"""calibrate_pattern: K, D and the posture from chessboard corners seen through the mirror."""

import math
import warnings

import cv2
import numpy as np
import pytest

import omnicam
from omnicam import MisalignedHyperbolicCamera, synthetic
from omnicam.chessboard.central import pinhole_D_from_unified, pinhole_K_from_unified
from omnicam.gauge import posture_error
from omnicam.synthetic import boards

PATTERN, SQUARE = (7, 5), 60.0
SIZE = (800, 800)


def _rig():
    """Tilted 3 deg, offset 3 mm, principal point off the image centre, fx != fy."""
    cam = synthetic.misaligned_rig(3.0, 30.0, (1.5, -2.0, 1.9), image_size=SIZE)
    K = cam.K.copy()
    K[0, 2] += 9.0
    K[1, 2] -= 6.0
    K[1, 1] *= 1.003
    return cam.replace(K=K)


RIG = _rig()
POSES = boards.random_board_poses(
    RIG, 10, PATTERN, SQUARE, distance=(300.0, 900.0), max_tilt_deg=50.0, rng=3
)


def _corners(noise=0.0, seed=0, poses=POSES):
    rng = np.random.default_rng(seed)
    pts = [boards.board_corners(RIG, PATTERN, SQUARE, *p) for p in poses]
    return [p + rng.normal(0.0, noise, p.shape) for p in pts]


def _rim(noise=0.0, seed=1):
    return RIG.rim_image_points(720) + np.random.default_rng(seed).normal(0.0, noise, (720, 2))


def _calibrate(image_points, rim=None, **kw):
    return omnicam.calibrate_pattern(
        None,
        PATTERN,
        SQUARE,
        RIG.mirror,
        image_size=SIZE,
        image_points=image_points,
        boundary_points=_rim() if rim is None else rim,
        **kw,
    )


@pytest.fixture(scope="module")
def exact():
    return _calibrate(_corners())


def test_exact_corners_give_K_posture_and_board_poses(exact):
    cam, report = exact
    f = RIG.K[0, 0]
    assert np.abs(cam.K - RIG.K).max() < 1e-6 * f
    assert np.abs(cam.D).max() < 1e-8  # the rig has no distortion; k1, k2 were free
    axis, origin = posture_error(cam, RIG)
    assert axis < 1e-6 and origin < 1e-6
    for i, (rvec, tvec) in enumerate(POSES):
        rb, tb = report.board_poses[i]
        assert np.abs(tb - tvec).max() < 1e-6 * np.linalg.norm(tvec)
        assert np.abs(rb - rvec).max() < 1e-8
    assert report.rms < 1e-6 and report.rim_rms < 1e-6
    # the start was far: K from the rim, the posture by Chen's method with that K
    assert posture_error(report.start, RIG)[0] > 1.0


def test_exact_result_is_in_the_gauge_and_reprojects_the_corners(exact):
    cam, report = exact
    assert abs(cam.rvec[2]) < 1e-15  # the smallest rotation from +z to the mirror axis
    for i, pts in enumerate(_corners()):
        assert np.abs(report.reprojected[i] - pts).max() < 1e-5


def test_noisy_corners_give_parameters_within_their_reported_uncertainty():
    cam, report = _calibrate(_corners(noise=0.2, seed=5), rim=_rim(0.1), dist_model="none")
    assert 0.2 < report.rms < 0.35  # sqrt(2) * 0.2 px: at the noise floor
    s = report.std
    for k, (i, j) in {"fx": (0, 0), "fy": (1, 1), "cx": (0, 2), "cy": (1, 2)}.items():
        assert abs(cam.K[i, j] - RIG.K[i, j]) < 4.0 * s[k], k
    axis, origin = posture_error(cam, RIG)
    assert axis < 4.0 * s["axis_deg"]
    assert origin < 4.0 * s["origin"]
    assert 0.0 < s["axis_deg"] < 1.0 and 0.0 < s["fx"] < 0.01 * RIG.K[0, 0]


def test_classmethod_builds_the_given_class():
    class Sub(MisalignedHyperbolicCamera):
        __slots__ = ()

    cam, _ = Sub.calibrate_pattern(
        None,
        PATTERN,
        SQUARE,
        RIG.mirror,
        image_size=SIZE,
        image_points=_corners()[:4],
        boundary_points=_rim(),
        dist_model="none",
    )
    assert type(cam) is Sub
    assert np.abs(cam.K - RIG.K).max() < 1e-5


def test_fewer_than_three_views_raise():
    pts = _corners()[:2] + [None]
    with (
        pytest.warns(RuntimeWarning, match="no board found"),
        pytest.raises(ValueError, match="at least 3"),
    ):
        _calibrate(pts)


def test_no_board_anywhere_raises():
    with pytest.raises(ValueError, match="pattern_size"):
        _calibrate([None, None, None])


def test_corner_count_that_does_not_match_pattern_size_raises():
    pts = _corners()[:4]
    pts[2] = pts[2][:-3]
    with pytest.raises(ValueError, match=r"image_points\[2\].*pattern_size"):
        _calibrate(pts)


def test_boards_seen_edge_on_raise():
    vp = np.array([0.0, 0.0, RIG.mirror.c])
    poses = []
    for az in (0.3, 2.0, 4.0):
        u = np.array([math.cos(az) * 0.9, math.sin(az) * 0.9, -0.43])
        u /= np.linalg.norm(u)
        x = u  # the board's x axis along the line of sight: its plane holds the viewpoint
        z = np.cross(u, [0.0, 0.0, 1.0])
        z /= np.linalg.norm(z)
        Rb = np.stack([x, np.cross(z, x), z], axis=1)
        rvec = cv2.Rodrigues(Rb)[0].ravel()
        poses.append((rvec, vp + 500.0 * u))
    pts = _corners(poses=poses)
    assert all(np.isfinite(p).all() for p in pts)
    with pytest.warns(RuntimeWarning, match="edge-on"), pytest.raises(ValueError, match="edge-on"):
        _calibrate(pts)


def test_a_view_with_bad_corners_is_dropped_with_a_warning():
    pts = _corners(noise=0.1, seed=2)
    pts[4] = pts[4] + np.random.default_rng(9).normal(0.0, 4.0, pts[4].shape)
    with pytest.warns(RuntimeWarning, match=r"view\(s\) \[4\]"):
        _, report = _calibrate(pts, rim=_rim(0.1), dist_model="none")
    assert 4 in report.dropped and 4 not in report.view_rms
    assert report.rms < 0.25
    assert any("[4]" in w for w in report.warnings)
    assert "dropped" in report.table()


def test_boards_all_on_one_side_are_warned_about():
    rng = np.random.default_rng(4)
    poses = [p for p in POSES if math.atan2(p[1][1], p[1][0]) > 0.0]
    if len(poses) < 3:  # make sure the case exists whatever the random poses
        poses = boards.random_board_poses(
            RIG, 12, PATTERN, SQUARE, distance=(300.0, 900.0), rng=rng
        )
        poses = [p for p in poses if math.atan2(p[1][1], p[1][0]) > 0.0]
    _, report = _calibrate(_corners(poses=poses), dist_model="none")
    assert any("one side" in w for w in report.warnings)


def test_bad_arguments_name_what_to_change():
    with pytest.raises(ValueError, match="pattern_size"):
        omnicam.calibrate_pattern(None, (1, 5), SQUARE, RIG.mirror, image_points=_corners())
    with pytest.raises(ValueError, match="square_size"):
        omnicam.calibrate_pattern(None, PATTERN, -1.0, RIG.mirror, image_points=_corners())
    with pytest.raises(ValueError, match="dist_model"):
        _calibrate(_corners(), dist_model="fisheye")
    with pytest.raises(ValueError, match="boundary_points"):
        omnicam.calibrate_pattern(
            None, PATTERN, SQUARE, RIG.mirror, image_points=_corners(), image_size=SIZE
        )


def test_the_camera_reflection_with_a_known_plane_pins_the_tilt_against_the_principal_point():
    from omnicam.calibration.reflection import outline_pixels

    pts = _corners(noise=0.2, seed=6)
    rng = np.random.default_rng(8)
    # the front edge of a lens barrel: a circle of radius 10 at 8 along the optical axis
    lens = outline_pixels(RIG, 10.0, 8.0, 120)[0]
    lens = lens[np.isfinite(lens).all(axis=1)]
    lens = lens + rng.normal(0.0, 0.1, lens.shape)
    _, without = _calibrate(pts, rim=_rim(0.1), dist_model="none", lens=None)
    # z unknown: the plane would trade against the tilt (tests/test_chessboard_hostile.py)
    with pytest.raises(ValueError, match="lens_z"):
        _calibrate(pts, rim=_rim(0.1), dist_model="none", lens=lens)
    cam, report = _calibrate(pts, rim=_rim(0.1), dist_model="none", lens=lens, lens_z=8.0)
    assert report.std["axis_deg"] < 0.5 * without.std["axis_deg"]
    assert report.std["cx"] < 0.5 * without.std["cx"]
    axis, _ = posture_error(cam, RIG)
    assert axis < 4.0 * report.std["axis_deg"]
    assert abs(cam.K[0, 2] - RIG.K[0, 2]) < 4.0 * report.std["cx"]
    assert report.lens_rms < 0.3 and report.lens_note.startswith("used")


def test_information_limit_at_the_truth_matches_the_reported_uncertainty_and_the_cues():
    from omnicam.calibration.reflection import outline_pixels
    from omnicam.chessboard.adjustment import pattern_uncertainty

    rim = RIG.rim_image_points(360)  # as many as the adjustment keeps
    lens = outline_pixels(RIG, 10.0, 8.0, 120)[0]
    lens = lens[np.isfinite(lens).all(axis=1)]

    def bound(**kw):
        return pattern_uncertainty(RIG, PATTERN, SQUARE, POSES, rim, 0.2, 0.2, **kw)

    none = bound(dist_model="none")
    # (rim noise as the corners' here; each group's own below)
    _, report = _calibrate(_corners(noise=0.2, seed=5), rim=_rim(0.2, 5), dist_model="none")
    for k in ("fx", "cx", "cy", "axis_deg", "origin"):
        assert 0.5 < report.std[k] / none[k] < 2.0, k
    # and so do the rays' (median and worst over the mirror's image)
    for got, bound_deg in zip(report.ray_std_deg, (none["ray_deg_median"], none["ray_deg_max"])):
        assert 0.5 < got / bound_deg < 2.0
    # each cue can only add information: a known plane more than a fitted one, and free
    # tangential distortion takes some away
    free = bound(dist_model="none", lens_points=lens, sigma_lens=0.1)
    known = bound(dist_model="none", lens_points=lens, lens_z=8.0, sigma_lens=0.1)
    assert known["cx"] < free["cx"] < none["cx"]
    assert known["axis_deg"] < free["axis_deg"] < none["axis_deg"]
    assert known["ray_deg_median"] < free["ray_deg_median"] < none["ray_deg_median"]
    assert "lens_z" in free and "lens_z" not in known
    assert bound(dist_model="k1k2p1p2")["cx"] > 2.0 * none["cx"]


def test_each_residual_group_gives_its_own_noise_to_the_stated_uncertainty():
    """The rim's points fit far better than the corners (0.05 against 0.3 px): the stated
    uncertainty takes each group's noise from its own residuals, so it meets the bound at the
    truth with the noise drawn for each (0.98 of it; one sigma pooled over both put it at
    0.80-0.83)."""
    from omnicam.chessboard.adjustment import pattern_uncertainty

    corners = _corners(noise=0.3, seed=7)
    drawn = np.std(np.concatenate(corners) - np.concatenate(_corners()))  # 0.280 px
    _, report = _calibrate(corners, rim=_rim(0.05, 7), dist_model="none")
    rim = RIG.rim_image_points(360)  # as many as the adjustment keeps
    bound = pattern_uncertainty(RIG, PATTERN, SQUARE, POSES, rim, drawn, 0.05, dist_model="none")
    # the fit weighs both groups alike, so it cannot beat the weighted bound; nor by far miss it
    for got, want in zip(report.ray_std_deg, (bound["ray_deg_median"], bound["ray_deg_max"])):
        assert 0.9 < got / want < 1.4, (got, want)
    for k in ("fx", "cx", "axis_deg"):
        assert 0.9 < report.std[k] / bound[k] < 1.4, k


def _shape_calibration(noise, seed, n_views):
    from omnicam.mirror import HyperbolicMirror

    m = RIG.mirror
    start = HyperbolicMirror(1.02 * m.a, 0.98 * m.b, m.rim_radius)  # 2 % off
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return omnicam.calibrate_pattern(
            None,
            PATTERN,
            SQUARE,
            start,
            image_size=SIZE,
            image_points=_corners(noise, seed)[:n_views],
            boundary_points=_rim(noise / 2),
            refine_mirror_shape=True,
            dist_model="none",
        )


def test_mirror_shape_is_recovered_from_exact_corners_started_off():
    cam, report = _shape_calibration(0.0, 0, 4)
    assert abs(cam.mirror.a / RIG.mirror.a - 1.0) < 1e-6
    assert abs(cam.mirror.b / RIG.mirror.b - 1.0) < 1e-6
    assert abs(cam.K[0, 0] / RIG.K[0, 0] - 1.0) < 1e-6
    assert posture_error(cam, RIG)[0] < 1e-5


def test_mirror_shape_from_noisy_corners_is_within_its_uncertainty_and_reported_as_weak():
    cam, report = _shape_calibration(0.2, 0, 5)
    for k in ("a", "b"):
        assert abs(getattr(cam.mirror, k) - getattr(RIG.mirror, k)) < 4.0 * report.std[k], k
    # at 0.2 px the shape is not determined (a, b trade against f and the axial distance)
    assert report.std["b"] > 0.01 * RIG.mirror.b
    assert any("NOT determined" in w for w in report.warnings)


def test_a_rim_that_leaves_corners_outside_is_named():
    centre = RIG.rim_image_points(720).mean(axis=0)
    small = centre + 0.5 * (RIG.rim_image_points(720) - centre)  # an inner edge, not the rim
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, report = _calibrate(_corners(), rim=small)
    assert any("lie outside the rim" in w for w in report.warnings)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, report = _calibrate(_corners())
    assert not any("outside the rim" in w for w in report.warnings)


def test_a_detected_rim_that_leaves_corners_outside_is_rejected_and_a_larger_one_taken(
    monkeypatch,
):
    from omnicam.calibration.rim import fit_rim
    from omnicam.chessboard import steps as pattern

    rim = RIG.rim_image_points(720)
    centre = rim.mean(axis=0)
    sizes = []

    def detect(image, expected=None, **kw):  # an inner edge first; the rim when asked larger
        sizes.append(expected)
        return fit_rim(rim if expected is not None else centre + 0.5 * (rim - centre))

    monkeypatch.setattr(pattern, "detect_rim", detect)
    images = [np.zeros((SIZE[1], SIZE[0], 3), np.uint8)] * len(POSES)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cam, report = omnicam.calibrate_pattern(
            images, PATTERN, SQUARE, RIG.mirror, image_points=_corners(), lens=None
        )
    assert sizes[0] is None and sizes[1][0] > 0.5 * np.ptp(rim[:, 0]) / 2
    assert any("leaves" in w and "rejected; the rim taken" in w for w in report.warnings)
    assert posture_error(cam, RIG)[0] < 1e-4


def _disc(centre, axes, angle_deg):
    """A bright mirror of elliptic outline on a dark holder, drawn by OpenCV (anti-aliased)."""
    image = np.full((480, 640), 50, np.uint8)
    box = (tuple(map(float, centre)), (2.0 * axes[0], 2.0 * axes[1]), float(angle_deg))
    cv2.ellipse(image, box, 190, -1, cv2.LINE_AA)
    return cv2.GaussianBlur(image, (0, 0), 1.0)


def test_the_rims_of_several_images_are_pooled():
    """A rigid rig shows one rim; each image's detection can be off by px (MiniOmni's single
    rims differ by up to 11 px in centre, their 2 % eccentricities pointing every way, which
    the adjustment took for a tilt). Four images whose outlines are a circle of radius 190 px
    moved 3 px and stretched 2 % each a different way: the rim is their pooled fit, the
    circle, not the first image's ellipse."""
    from omnicam.chessboard import steps as pattern

    truth = np.array([320.0, 240.0])
    images = []
    for k in range(4):
        shift = 3.0 * np.array([math.cos(0.5 * math.pi * k), math.sin(0.5 * math.pi * k)])
        images.append(_disc(truth + shift, (190.0 * 1.01, 190.0 * 0.99), 45.0 * k))
    greys = [pattern._grey_image(im, i) for i, im in enumerate(images)]
    first = pattern.detect_rim(greys[0].edges)
    assert np.linalg.norm(first.center - truth) > 2.5 and first.axes[0] / first.axes[1] > 1.015
    rim = pattern.rim_step(greys, None, (640, 480))
    assert rim.image == 0 and len(rim.seen) > 3 * len(first.points)
    assert np.linalg.norm(rim.fit.center - truth) < 0.3
    assert rim.fit.axes[0] / rim.fit.axes[1] < 1.002


def test_adjustment_jacobian_is_the_derivative_of_its_residuals():
    """Each column differenced where its parameter acts (K and D on the traced coordinates, the
    rim at its fixed foot points, the boards in groups) is the derivative of the residuals."""
    from omnicam.calibration.reflection import outline_pixels
    from omnicam.chessboard.adjustment import AdjustmentModel, BundleAdjustment
    from omnicam.chessboard.board_pose import object_points

    lens = outline_pixels(RIG, 10.0, 8.0, 40)[0]
    lens = lens[np.isfinite(lens).all(axis=1)]
    rng = np.random.default_rng(4)
    rim = _rim(0.5, 4)[::6]  # off the curve: distances that do not vanish
    model = AdjustmentModel((0, 1), 4, True, True, lens, None)
    views = [v.reshape(-1, 2) for v in _corners(0.3, 4, POSES[:3])]
    adj = BundleAdjustment(RIG, RIG.mirror, object_points(PATTERN, SQUARE), views, rim, model)
    boards_x = [np.concatenate([np.ravel(r), np.ravel(t)]) for r, t in POSES[:3]]
    x = np.concatenate([adj.x0_global, *boards_x])
    x[adj.names.index("k1")], x[adj.names.index("k2")] = -0.05, 0.01
    x[adj.names.index("w1")], x[adj.names.index("tz")] = 2e-3, x[adj.names.index("tz")] + 0.2
    x[adj.n_global :] += rng.normal(0.0, 1e-3, len(x) - adj.n_global)
    J = adj.jacobian(x)
    h = adj.steps(x)
    for k in range(len(x)):
        e = np.zeros(len(x))
        e[k] = h[k]
        fd = (adj.residuals(x + e) - adj.residuals(x - e)) / (2 * h[k])
        scale = max(np.abs(fd).max(), 1e-9)
        np.testing.assert_allclose(J[:, k], fd, rtol=0, atol=1e-5 * scale, err_msg=str(k))
    assert np.abs(J[2 * len(views[0]) * 3 :, adj.n_global :]).max() == 0  # boards: corners only


def test_a_solver_step_to_a_shape_no_mirror_has_costs_instead_of_raising():
    """With the shape free, a trial step of ln a, ln b out of HyperbolicMirror's range (the
    wide-angle hostile rig's fit took one to a = 6e6) is a large residual the solver rejects."""
    from omnicam.chessboard.adjustment import AdjustmentModel, BundleAdjustment
    from omnicam.chessboard.board_pose import object_points

    model = AdjustmentModel((0, 1), 4, False, True)
    views = [v.reshape(-1, 2) for v in _corners(0.0, 0, POSES[:3])]
    adj = BundleAdjustment(RIG, RIG.mirror, object_points(PATTERN, SQUARE), views, _rim(), model)
    x = np.concatenate(
        [adj.x0_global, *[np.concatenate([np.ravel(r), np.ravel(t)]) for r, t in POSES[:3]]]
    )
    good = adj.residuals(x)
    assert np.abs(good).max() < 1e-6
    x[adj.names.index("a")] = math.log(6e6)
    bad = adj.residuals(x)
    assert bad.shape == good.shape and np.all(bad == 50.0)


def test_outline_pixels_whose_rays_miss_the_lens_plane_cost_instead_of_fitting_perfectly():
    """The camera's reflection with its plane where no reflected ray reaches (a free ``z`` on
    an unknown-mirror render was moved there from a start behind the camera): every outline
    pixel costs as a corner the rig cannot see, not a residual of 0."""
    from omnicam.calibration.reflection import outline_pixels
    from omnicam.chessboard.adjustment import AdjustmentModel, BundleAdjustment
    from omnicam.chessboard.board_pose import object_points

    lens = outline_pixels(RIG, 10.0, 8.0, 40)[0]
    lens = lens[np.isfinite(lens).all(axis=1)]
    views = [v.reshape(-1, 2) for v in _corners(0.0, 0, POSES[:3])]
    x_boards = [np.concatenate([np.ravel(r), np.ravel(t)]) for r, t in POSES[:3]]
    for z, fits in ((8.0, True), (1e6, False)):
        model = AdjustmentModel((0, 1), 4, False, False, lens, z)
        adj = BundleAdjustment(
            RIG, RIG.mirror, object_points(PATTERN, SQUARE), views, _rim(), model
        )
        r = adj.lens_residuals(np.concatenate([adj.x0_global, *x_boards]))
        assert len(r) == len(lens)
        if fits:
            assert np.abs(r).max() < 1e-3
        else:
            assert np.all(r == 50.0)


def test_pinhole_distortion_behind_a_unified_models_is_the_same_image():
    """cv2.omnidir's unified model with radial ``D`` and the pinhole behind it (focal length
    ``/ sqrt(1 - xi^2)``, :func:`pinhole_D_from_unified`'s ``D``) map every point to the same
    pixel, each by OpenCV's own projection."""
    xi, D_u = 0.57, np.array([-0.16, 0.02, 0.0, 0.0])
    K_u = np.array([[140.0, 0.0, 640.0], [0.0, 139.0, 540.0], [0.0, 0.0, 1.0]])
    X = np.random.default_rng(4).normal([0.0, 0.0, 1.0], 0.6, (200, 3))
    X = X[X[:, 2] > 0.3]
    ref, _ = cv2.omnidir.projectPoints(
        X.reshape(1, -1, 3), np.zeros(3), np.zeros(3), K_u, xi, D_u.reshape(1, 4)
    )
    unified = X[:, :2] / (X[:, 2:] + xi * np.linalg.norm(X, axis=1, keepdims=True))
    s = math.sqrt(1.0 - xi * xi)  # the pinhole's normalised plane is the unified one's times s
    Xp = np.column_stack([s * unified, np.ones(len(unified))])
    K_p = pinhole_K_from_unified(K_u, xi)
    px, _ = cv2.projectPoints(Xp, np.zeros(3), np.zeros(3), K_p, pinhole_D_from_unified(D_u, xi))
    assert np.abs(px.reshape(-1, 2) - ref.reshape(-1, 2)).max() < 1e-9


def test_each_warning_policy_speaks_alone_of_its_own_finding():
    """The report's warning policies (chessboard/report_warnings.py) each read one fact: a
    fit that gives none of them is silent, and each finding wakes its own policy only."""
    from dataclasses import replace

    from omnicam.chessboard import report_warnings as rw

    around = np.array([[500.0, 0, 0], [-500.0, 0, 0], [0, 500.0, 0], [0, -500.0, 0]])
    quiet = rw.FitFacts(
        camera=RIG,
        std={"cx": 0.1, "cy": 0.1, "fx": 0.1, "a": 0.0, "b": 0.0},
        ray_deg=(0.01, 0.02),
        rms=0.1,
        n_views=10,
        board_centres=around,
        converged=True,
        solver_message="",
        held_shape=False,
        estimated_shape=False,
        central=None,
        image_size=SIZE,
    )
    assert [p(quiet) for p in rw.POLICIES] == [None] * len(rw.POLICIES)
    woken = {
        rw.few_views: replace(quiet, n_views=5),
        rw.one_sided: replace(quiet, board_centres=around[[0, 2]]),
        rw.principal_point_weak: replace(quiet, std={**quiet.std, "cx": 2.0}),
        rw.not_converged: replace(quiet, converged=False, solver_message="gave up"),
        rw.held_shape: replace(quiet, held_shape=True),
        rw.estimated_shape: replace(quiet, estimated_shape=True),
        rw.focal_length_weak: replace(quiet, std={**quiet.std, "fx": 0.02 * RIG.K[0, 0]}),
    }
    for policy, facts in woken.items():
        said = [p for p in rw.POLICIES if p(facts) is not None]
        assert said == [policy], (policy.__name__, [p.__name__ for p in said])
    assert rw.one_sided(woken[rw.one_sided]).startswith(rw.ONE_SIDED)
