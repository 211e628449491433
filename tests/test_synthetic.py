"""The synthetic renderer (paper Fig. 6): housing, camera reflection, subpixel-true edges."""

import cv2
import numpy as np
import pytest

from omnicam import synthetic
from omnicam.calibration.chen import rim_conic

SMALL = (200, 200)


@pytest.fixture(scope="module")
def rigs():
    return {
        "aligned": synthetic.aligned_rig(SMALL),
        "misaligned": synthetic.misaligned_rig(image_size=SMALL),
    }


@pytest.fixture(scope="module")
def environment():
    return synthetic.make_environment((1024, 512))


def _step_environment(size=(2048, 1024), row=620):
    """Black above ``row``, white below: the 50 % level at elevation of row + 1/2."""
    w, h = size
    env = np.zeros((h, w, 3), np.uint8)
    env[row + 1 :] = 255
    return env, 90.0 - 180.0 * (row + 0.5) / (h - 1)


def _directions(az_deg, el_deg):
    az, el = np.deg2rad(az_deg), np.deg2rad(el_deg)
    return np.stack(
        np.broadcast_arrays(np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)), axis=-1
    )


def test_equirect_coords_invert_equirect_directions():
    size = (64, 33)
    d = synthetic.equirect_directions(size)
    x, y = synthetic.equirect_coords(d, size)
    gx, gy = np.meshgrid(np.arange(64.0), np.arange(33.0))
    inner = slice(1, -1)  # the pole rows have no azimuth
    assert np.allclose(x[inner], gx[inner], atol=1e-9)
    assert np.allclose(y, gy, atol=1e-9)


def test_equirect_azimuth_follows_panorama_convention():
    # column x looks at azimuth -360 x / W: +Y (azimuth 90) is at column 3/4 W
    x, y = synthetic.equirect_coords(np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 1.0]]), (400, 201))
    assert np.allclose(x, [300.0, 0.0]) and np.allclose(y, [100.0, 50.0])


@pytest.mark.parametrize("name", ["aligned", "misaligned"])
def test_housing_is_dark_exactly_outside_rim_ellipse(rigs, environment, name):
    cam = rigs[name]
    img = synthetic.render_environment(cam, environment, supersample=2)
    Q = rim_conic(cam.K, cam.R, cam.tvec, cam.mirror)
    gx, gy = np.meshgrid(np.arange(SMALL[0], dtype=float), np.arange(SMALL[1], dtype=float))
    p = np.stack([gx, gy, np.ones_like(gx)], axis=-1)
    Qp = p @ Q
    dist = np.einsum("...i,...i", Qp, p) / (2 * np.hypot(Qp[..., 0], Qp[..., 1]))  # signed px
    housing = (img == synthetic.HOUSING_COLOR).all(axis=-1)
    assert housing[dist > 0.75].all()
    ring = (dist < -0.75) & (dist > -5)  # just inside the rim: the bright sky
    assert ring.sum() > 100 and not housing[ring].any()
    assert np.median(img[ring]) > 150  # (poles and a line cross it too)


def test_background_replaces_housing_outside_the_rim_only(rigs, environment):
    cam = rigs["misaligned"]
    rng = np.random.default_rng(3)
    clutter = rng.integers(0, 256, (SMALL[1], SMALL[0], 3), dtype=np.uint8)
    plain = synthetic.render_environment(cam, environment, supersample=2)
    img = synthetic.render_environment(cam, environment, supersample=2, background=clutter)
    housing = (plain == synthetic.HOUSING_COLOR).all(axis=-1)
    assert np.array_equal(img[housing], clutter[housing])
    inside = synthetic.render_environment(
        cam, environment, supersample=2, housing_color=(200, 0, 200)
    )
    mirror = ~housing & (inside == plain).all(axis=-1)  # no housing share: untouched
    assert mirror.sum() > 0.5 * SMALL[0] * SMALL[1]
    assert np.array_equal(img[mirror], plain[mirror])
    with pytest.raises(ValueError, match="background"):
        synthetic.render_environment(cam, environment, background=clutter[:, :100])


