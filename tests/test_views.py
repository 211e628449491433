"""Remap tables against the exact non-central projection, and the view conventions.

The reference is the camera's own exact projection (``project_directions`` / ``project``,
Newton on Fermat's path length) of the direction each output pixel looks along, with the
directions written here from docs/conventions.md ("Views"), independently of ``omnicam.views``.
"""

import math

import cv2
import numpy as np
import pytest

from omnicam import K_from_fov, MisalignedHyperbolicCamera, rotation_from_ypr, synthetic, views
from omnicam.views import api, grid

TOL = 0.01  # px, the accuracy every float table entry keeps

RIGS = {
    "aligned": synthetic.aligned_rig,
    "misaligned": synthetic.misaligned_rig,
    "distorted": lambda: synthetic.misaligned_rig(
        tilt_deg=4.0,
        tilt_azimuth_deg=-70.0,
        offset_mm=(-2.0, 1.0, -1.5),
        D=[-0.05, 0.01, 0.001, -0.0015, 0.002],
    ),
    "tilted_sensor": lambda: synthetic.misaligned_rig(
        D=[-0.03, 0.004, 0.0005, 0.0002, 0.0, 0.01, 0.0, 0.0, 0.001, 0.0, -0.001, 0.0, 0.01, -0.02]
    ),
}


@pytest.fixture(scope="module", params=sorted(RIGS))
def rig(request):
    return RIGS[request.param]()


# -- directions written from docs/conventions.md ------------------------------------------------
def forward_yaw(cam, R=None):
    """The default yaw: minus the azimuth of the camera's optical axis in the panorama frame,
    0 when it leans less than 1 deg from the panorama's up axis."""
    x, y, z = (np.eye(3) if R is None else R) @ cam.R[2]
    if math.degrees(math.atan2(math.hypot(x, y), z)) < 1.0:
        return 0.0
    return -math.degrees(math.atan2(y, x))


def panorama_dirs(size, lo, hi, projection, R=None, yaw=0.0):
    R = np.eye(3) if R is None else R
    w, h = size
    az = np.radians(-yaw - 360.0 * (np.arange(w) - (w - 1) / 2.0) / w)
    if projection == "cylindrical":
        tz = np.linspace(math.tan(math.radians(hi)), math.tan(math.radians(lo)), h)
        el = np.arctan(tz)
    else:
        el = np.radians(np.linspace(hi, lo, h))
    el, az = np.meshgrid(el, az, indexing="ij")
    d = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)
    return d @ R  # R^T d for row vectors


def perspective_dirs(K, size, R):
    w, h = size
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    d = np.stack([u, v, np.ones_like(u)], axis=-1) @ np.linalg.inv(K).T @ R
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def exact(cam, dirs, depth=None, viewpoint=None):
    d = dirs.reshape(-1, 3)
    if depth is None:
        xy = cam.project_directions(d)
    else:
        vp = cam.best_fit_viewpoint()[0] if viewpoint is None else np.asarray(viewpoint, float)
        xy = cam.project(vp + depth * d)
    return xy.reshape(dirs.shape[:-1] + (2,))


def rim_distance(cam, xy):
    """Distance of pixels to the image of the rim (a dense polyline of it)."""
    rim = cam.rim_image_points(20000)
    d = np.full(len(xy), np.inf)
    for i in range(0, len(xy), 256):
        chunk = xy[i : i + 256]
        d[i : i + 256] = np.min(np.linalg.norm(chunk[:, None, :] - rim[None], axis=2), axis=1)
    return d


def assert_matches_exact(cam, mapx, mapy, ref):
    """Every seen entry within TOL of the exact answer; unseen exactly where the exact model
    has NaN, except ties on the rim itself (within the rim polyline's resolution)."""
    got = np.stack([mapx, mapy], axis=-1).astype(np.float64)
    seen = ~((mapx == views.UNSEEN) & (mapy == views.UNSEEN))
    fin = np.isfinite(ref).all(axis=-1)
    both = seen & fin
    assert both.any()
    err = np.linalg.norm(got[both] - ref[both], axis=1)
    assert err.max() <= TOL, f"max error {err.max():.4g} px"
    only_table = seen & ~fin
    only_exact = fin & ~seen
    if only_table.any():
        assert rim_distance(cam, got[only_table]).max() < 0.1
    if only_exact.any():
        assert rim_distance(cam, ref[only_exact]).max() < 0.1
    assert only_table.sum() + only_exact.sum() <= max(4, 0.01 * both.sum())
    return err.max()


# -- accuracy ---------------------------------------------------------------------------------
@pytest.mark.parametrize("projection", ["cylindrical", "equirectangular"])
@pytest.mark.parametrize("depth", [None, 600.0])
@pytest.mark.parametrize("size", [(256, 64), (1024, 256)])
def test_panorama_table_within_tolerance_of_exact_projection(rig, projection, depth, size):
    mapx, mapy = rig.init_panorama_maps(
        size, projection=projection, m1type=cv2.CV_32FC1, depth=depth
    )
    lo, hi = views.visible_elevation_range(rig)
    lo = max(lo, views.CYLINDRICAL_MIN_ELEVATION)  # the default leaves out the camera itself
    ref = exact(rig, panorama_dirs(size, lo, hi, projection, yaw=forward_yaw(rig)), depth)
    assert_matches_exact(rig, mapx, mapy, ref)


@pytest.mark.parametrize("depth", [None, 600.0])
@pytest.mark.parametrize(
    "size, fov, ypr",
    [
        ((160, 120), 90.0, (0.0, 0.0, 0.0)),
        ((640, 480), 110.0, (25.0, -20.0, 10.0)),
        ((320, 240), 60.0, (-100.0, 8.0, -5.0)),
    ],
)
def test_perspective_table_within_tolerance_of_exact_projection(rig, depth, size, fov, ypr):
    K = K_from_fov(fov, size)
    R = rotation_from_ypr(*ypr)
    mapx, mapy = rig.init_perspective_maps(K, size, R=R, m1type=cv2.CV_32FC1, depth=depth)
    ref = exact(rig, perspective_dirs(K, size, R), depth)
    assert_matches_exact(rig, mapx, mapy, ref)


@pytest.mark.parametrize("ypr", [(0.0, 0.0, 0.0), (30.0, 20.0, 0.0), (-60.0, -10.0, 0.0)])
def test_views_across_the_edge_of_the_band_keep_the_bound(ypr):
    """Views that straddle the band (f = 400 at 1024x768), scaled to 320x240: the band's upper
    edge crosses the view, cells wholly above it are skipped, cells on it are refined."""
    cam = synthetic.misaligned_rig()
    size = (320, 240)
    K = np.array([[125.0, 0.0, 159.5], [0.0, 125.0, 119.5], [0.0, 0.0, 1.0]])
    R = rotation_from_ypr(*ypr)
    stats = np.zeros(9, np.int64)
    step = grid._step_for(math.degrees(1.0 / 125.0))
    mapx, mapy = grid._table(
        cam,
        grid.Directions(0, R.T @ np.linalg.inv(K)),
        size,
        None,
        None,
        cv2.CV_32FC1,
        step=step,
        stats=stats,
    )
    assert (mapx == views.UNSEEN).any() and (mapx != views.UNSEEN).any()
    assert stats[5] > 0  # cells on the edge were refined
    assert stats[8] == np.count_nonzero(mapx == views.UNSEEN)  # the unseen count of the warning
    assert_matches_exact(cam, mapx, mapy, exact(cam, perspective_dirs(K, size, R)))


def test_explicit_viewpoint_is_used_for_finite_depth():
    cam = synthetic.misaligned_rig()
    vp = np.array([1.0, -2.0, 30.0])
    K = K_from_fov(90.0, (160, 120))
    R = rotation_from_ypr(40.0, -30.0, 0.0)
    mapx, mapy = cam.init_perspective_maps(
        K, (160, 120), R=R, m1type=cv2.CV_32FC1, depth=80.0, viewpoint=vp
    )
    ref = exact(cam, perspective_dirs(K, (160, 120), R), 80.0, vp)
    assert_matches_exact(cam, mapx, mapy, ref)


def test_large_tables_are_interpolated_and_keep_the_bound():
    """The fast path (exact nodes, cubic cells, refined where needed) is what big tables use."""
    cam = synthetic.misaligned_rig()
    size = (1024, 256)
    lo, hi = views.visible_elevation_range(cam)
    p0, p1, az = api._panorama_params(size, lo, hi, "equirectangular")
    stats = np.zeros(9, np.int64)
    mapx, mapy = grid._table(
        cam, grid.Directions(2, np.eye(3), p0, p1, az), size, None, None, cv2.CV_32FC1, stats=stats
    )
    n_pixels = size[0] * size[1]
    assert stats[2] > 0  # cells interpolated from the nodes
    assert stats[0] + stats[1] < 0.1 * n_pixels  # exact solutions at nodes and check points
    assert stats[7] < 0.02 * n_pixels  # few pixels solved one by one
    # _table's own layout (no turn): column j at azimuth -360 j / W, the centre's yaw below
    ref = exact(cam, panorama_dirs(size, lo, hi, "equirectangular", yaw=180.0 * 1023 / 1024))
    assert_matches_exact(cam, mapx, mapy, ref)