def test_distorted_rig_housing_follows_the_distorted_rim(environment):
    cam = synthetic.misaligned_rig(image_size=SMALL, D=[-0.12, 0.05, 0.001, -0.0015, -0.01])
    img = synthetic.render_environment(cam, environment, supersample=2)
    rim = cam.rim_image_points(2000).astype(np.float32)
    housing = (img == synthetic.HOUSING_COLOR).all(axis=-1)
    for y in range(SMALL[1]):
        for x in range(0, SMALL[0], 3):
            dist = cv2.pointPolygonTest(rim, (float(x), float(y)), True)  # > 0 inside
            if dist < -0.75:
                assert housing[y, x], (x, y)
            elif dist > 0.75:
                assert not housing[y, x], (x, y)


@pytest.mark.parametrize("name", ["aligned", "misaligned"])
def test_environment_colour_appears_at_projected_direction(rigs, name):
    # a checker cell centre of the procedural environment, far from its edges
    cam = rigs[name]
    env = synthetic.make_environment((1024, 512), line_elevations_deg=())
    img = synthetic.render_environment(cam, env, supersample=2)
    for az, el in [(-37.5, -35.0), (97.5, -15.0), (172.5, -55.0), (-127.5, -25.0)]:
        px = cam.project_directions(_directions(az, el)[None])[0]
        x, y = synthetic.equirect_coords(_directions(az, el), (1024, 512))
        expected = env[int(round(float(y))), int(round(float(x)))]
        got = img[int(round(px[1])), int(round(px[0]))]
        assert np.abs(got.astype(int) - expected).max() <= 1, (az, el)


@pytest.mark.parametrize("name", ["aligned", "misaligned"])
def test_edges_are_subpixel_true(rigs, name):
    # white below an elevation: the white area equals the area inside the projected boundary
    cam = rigs[name]
    env, el = _step_environment()
    img = synthetic.render_environment(
        cam, env, supersample=4, housing_color=(0, 0, 0), body_radius=None
    )
    p = cam.project_directions(_directions(np.linspace(0, 360, 3600, endpoint=False), el))
    x, y = p.T
    area = 0.5 * abs(x @ np.roll(y, -1) - y @ np.roll(x, -1))
    perimeter = np.linalg.norm(p - np.roll(p, 1, axis=0), axis=1).sum()
    mean_offset = (img[..., 1].sum() / 255.0 - area) / perimeter
    assert abs(mean_offset) < 0.01


def test_camera_reflection_is_dark_at_the_centre(rigs, environment):
    cam = rigs["aligned"]
    img = synthetic.render_environment(cam, environment, supersample=2)
    # the nadir comes back to the camera: the lens, darker than the housing and the scene
    c = np.round(cam.project_directions(np.array([[0.0, 0.0, -1.0]]))[0]).astype(int)
    assert img[c[1], c[0]].max() < 15
    without = synthetic.render_environment(cam, environment, supersample=2, body_radius=None)
    assert without[c[1], c[0]].max() > 40


def test_aligned_and_misaligned_renders_differ(rigs, environment):
    a = synthetic.render_environment(rigs["aligned"], environment, supersample=1)
    b = synthetic.render_environment(rigs["misaligned"], environment, supersample=1)
    assert a.shape == b.shape == (SMALL[1], SMALL[0], 3) and a.dtype == np.uint8
    assert (np.abs(a.astype(int) - b).max(axis=-1) > 30).mean() > 0.05


def test_render_size_is_width_by_height(environment):
    cam = synthetic.misaligned_rig(image_size=(160, 120))
    img = synthetic.render_environment(cam, environment, supersample=1)
    assert img.shape == (120, 160, 3)
    assert synthetic.render_room(cam, supersample=1).shape == (120, 160, 3)


def test_noise_is_deterministic_with_seed(rigs, environment):
    cam = rigs["misaligned"]
    clean = synthetic.render_environment(cam, environment, supersample=1)
    assert np.array_equal(clean, synthetic.render_environment(cam, environment, supersample=1))
    a = synthetic.render_environment(cam, environment, supersample=1, noise=3.0, seed=7)
    b = synthetic.render_environment(cam, environment, supersample=1, noise=3.0, seed=7)
    c = synthetic.render_environment(cam, environment, supersample=1, noise=3.0, seed=8)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert 2.0 < np.std(a.astype(float) - clean) < 4.0


def test_room_cube_faces_and_normals():
    room = synthetic.Room()
    faces = room.cube_faces()
    n = room.face_normals()
    for f, normal in zip(faces, n):
        assert np.allclose(np.cross(f[1] - f[0], f[2] - f[1]) / room.cube_size**2, normal)
        assert np.allclose(np.linalg.norm(f - np.roll(f, 1, axis=0), axis=1), room.cube_size)
    viewpoint = synthetic.aligned_rig().best_fit_viewpoint()[0]
    assert list(room.visible_faces(viewpoint)) == [1, 2, 4]
    assert 1400 < np.linalg.norm(np.asarray(room.cube_center) - viewpoint) < 1600


@pytest.mark.parametrize("name", ["aligned", "misaligned"])
def test_cube_faces_appear_where_they_project(name):
    cam = synthetic.aligned_rig((500, 500)) if name == "aligned" else synthetic.misaligned_rig()
    room = synthetic.Room()
    img = synthetic.render_room(cam, room, supersample=2)
    colours = np.asarray(room.cube_colors)
    any_face = np.zeros((500, 500), bool)
    for i in room.visible_faces(cam.best_fit_viewpoint()[0]):
        # dense points along the face's edges: the image of a straight edge is curved
        f = room.cube_faces()[i]
        t = np.linspace(0, 1, 50, endpoint=False)[:, None]
        outline = np.concatenate([f[k] + t * (f[(k + 1) % 4] - f[k]) for k in range(4)])
        poly = cam.project(outline).astype(np.float32)
        dist = _polygon_distance(poly, (500, 500))
        inside = dist > 0.75
        assert inside.sum() > 20
        assert (img[inside] == colours[i]).all()
        any_face |= dist > -0.75
    # away from the faces no pixel has a face colour of the visible faces
    outside = ~any_face
    for i in room.visible_faces(cam.best_fit_viewpoint()[0]):
        assert not (img[outside] == colours[i]).all(axis=-1).any()


def _polygon_distance(poly, shape):
    """Signed distance (positive inside) of pixel centres to a polygon, near its bounding box."""
    out = np.full(shape, -1e9)
    lo = np.floor(poly.min(axis=0)).astype(int) - 3
    hi = np.ceil(poly.max(axis=0)).astype(int) + 3
    for y in range(lo[1], hi[1] + 1):
        for x in range(lo[0], hi[0] + 1):
            out[y, x] = cv2.pointPolygonTest(poly, (float(x), float(y)), True)
    return out


def test_cube_corner_is_where_three_colours_meet():
    cam = synthetic.misaligned_rig()
    room = synthetic.Room()
    img = synthetic.render_room(cam, room, supersample=4)
    faces = room.visible_faces(cam.best_fit_viewpoint()[0])
    corners = room.cube_corners()
    # the corner shared by the three visible faces (nearest the viewpoint)
    shared = [
        i
        for i in range(8)
        if all(np.isclose(room.cube_faces()[f], corners[i]).all(axis=1).any() for f in faces)
    ]
    assert len(shared) == 1
    px = cam.project(corners[shared])[0]
    colours = np.asarray(room.cube_colors, float)[faces]
    # 2 px from the corner towards each face's centre: that face's pure colour
    for f, col in zip(faces, colours):
        centre = cam.project(room.cube_faces()[f].mean(axis=0)[None])[0]
        u = (centre - px) / np.linalg.norm(centre - px)
        q = np.round(px + 2.5 * u).astype(int)
        assert np.abs(img[q[1], q[0]] - col).max() <= 1
    # the pixel at the corner mixes all three: it is none of them
    c = np.round(px).astype(int)
    assert (np.abs(img[c[1], c[0]] - colours).max(axis=1) > 10).all()