# -- conventions ------------------------------------------------------------------------------
@pytest.mark.parametrize("W", [400, 401])
def test_panorama_column_looks_at_minus_yaw_turning_right_from_the_centre(W):
    """Column j looks at azimuth -yaw - 360 (j - (W - 1) / 2) / W: the centre at -yaw, a
    quarter turn right of it (-90 deg more) a quarter of the width further, the seam between
    the last column and the first."""
    cam = synthetic.misaligned_rig()
    yaw, H = 30.0, 51
    mapx, mapy = cam.init_panorama_maps(
        (W, H), (-50.0, 0.0), "equirectangular", m1type=cv2.CV_32FC1, yaw=yaw
    )
    for row, el in ((0, 0.0), (25, -25.0), (50, -50.0)):
        e = math.radians(el)
        for col in (0, W // 4, (W - 1) // 2, W // 2, 3 * W // 4, W - 1):
            az = math.radians(-yaw - 360.0 * (col - (W - 1) / 2.0) / W)
            d = (math.cos(e) * math.cos(az), math.cos(e) * math.sin(az), math.sin(e))
            ref = cam.project_directions(np.array([d]))[0]
            assert np.hypot(mapx[row, col] - ref[0], mapy[row, col] - ref[1]) < TOL


def test_panorama_turns_right_and_is_not_mirrored():
    """Aligned rig: the default centre is azimuth 0 (+X), image right of the image centre; a
    quarter of the width to the right, -90 deg (-Y), is image up."""
    cam = synthetic.aligned_rig()
    mapx, mapy = cam.init_panorama_maps(
        (401, 40), elevation_range=(-40.0, 0.0), m1type=cv2.CV_32FC1
    )
    cx, cy = cam.K[0, 2], cam.K[1, 2]
    assert mapx[20, 200] > cx + 50 and abs(mapy[20, 200] - cy) < 1
    assert mapy[20, 300] < cy - 50 and abs(mapx[20, 300] - cx) < 1


@pytest.mark.parametrize("projection", ["cylindrical", "equirectangular"])
def test_panorama_rows_from_hi_to_lo_with_the_projection_spacing(projection):
    cam = synthetic.misaligned_rig()
    lo, hi = -50.0, 10.0
    H = 41
    mapx, mapy = cam.init_panorama_maps(
        (65, H), elevation_range=(lo, hi), projection=projection, m1type=cv2.CV_32FC1, yaw=0.0
    )
    if projection == "cylindrical":
        mid = math.degrees(
            math.atan(0.5 * (math.tan(math.radians(lo)) + math.tan(math.radians(hi))))
        )
    else:
        mid = 0.5 * (lo + hi)
    for row, el in ((0, hi), (H // 2, mid), (H - 1, lo)):
        e = math.radians(el)
        ref = cam.project_directions(np.array([[math.cos(e), 0.0, math.sin(e)]]))[0]
        assert np.hypot(mapx[row, 32] - ref[0], mapy[row, 32] - ref[1]) < TOL  # azimuth 0


def test_panorama_R_rotates_the_panorama_frame():
    cam = synthetic.misaligned_rig()
    R = rotation_from_ypr(0.0, 0.0, 0.0) @ cv2.Rodrigues(np.array([0.1, -0.2, 0.3]))[0]
    size = (128, 32)
    with pytest.warns(RuntimeWarning, match="outside what the mirror sees"):  # tilted: 42 %
        mapx, mapy = cam.init_panorama_maps(
            size, elevation_range=(-60.0, 5.0), R=R, m1type=cv2.CV_32FC1
        )
    ref = exact(cam, panorama_dirs(size, -60.0, 5.0, "cylindrical", R, forward_yaw(cam, R)))
    assert_matches_exact(cam, mapx, mapy, ref)


def far_ahead_pixel(cam, yaw, el_deg, depth=1e7):
    """The pixel of a point ``depth`` away from the camera centre, at the panorama azimuth
    ``-yaw`` and elevation ``el_deg``."""
    az, el = math.radians(-yaw), math.radians(el_deg)
    d = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    return cam.project(np.asarray(cam.camera_center) + depth * d[None])[0]


def nearest_column(map1, row, pixel):
    return int(np.argmin(np.linalg.norm(map1[row].astype(np.float64) - pixel, axis=1)))


@pytest.mark.parametrize("rig_name", ["aligned", "misaligned", "distorted"])
@pytest.mark.parametrize("depth", [None, 5000.0])
def test_the_cameras_forward_lands_on_the_centre_column(rig_name, depth):
    """A point far straight ahead of the camera (the azimuth of its optical axis; +X for the
    aligned rig) is seen by the centre column of a default panorama: not cut by the seam."""
    cam = RIGS[rig_name]()
    x, y, _ = cam.R[2]
    expected = 0.0 if rig_name == "aligned" else -math.degrees(math.atan2(y, x))
    assert views.camera_forward_yaw(cam) == pytest.approx(expected, abs=1e-9)
    W, H = 361, 61  # centre column 180
    # row 30 halfway: elevation -20 deg, and tan(elevation) -0.4 for the cylindrical band
    for projection, band, el in (
        ("equirectangular", (-50.0, 10.0), -20.0),
        ("cylindrical", (math.degrees(math.atan(-0.8)), 0.0), math.degrees(math.atan(-0.4))),
    ):
        view = views.PanoramaView((W, H), band, projection, depth=depth)
        map1, _ = view.maps(cam, cv2.CV_32FC2)
        pixel = far_ahead_pixel(cam, expected, el)
        assert nearest_column(map1, 30, pixel) == 180
        if depth is None:  # directions: the entry is that pixel
            assert np.linalg.norm(map1[30, 180] - pixel) < TOL


@pytest.mark.parametrize("rig_name", ["aligned", "misaligned"])
def test_yaw_moves_the_forward_point_by_its_share_of_the_width(rig_name):
    """yaw = forward + 360 k / W puts what is ahead k columns left of the centre."""
    cam = RIGS[rig_name]()
    W, H = 361, 61
    forward = views.camera_forward_yaw(cam)
    pixel = far_ahead_pixel(cam, forward, -20.0)
    for k in (30, -75, 180):
        map1, _ = cam.init_panorama_maps(
            (W, H),
            (-50.0, 10.0),
            "equirectangular",
            m1type=cv2.CV_32FC2,
            yaw=forward + 360.0 * k / W,
        )
        col = nearest_column(map1, 30, pixel)
        assert col == (180 - k) % W
        assert np.linalg.norm(map1[30, col] - pixel) < TOL


def test_the_forward_direction_of_a_rig_leaning_less_than_a_degree_is_plus_X():
    """Below FORWARD_MIN_TILT_DEG the lean is no direction: yaw 0 (azimuth 0, +X)."""
    assert views.FORWARD_MIN_TILT_DEG == 1.0
    slight = synthetic.misaligned_rig(tilt_deg=0.9)
    assert views.camera_forward_yaw(slight) == 0.0
    leaning = synthetic.misaligned_rig(tilt_deg=1.1)
    x, y, _ = leaning.R[2]
    assert views.camera_forward_yaw(leaning) == pytest.approx(-math.degrees(math.atan2(y, x)))
    # in a panorama frame turned by R, the lean is measured there
    R = cv2.Rodrigues(np.array([0.0, 0.0, 0.5]))[0]
    x, y, _ = R @ leaning.R[2]
    assert views.camera_forward_yaw(leaning, R) == pytest.approx(-math.degrees(math.atan2(y, x)))


@pytest.mark.parametrize("yaw", ["a", float("nan"), float("inf"), 1j, [1.0], True])
def test_a_bad_yaw_is_refused_naming_it(yaw):
    with pytest.raises(ValueError, match="yaw must be None or a finite number of degrees"):
        views.PanoramaView((64, 16), yaw=yaw)
    with pytest.raises(ValueError, match="yaw must be"):
        synthetic.aligned_rig().init_panorama_maps((64, 16), yaw=yaw)


@pytest.mark.parametrize("size", [(160, 640), (99, 100)])
def test_a_panorama_taller_than_wide_is_refused_with_the_size_to_give(size):
    w, h = size
    msg = rf"size: .*{w}x{h} is taller than wide; give size=\({h}, {w}\)"
    with pytest.raises(ValueError, match=msg):
        views.PanoramaView(size)
    with pytest.raises(ValueError, match=msg):
        synthetic.aligned_rig().init_panorama_maps(size)
    views.PanoramaView((100, 100))  # square is fine


def test_default_elevation_range_is_the_band_the_mirror_sees():
    cam = synthetic.aligned_rig()
    m = cam.mirror
    # aligned: every rim ray passes through the outer focus (0, 0, c)
    hi = math.degrees(math.atan2(m.z_rim - m.c, m.rim_radius))
    lo, hi_got = views.visible_elevation_range(cam)
    assert lo == -90.0
    assert hi_got == pytest.approx(hi, abs=1e-9)
    lo_m, hi_m = views.visible_elevation_range(synthetic.misaligned_rig())
    assert lo_m == -90.0 and 10.0 < hi_m < 30.0
    # the highest seen row is seen somewhere, and nothing above hi is seen
    mapx, _ = cam.init_panorama_maps((360, 90), projection="equirectangular", m1type=cv2.CV_32FC1)
    assert (mapx[1] != views.UNSEEN).all()
    assert (mapx[-1] != views.UNSEEN).all()


def test_rotation_from_ypr_signs():
    R0 = np.array([[0, -1, 0], [0, 0, -1], [1, 0, 0]], dtype=float)
    np.testing.assert_allclose(rotation_from_ypr(0, 0, 0), R0, atol=1e-15)
    np.testing.assert_allclose(views.R0, R0)
    # yaw 90: optical axis at azimuth -90 (towards -Y), turning right
    np.testing.assert_allclose(rotation_from_ypr(90, 0, 0)[2], [0, -1, 0], atol=1e-12)
    # pitch 30: looking up
    f = rotation_from_ypr(0, 30, 0)[2]
    assert math.degrees(math.asin(f[2])) == pytest.approx(30.0)
    # image-up (-y row) stays as close to +Z as possible: image-right is horizontal
    R = rotation_from_ypr(37, -25, 0)
    assert abs(R[0, 2]) < 1e-12 and -R[1, 2] > 0
    # roll clockwise: image-right tilts towards image-down (-Z), optical axis unchanged
    Rr = rotation_from_ypr(0, 0, 10)
    np.testing.assert_allclose(Rr[2], R0[2], atol=1e-12)
    assert Rr[0, 2] < 0
    for ypr in ((10, 20, 30), (-170, 89, -45), (0, -90, 0)):
        R = rotation_from_ypr(*ypr)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)


def test_default_R_is_R0_and_looks_at_azimuth_zero():
    cam = synthetic.misaligned_rig()
    size = (161, 121)
    K = K_from_fov(90.0, size)
    mapx, mapy = cam.init_perspective_maps(K, size, m1type=cv2.CV_32FC1)
    centre = cam.project_directions(np.array([[1.0, 0.0, 0.0]]))[0]
    assert np.hypot(mapx[60, 80] - centre[0], mapy[60, 80] - centre[1]) < TOL
    # the right edge at 45 deg looks towards -Y (right turn), the top edge up
    right = cam.project_directions(np.array([[1.0, -80.0 / K[0, 0], 0.0]]))[0]
    assert np.hypot(mapx[60, 160] - right[0], mapy[60, 160] - right[1]) < TOL


def test_K_from_fov_is_horizontal_with_centred_principal_point():
    K = K_from_fov(90.0, (640, 480))
    assert K[0, 2] == 319.5 and K[1, 2] == 239.5 and K[0, 0] == K[1, 1]
    # the left edge of the image (u = -0.5) is 45 deg off the axis
    assert math.degrees(math.atan((K[0, 2] + 0.5) / K[0, 0])) == pytest.approx(45.0)


def test_aligned_baseline_differs_from_calibrated_on_a_misaligned_rig():
    """Paper Fig. 7: the uncalibrated model (eqs. 2-5) warps a misaligned rig's panorama."""
    cam = synthetic.misaligned_rig()
    base = MisalignedHyperbolicCamera.aligned(cam.mirror, cam.K[0, 0], cam.K[0, 2], cam.K[1, 2])
    kw = dict(elevation_range=(-60.0, 5.0), m1type=cv2.CV_32FC1, yaw=0.0)
    a = np.stack(cam.init_panorama_maps((256, 64), **kw), axis=-1)
    b = np.stack(base.init_panorama_maps((256, 64), **kw), axis=-1)
    ok = (a != views.UNSEEN).all(-1) & (b != views.UNSEEN).all(-1)
    assert np.linalg.norm(a - b, axis=-1)[ok].max() > 5.0


@pytest.mark.parametrize("rig_name", ["misaligned", "distorted"])
def test_rim_cells_give_the_entries_of_edge_cells(rig_name):
    """A RIM sub-cell (every visibility test but the rim's clearly passed) decides its pixels by
    the rim margin alone (``_rim_pixel``); where the other tests pass, that is the entry the
    full per-pixel test of an EDGE sub-cell (``_edge_pixel``) gives: unseen past the rim's
    margin, undecided within it, the same pixel inside it."""
    from omnicam._kernels import fill as k

    cam = RIGS[rig_name]()
    m = cam.mirror
    view = grid._view_args(cam, 0, np.eye(3), 0.0, 0.0, 0.0, None, None)
    rig = grid._rig_args(cam)
    rng = np.random.default_rng(5)
    radius = m.rim_radius * np.concatenate(
        [rng.uniform(0.05, 1.05, 300), 1.0 + rng.uniform(-2e-3, 2e-3, 100)]
    )
    azimuth = rng.uniform(0.0, 2.0 * np.pi, radius.size)
    s = np.stack([radius * np.cos(azimuth), radius * np.sin(azimuth)], axis=1)
    P = np.column_stack([s, m.surface_z(s[:, 0], s[:, 1])])
    V = P - np.asarray(cam.camera_center)
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    d = m.reflect(V, m.unit_normal(P))  # the direction whose reflection point is s
    verdicts = set()
    for (s1, s2), (dx, dy, dz) in zip(s, d):
        rim = k._rim_pixel(rig, s1, s2)
        edge = k._edge_pixel(view, rig, s1, s2, dx, dy, dz)
        assert rim[2] == edge[2]
        np.testing.assert_array_equal(rim[:2], edge[:2])
        verdicts.add((rim[2], bool(np.isfinite(rim[0]))))
    assert verdicts == {(True, True), (True, False), (False, False)}  # seen, unseen, undecided


# -- m1type variants and unseen entries -------------------------------------------------------
@pytest.mark.parametrize("kind", ["panorama", "perspective"])
def test_m1type_variants_agree(kind):
    cam = synthetic.misaligned_rig()
    if kind == "panorama":
        make = lambda t: cam.init_panorama_maps((300, 80), m1type=t)
    else:
        K = K_from_fov(100.0, (200, 150))
        make = lambda t: cam.init_perspective_maps(
            K, (200, 150), R=rotation_from_ypr(5, 10, 0), m1type=t
        )
    fx, fy = make(cv2.CV_32FC1)
    assert fx.dtype == np.float32 and fx.shape == (fx.shape[0], fx.shape[1])
    xy, none = make(cv2.CV_32FC2)
    assert none is None and xy.dtype == np.float32 and xy.shape == fx.shape + (2,)
    np.testing.assert_array_equal(xy[..., 0], fx)
    np.testing.assert_array_equal(xy[..., 1], fy)
    m1, m2 = make(cv2.CV_16SC2)
    assert m1.dtype == np.int16 and m1.shape == fx.shape + (2,)
    assert m2.dtype == np.uint16 and m2.shape == fx.shape
    ref1, ref2 = cv2.convertMaps(fx, fy, cv2.CV_16SC2)
    np.testing.assert_array_equal(m1, ref1)
    np.testing.assert_array_equal(m2, ref2)
    back_x = m1[..., 0] + (m2 & 31) / 32.0
    back_y = m1[..., 1] + (m2 >> 5) / 32.0
    assert np.abs(back_x - fx).max() <= 1 / 64 + 1e-6
    assert np.abs(back_y - fy).max() <= 1 / 64 + 1e-6


def test_fixed_point_rounding_is_rint_of_32x_with_ties_to_even():
    """The vectorised fixed point of SEEN cells (1.5 * 2^52 trick) is cvRound(x * 32) as
    np.rint gives it, ties to even included, and saturates beyond its clamp."""
    from omnicam._kernels.fill import _round_fixed

    ties = np.arange(-200, 200) / 64.0  # x * 32 = k / 2: every other one a tie
    rng = np.random.default_rng(1)
    values = np.concatenate([ties, rng.uniform(-5000.0, 5000.0, 2000), [0.0, -0.0, -10.0]])
    for f in values.astype(np.float32):
        assert _round_fixed(f) == int(np.rint(np.float64(f) * 32.0)), f
    for f in (np.float32(1e20), np.float32(-1e20)):
        r = _round_fixed(f)
        assert r % 32 == 0 and abs(r) >> 5 > 32767


def test_default_m1type_is_fixed_point():
    cam = synthetic.aligned_rig()
    m1, m2 = cam.init_panorama_maps((64, 16))
    assert m1.dtype == np.int16 and m2.dtype == np.uint16


def test_unseen_directions_map_outside_and_remap_to_the_border():
    cam = synthetic.misaligned_rig()
    size = (120, 90)
    K = K_from_fov(60.0, size)
    up = rotation_from_ypr(0.0, 85.0, 0.0)  # looking at the zenith: nothing is seen
    for m1type in (cv2.CV_32FC1, cv2.CV_32FC2, cv2.CV_16SC2):
        with pytest.warns(RuntimeWarning, match="visible_elevation_range"):
            m1, m2 = cam.init_perspective_maps(K, size, R=up, m1type=m1type)
        img = np.full((500, 500, 3), 200, np.uint8)
        out = cv2.remap(
            img, m1, m2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=(7, 7, 7)
        )
        assert (out == 7).all()
    with pytest.warns(RuntimeWarning, match="100% of its pixels"):
        mapx, mapy = cam.init_perspective_maps(K, size, R=up, m1type=cv2.CV_32FC1)
    assert (mapx == views.UNSEEN).all() and (mapy == views.UNSEEN).all()
    assert views.UNSEEN <= -2.0 and views.UNSEEN > -32768 / 32
    # a horizontal view sees the lower half and not the top rows
    mapx, mapy = cam.init_perspective_maps(K, size, m1type=cv2.CV_32FC1)
    assert (mapx[0] == views.UNSEEN).all() and (mapx[-1] != views.UNSEEN).all()


# -- bad input --------------------------------------------------------------------------------
@pytest.mark.parametrize("size", [(0, 10), (10,), "ab", (10.5, 3), (10, -1), None, (10, 1)])
def test_panorama_bad_size_raises(size):
    with pytest.raises(ValueError, match="size"):
        synthetic.aligned_rig().init_panorama_maps(size)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(projection="spherical"), "projection"),
        (dict(projection=None), "projection"),
        (dict(m1type=cv2.CV_8UC1), "m1type"),
        (dict(m1type=5.0), "m1type"),
        (dict(m1type=True), "m1type"),
        (dict(elevation_range=(10.0, 10.0)), "elevation_range"),
        (dict(elevation_range=(20.0, -10.0)), "elevation_range"),
        (dict(elevation_range=(-95.0, 10.0)), "elevation_range"),
        (dict(elevation_range=(-10.0, 91.0)), "elevation_range"),
        (dict(elevation_range=(-90.0, 10.0)), "elevation_range"),  # cylindrical: tan(-90)
        (dict(elevation_range=(float("nan"), 10.0)), "elevation_range"),
        (dict(elevation_range=(1.0, 2.0, 3.0)), "elevation_range"),
        (dict(R=np.eye(2)), "R"),
        (dict(R=2 * np.eye(3)), "R"),
        (dict(depth=0.0), "depth"),
        (dict(depth=-5.0), "depth"),
        (dict(depth="far"), "depth"),
        (dict(depth=100.0, viewpoint=(1.0, 2.0)), "viewpoint"),
    ],
)
def test_panorama_bad_arguments_raise_naming_them(kwargs, name):
    with pytest.raises(ValueError, match=name):
        synthetic.aligned_rig().init_panorama_maps((64, 16), **kwargs)