def test_bad_input_raises_value_error(environment):
    cam = synthetic.misaligned_rig()
    no_size = cam.replace(image_size=None)
    with pytest.raises(ValueError, match="image_size"):
        synthetic.render_environment(no_size, environment)
    with pytest.raises(ValueError, match="image_size"):
        synthetic.render_room(no_size)
    with pytest.raises(ValueError, match="MisalignedHyperbolicCamera"):
        synthetic.render_environment("camera", environment)
    for bad in (np.zeros((64, 128)), np.zeros((64, 128, 4)), np.zeros((1, 128, 3))):
        with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
            synthetic.render_environment(cam, bad)
    with pytest.raises(ValueError, match="finite"):
        synthetic.render_environment(cam, np.full((8, 16, 3), np.nan))
    for s in (0, 2.5, True):
        with pytest.raises(ValueError, match="supersample"):
            synthetic.render_environment(cam, environment, supersample=s)
    with pytest.raises(ValueError, match="noise"):
        synthetic.render_environment(cam, environment, noise=-1.0)
    with pytest.raises(ValueError, match="inside the room"):
        synthetic.render_room(cam, synthetic.Room(box_min=(100.0, -2500.0, -850.0)))
    with pytest.raises(ValueError, match="cube"):
        synthetic.Room(cube_center=(2450.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="cube_colors"):
        synthetic.Room(cube_colors=((0, 0, 0),) * 5)
    with pytest.raises(ValueError, match="room"):
        synthetic.render_room(cam, room="box")


def test_cube_face_edges_are_subpixel_true():
    # the visible faces -X, +Y, +Z pure blue, green, red, everything else black: each
    # channel's area (sum / 255) is its face's projected area
    cam = synthetic.misaligned_rig()
    black = ((0, 0, 0), (0, 0, 0))
    room = synthetic.Room(
        wall_colors=(black,) * 6,
        cube_colors=((0, 0, 0), (255, 0, 0), (0, 255, 0), (0, 0, 0), (0, 0, 255), (0, 0, 0)),
    )
    img = synthetic.render_room(cam, room, supersample=4, housing_color=(0, 0, 0), body_radius=None)
    t = np.linspace(0, 1, 100, endpoint=False)[:, None]
    for channel, face in enumerate([1, 2, 4]):
        f = room.cube_faces()[face]
        p = cam.project(np.concatenate([f[k] + t * (f[(k + 1) % 4] - f[k]) for k in range(4)]))
        x, y = p.T
        area = 0.5 * abs(x @ np.roll(y, -1) - y @ np.roll(x, -1))
        perimeter = np.linalg.norm(p - np.roll(p, 1, axis=0), axis=1).sum()
        assert area > 100
        assert abs((img[..., channel].sum() / 255.0 - area) / perimeter) < 0.01, face


def test_true_equirectangular_panorama_reproduces_the_environment(rigs, environment):
    # the environment's mapping is the panorama convention of docs/conventions.md over (-90, 90)
    cam = rigs["misaligned"]
    img = synthetic.render_environment(cam, environment, supersample=4)
    h, w = environment.shape[:2]
    m1, m2 = cam.init_panorama_maps(
        (w, h), elevation_range=(-90.0, 90.0), projection="equirectangular", m1type=cv2.CV_32FC1
    )
    pano = cv2.remap(img, m1, m2, cv2.INTER_LINEAR)
    el = 90.0 - 180.0 * np.arange(h) / (h - 1)
    band = (el > -60) & (el < 5)  # seen all around, lens excluded
    diff = np.abs(pano[band].astype(int) - environment[band]).max(axis=-1)
    assert np.median(diff) <= 2
    assert np.mean(diff > 40) < 0.1  # only near edges (200 px image)


def test_far_line_pixels_are_images_of_straight_lines():
    cam = synthetic.misaligned_rig()
    lines = synthetic.far_line_pixels(cam, n_lines=4, rng=3)
    assert len(lines) == 4
    for px in lines:
        assert len(px) >= 5 and np.isfinite(px).all()
        P, d = cam.unproject(px)
        # the rays meet one 3-D line: their directions are nearly coplanar (far away, eq. 31)
        assert np.linalg.svd(d, compute_uv=False)[-1] < 1e-5
    assert all(
        np.array_equal(a, b)
        for a, b in zip(lines, synthetic.far_line_pixels(cam, n_lines=4, rng=3))
    )