@pytest.mark.parametrize(
    "K_new",
    [
        np.zeros((3, 3)),
        np.diag([0.0, 100.0, 1.0]),
        np.eye(2),
        [[100, 0, 50], [0, 100, 50], [0, 0, 2]],
        np.full((3, 3), np.nan),
    ],
)
def test_perspective_bad_K_new_raises(K_new):
    with pytest.raises(ValueError, match="K_new"):
        synthetic.aligned_rig().init_perspective_maps(K_new, (64, 48))


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(size=(0, 48)), "size"),
        (dict(m1type=cv2.CV_16UC1), "m1type"),
        (dict(R=np.diag([1.0, 1.0, -1.0])), "R"),
    ],
)
def test_perspective_bad_arguments_raise_naming_them(kwargs, name):
    args = dict(size=(64, 48))
    args.update(kwargs)
    with pytest.raises(ValueError, match=name):
        synthetic.aligned_rig().init_perspective_maps(K_from_fov(90.0, (64, 48)), **args)


def test_equirectangular_accepts_the_poles():
    cam = synthetic.aligned_rig()
    mapx, mapy = cam.init_panorama_maps(
        (64, 33), elevation_range=(-90.0, 0.0), projection="equirectangular", m1type=cv2.CV_32FC1
    )
    nadir = cam.project_directions(np.array([[0.0, 0.0, -1.0]]))[0]
    assert np.abs(mapx[-1] - nadir[0]).max() < TOL and np.abs(mapy[-1] - nadir[1]).max() < TOL


@pytest.mark.parametrize("bad", [(float("inf"), 0, 0), ("a", 0, 0)])
def test_rotation_from_ypr_bad_input(bad):
    with pytest.raises(ValueError, match="yaw"):
        rotation_from_ypr(*bad)


@pytest.mark.parametrize("fov", [0.0, 180.0, -10.0, "wide"])
def test_K_from_fov_bad_input(fov):
    with pytest.raises(ValueError, match="fov"):
        K_from_fov(fov, (64, 48))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_random_rigs_keep_the_bound(seed):
    """Random 5-DOF misalignments (up to 5 deg, 5 mm), random views and depths."""
    rng = np.random.default_rng(seed)
    cam = synthetic.random_misaligned_rig(rng, max_tilt_deg=5.0, max_offset_mm=5.0)
    depth = None if seed % 2 else float(rng.uniform(200.0, 3000.0))
    size = (768, 192)
    lo, hi = views.visible_elevation_range(cam)  # the whole band, the nadir included
    mapx, mapy = cam.init_panorama_maps(
        size, (lo, hi), projection="equirectangular", m1type=cv2.CV_32FC1, depth=depth
    )
    assert_matches_exact(
        cam,
        mapx,
        mapy,
        exact(cam, panorama_dirs(size, lo, hi, "equirectangular", yaw=forward_yaw(cam)), depth),
    )
    size = (400, 300)
    K = K_from_fov(rng.uniform(40.0, 140.0), size)
    R = rotation_from_ypr(rng.uniform(-180, 180), rng.uniform(-80, 10), rng.uniform(-30, 30))
    mapx, mapy = cam.init_perspective_maps(K, size, R=R, m1type=cv2.CV_32FC1, depth=depth)
    assert_matches_exact(cam, mapx, mapy, exact(cam, perspective_dirs(K, size, R), depth))


@pytest.mark.parametrize(
    "build, advice",
    [
        (
            lambda cam: cam.init_panorama_maps(
                (64, 32), elevation_range=(-60.0, 80.0), projection="equirectangular"
            ),
            "narrow",
        ),
        (
            lambda cam: cam.init_perspective_maps(
                views.K_from_fov(60, (64, 48)), (64, 48), R=rotation_from_ypr(pitch=70.0)
            ),
            "pitch it into that band",
        ),
    ],
    ids=["panorama a third black", "perspective view above the band"],
)
def test_a_view_much_outside_the_band_gets_a_note_with_the_way_back(build, advice):
    with pytest.warns(RuntimeWarning, match=advice):
        build(synthetic.misaligned_rig())


# -- the default lower edge: the camera's own reflection as detected (issue 18 item 6) ----------
R_BODY, Z_BODY = 22.0, 50.0  # a wide lens barrel close to the mirror: it shows up to -45 deg


def true_body_top(truth, r=R_BODY, z=Z_BODY):
    """The highest elevation of the true outline (by bisection, calibration.reflection)."""
    from omnicam.calibration.reflection import outline_pixels

    _, V = truth.unproject(outline_pixels(truth, r, z, 720)[0])
    return float(np.degrees(np.arctan2(V[:, 2], np.hypot(V[:, 0], V[:, 1]))).max())


@pytest.fixture(scope="module")
def body_rig():
    """A render with a known lens barrel (tests/barrel.py, traced against the solid itself),
    calibrated from the image alone with the true K and mirror."""
    from barrel import render

    truth = synthetic.random_misaligned_rig(np.random.default_rng(5), 5.0, 5.0)
    image = render(truth, r=R_BODY, z=Z_BODY, box=None)
    cam, report = MisalignedHyperbolicCamera.calibrate(truth.K, truth.mirror, image=image)
    return truth, cam, report


def test_the_calibration_records_the_camera_reflection_it_detected(body_rig):
    """The recorded circle's outline lies on the true one within the fit's own scatter."""
    from omnicam.calibration.reflection import outline_pixels, plane_radius

    truth, cam, report = body_rig
    assert report.lens_used and cam.camera_reflection is not None, report.lens_note
    assert cam.camera_reflection == (report.lens_r, report.lens_z)
    out, _ = outline_pixels(cam, *cam.camera_reflection, 180)
    Ki = np.linalg.inv(truth.K)
    xn = out @ Ki[:2, :2].T + Ki[:2, 2]
    rho, g = plane_radius(truth.mirror, truth.R, truth.tvec, xn, Z_BODY, Ki[:2, :2])
    off = (rho - R_BODY) / g  # px from the true outline
    assert np.abs(off).max() < max(0.2, 3.0 * report.lens_rms), (off, report.lens_rms)


@pytest.mark.parametrize(
    "projection, depth", [("cylindrical", None), ("equirectangular", None), ("cylindrical", 600.0)]
)
def test_the_default_panorama_leaves_out_the_camera_reflection_as_detected(
    body_rig, projection, depth
):
    """No entry of the default panorama sees the barrel (each entry's source pixel traced in
    the true rig against the solid), and the lower edge lies at most a few rows above the
    true outline's top (of 96 rows)."""
    from barrel import hits

    truth, cam, _ = body_rig
    size = (256, 96)
    band = views.default_elevation_range(cam, projection, depth=depth)
    assert band.lower_edge == views.LOWER_EDGE_REFLECTION and band.lo > -60.0
    assert "the camera's reflection as detected" in band.describe()
    map1, _ = cam.init_panorama_maps(size, projection=projection, m1type=cv2.CV_32FC2, depth=depth)
    src = map1.reshape(-1, 2).astype(np.float64)
    src = src[src[:, 0] != views.UNSEEN]
    assert len(src) > 0.9 * size[0] * size[1]
    assert not np.isfinite(hits(truth, src, R_BODY, Z_BODY)).any()
    top = true_body_top(truth)
    if projection == "cylindrical":
        step = (math.tan(math.radians(band.hi)) - math.tan(math.radians(band.lo))) / (size[1] - 1)
        rows = (math.tan(math.radians(band.lo)) - math.tan(math.radians(top))) / step
    else:
        rows = (band.lo - top) / ((band.hi - band.lo) / (size[1] - 1))
    assert 0.0 < rows <= 5.0, rows
    below = cam.init_panorama_maps(
        size, (band.lo - 3.0, band.hi), projection, m1type=cv2.CV_32FC2, depth=depth
    )[0].reshape(-1, 2)
    below = below[below[:, 0] != views.UNSEEN].astype(np.float64)
    assert np.isfinite(hits(truth, below, R_BODY, Z_BODY)).any()  # 3 deg lower: the barrel


def test_an_explicit_elevation_range_wins_over_the_camera_reflection(body_rig):
    _, cam, _ = body_rig
    bare = cam.replace(camera_reflection=None)
    for band in ((-80.0, 10.0), (-20.0, 5.0)):
        with_body = cam.init_panorama_maps((128, 32), band)
        without = bare.init_panorama_maps((128, 32), band)
        assert all(np.array_equal(a, b) for a, b in zip(with_body, without))
    assert not np.array_equal(
        cam.init_panorama_maps((128, 32))[0], bare.init_panorama_maps((128, 32))[0]
    )
    assert views.PanoramaView((128, 32), (-80.0, 10.0)).default_range(cam) is None


def test_without_a_camera_reflection_the_default_starts_at_minus_60():
    cam = synthetic.misaligned_rig()
    assert cam.camera_reflection is None and views.camera_reflection_elevation(cam) is None
    lo, hi = views.visible_elevation_range(cam)
    for projection in views.PROJECTIONS:
        band = views.default_elevation_range(cam, projection)
        assert (band.lo, band.hi) == (-60.0, min(hi, 89.0) if projection == "cylindrical" else hi)
        assert band.lower_edge == views.LOWER_EDGE_FIXED
        default = cam.init_panorama_maps((128, 32), projection=projection)
        given = cam.init_panorama_maps((128, 32), (band.lo, band.hi), projection)
        assert all(np.array_equal(a, b) for a, b in zip(default, given))


def test_a_camera_reflection_below_minus_60_leaves_a_cylindrical_panorama_at_minus_60():
    """A small barrel (radius 9 at 12 mm) shows only below -75 deg: an equirectangular panorama
    goes down to it; a cylindrical one stops at -60 deg, its rows stretching as tan(el)."""
    cam = synthetic.misaligned_rig().replace(camera_reflection=(9.0, 12.0))
    top = true_body_top(cam, 9.0, 12.0)
    cyl = views.default_elevation_range(cam, "cylindrical")
    assert (cyl.lo, cyl.lower_edge) == (-60.0, views.LOWER_EDGE_FLOOR) and top < -75.0
    equi = views.default_elevation_range(cam, "equirectangular")
    assert equi.lower_edge == views.LOWER_EDGE_REFLECTION and top < equi.lo < top + 3.0


def test_the_camera_reflection_elevation_is_that_of_its_exact_outline(body_rig):
    """Without a margin, the outline's highest elevation as outline_pixels (bisection) gives
    it; with one, a little higher; at a great depth, close to the direction's."""
    truth = body_rig[0].replace(camera_reflection=(R_BODY, Z_BODY))
    top = true_body_top(truth)
    assert views.camera_reflection_elevation(truth, margin_px=0.0) == pytest.approx(top, abs=0.01)
    with_margin = views.camera_reflection_elevation(truth)
    assert top < with_margin < top + 2.0
    far = views.camera_reflection_elevation(truth, depth=1e7)
    assert far == pytest.approx(with_margin, abs=1e-3)
    near = views.camera_reflection_elevation(truth, depth=600.0)
    assert near != far and abs(near - far) < 2.0
    with pytest.raises(ValueError, match="margin_px"):
        views.camera_reflection_elevation(truth, margin_px=-1.0)
    with pytest.raises(ValueError, match="n must be"):
        views.camera_reflection_elevation(truth, n=2)
