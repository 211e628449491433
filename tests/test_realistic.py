"""The realistic renderer (omnicam.synthetic.realistic) against independent references.

The renderer has its own tracer; omnicam (its rim ellipse, its unproject) is the independent
check here, together with the aligned model (eqs. 2-5) and the reflection law.
"""

import math

import cv2
import numpy as np
import pytest

from omnicam import MisalignedHyperbolicCamera, synthetic
from omnicam.synthetic import realistic as rl
from omnicam.synthetic.realistic.optics import CameraNumbers, lin
from omnicam.synthetic.realistic.scene import MIRROR_LABELS
from omnicam.synthetic.realistic.stress import _reflection_visible

FRONT = (rl.LABELS["glass"], rl.LABELS["front_ring"])


def _rig(tilt=3.0, az=40.0, offset=(1.5, -1.0, 1.0), size=(400, 400), D=None):
    return synthetic.misaligned_rig(tilt, az, offset, image_size=size, D=D)


DISTORTED = _rig(4.0, 100.0, (-2.0, 1.0, 2.0), D=[-0.08, 0.02, 0.0008, -0.0005, 0.0])


def _mirror_edge_along(camera, centre, targets, lo=0.5, hi=1.5, iters=60):
    """Own tracer: where the mirror ends on rays from ``centre`` through ``targets`` (bisection
    on the fraction of the way, inside at ``lo``, outside at ``hi``)."""
    num = CameraNumbers(camera)
    a = np.full(len(targets), lo)
    b = np.full(len(targets), hi)
    for _ in range(iters):
        m = 0.5 * (a + b)
        px = centre + m[:, None] * (targets - centre)
        v = lin(rl.camera_rays(num.K, num.D, px), num.R.T)
        inside = np.isfinite(
            rl.intersect_mirror(num.a, num.b, num.rim, np.broadcast_to(num.C, v.shape), v)
        )
        a = np.where(inside, m, a)
        b = np.where(inside, b, m)
    return centre + (0.5 * (a + b))[:, None] * (targets - centre)


# -- the tracer -------------------------------------------------------------------------------
def test_aligned_rig_rendered_rim_matches_eqs_2_to_5():
    cam = synthetic.aligned_rig((400, 400))
    m = cam.mirror
    r_pred = cam.K[0, 0] * m.rim_radius / (m.z_rim + m.c)  # aligned rim radius (eqs. 2-5)
    centre = cam.K[:2, 2]
    ren = rl.render_rig(cam, rl.Rig(), supersample=4)
    # the 0.5 level of the rendered mirror coverage along 180 radial lines
    th = np.linspace(0, 2 * np.pi, 180, endpoint=False)
    radii = np.arange(r_pred - 3, r_pred + 3, 0.01)
    mx = (centre[0] + np.cos(th)[:, None] * radii).astype(np.float32)
    my = (centre[1] + np.sin(th)[:, None] * radii).astype(np.float32)
    prof = cv2.remap(ren.coverage, mx, my, cv2.INTER_LINEAR)
    edge = radii[np.argmax(prof < 0.5, axis=1)]
    assert np.abs(edge - r_pred).max() < 0.5
    # and against omnicam's rim ellipse
    rim = cam.rim_image_points(180)
    assert np.abs(np.linalg.norm(rim - centre, axis=1) - r_pred).max() < 1e-9
    assert abs(np.median(edge) - r_pred) < 0.1


@pytest.mark.parametrize("camera", [_rig(), DISTORTED], ids=["misaligned", "distorted"])
def test_tracer_rim_edge_lies_on_omnicams_rim_ellipse(camera):
    rim = camera.rim_image_points(90)
    centre = rim.mean(axis=0)
    edge = _mirror_edge_along(camera, centre, rim)
    assert np.abs(edge - rim).max() < 1e-5


def test_rendered_mask_edge_matches_rim_ellipse_within_half_a_pixel():
    cam = DISTORTED
    ren = rl.render_rig(cam, rl.Rig(), supersample=4)
    rim = cam.rim_image_points(120)
    centre = rim.mean(axis=0)
    u = (rim - centre) / np.linalg.norm(rim - centre, axis=1)[:, None]
    s = np.arange(-3, 3, 0.01)
    mx = (rim[:, 0:1] + u[:, 0:1] * s).astype(np.float32)
    my = (rim[:, 1:2] + u[:, 1:2] * s).astype(np.float32)
    prof = cv2.remap(ren.coverage, mx, my, cv2.INTER_LINEAR)
    assert np.abs(s[np.argmax(prof < 0.5, axis=1)]).max() < 0.5


def test_reflection_law_angle_in_equals_angle_out():
    cam = _rig()
    num = CameraNumbers(cam)
    pix = cam.rim_image_points(50) * 0.6 + 0.4 * cam.K[:2, 2]
    v = lin(rl.camera_rays(num.K, num.D, pix), num.R.T)
    t = rl.intersect_mirror(num.a, num.b, num.rim, np.broadcast_to(num.C, v.shape), v)
    P = num.C + t[:, None] * v
    assert (
        np.abs((P[:, 0] ** 2 + P[:, 1] ** 2) / num.a**2 - P[:, 2] ** 2 / num.b**2 + 1).max() < 1e-12
    )
    n = rl.mirror_normal(num.a, num.b, P)
    d = rl.reflect(v, n)
    cos_in = np.einsum("ij,ij->i", v, n)
    cos_out = np.einsum("ij,ij->i", d, n)
    np.testing.assert_allclose(cos_out, -cos_in, atol=1e-13)  # angle in = angle out
    assert np.abs(np.linalg.det(np.stack([v, n, d], axis=1))).max() < 1e-13  # coplanar
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-13)


def test_aligned_rig_reflected_rays_pass_through_outer_focus():
    cam = synthetic.aligned_rig((300, 300))
    pix = np.random.default_rng(1).uniform(60, 240, (500, 2))
    _, _, P, d = rl.trace(cam, pix)
    ok = np.isfinite(d[:, 0])
    assert ok.sum() > 300
    w = np.array([0.0, 0.0, cam.mirror.c]) - P[ok]
    miss = np.linalg.norm(w - np.einsum("ij,ij->i", w, d[ok])[:, None] * d[ok], axis=1)
    assert miss.max() < 1e-9


@pytest.mark.parametrize("camera", [_rig(), DISTORTED], ids=["misaligned", "distorted"])
def test_tracer_rays_agree_with_omnicam_unproject(camera):
    pix = camera.rim_image_points(64) * 0.9 + 0.1 * camera.rim_image_points(64).mean(axis=0)
    pix = np.concatenate([pix, np.random.default_rng(2).uniform(150, 250, (200, 2))])
    _, _, P, d = rl.trace(camera, pix)
    P2, d2 = camera.unproject(pix)
    assert np.array_equal(np.isnan(d[:, 0]), np.isnan(d2[:, 0]))
    ok = np.isfinite(d[:, 0])
    assert np.abs(P[ok] - P2[ok]).max() < 1e-8 and np.abs(d[ok] - d2[ok]).max() < 1e-10


# -- far lines --------------------------------------------------------------------------------
@pytest.mark.parametrize("camera", [_rig(), DISTORTED], ids=["misaligned", "distorted"])
def test_far_line_pixels_rays_are_coplanar_with_the_great_circle(camera):
    room = rl.RoomScene(yaw_deg=20.0)
    checked = 0
    for p1, p2 in room.edges():
        px = rl.far_line_pixels(camera, p1, p2, n_points=30)
        assert px.ndim == 2 and px.shape[1] == 2 and px.dtype == np.float64
        if len(px) < 5:
            continue
        n = np.cross(p1, p2)
        n /= np.linalg.norm(n)
        _, d = camera.unproject(px)
        assert np.isfinite(d).all()
        assert np.abs(d @ n).max() < 1e-4
        # on the segment's arc, not the rest of the great circle
        assert (np.cross(p1, d) @ n >= -1e-9).all() and (np.cross(d, p2) @ n >= -1e-9).all()
        checked += 1
    assert checked >= 3


# -- hostile elements -------------------------------------------------------------------------
def _outline_radius(camera, body, centre, angles):
    """Independent outline: along rays from ``centre``, where omnicam's reflected ray meets the
    front plane z = z_barrel (camera frame) at radius r_barrel (bisection)."""
    R, t = camera.R, camera.tvec
    u = np.stack([np.cos(angles), np.sin(angles)], axis=1)

    def rho(s):
        P, d = camera.unproject(centre + s[:, None] * u)
        o, v = P @ R.T + t, d @ R.T
        k = (body.z_barrel - o[:, 2]) / v[:, 2]
        return np.hypot(o[:, 0] + k * v[:, 0], o[:, 1] + k * v[:, 1])

    a, b = np.zeros(len(u)), np.full(len(u), 80.0)
    assert (rho(a) < body.r_barrel).all() and (rho(b) > body.r_barrel).all()
    for _ in range(50):
        m = 0.5 * (a + b)
        inside = rho(m) < body.r_barrel
        a, b = np.where(inside, m, a), np.where(inside, b, m)
    return 0.5 * (a + b), u


def test_body_outline_appears_where_the_front_circle_predicts():
    cam = _rig(size=(500, 500))
    body = rl.BodyGeometry(
        r_barrel=14.0,
        z_barrel=25.0,
        r_glass=11.0,
        w_box=18.0,
        h_box=14.0,
        z_box=-8.0,
        box_color=(180.0, 180.0, 185.0),
    )
    ren = rl.render_rig(cam, rl.Rig(body=body), supersample=3)
    front = np.isin(ren.labels, FRONT)
    ys, xs = np.nonzero(front)
    centre = np.array([xs.mean(), ys.mean()])
    angles = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    s, u = _outline_radius(cam, body, centre, angles)
    outline = centre + s[:, None] * u
    # the own tracer flips from the front disc to something else exactly there
    lab_in, *_ = rl.trace(cam, outline - 0.02 * u, rl.Rig(body=body))
    lab_out, *_ = rl.trace(cam, outline + 0.02 * u, rl.Rig(body=body))
    assert np.isin(lab_in, FRONT).all() and not np.isin(lab_out, FRONT).any()
    # and the rendered boundary pixels lie on that outline
    edge = front & ~cv2.erode(front.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    ey, ex = np.nonzero(edge)
    dense_s, dense_u = _outline_radius(cam, body, centre, np.linspace(0, 2 * np.pi, 720))
    dense = centre + dense_s[:, None] * dense_u
    dist = np.min(np.hypot(ex[:, None] - dense[:, 0], ey[:, None] - dense[:, 1]), axis=1)
    assert dist.max() < 1.5
    # the truth the renders carry is that circle
    assert body.circles() == ((14.0, 25.0),)


def test_reflection_visible_follows_the_contrast_of_the_silhouette():
    cam = _rig(size=(400, 400))
    common = {"r_barrel": 12.0, "z_barrel": 20.0, "r_glass": 10.0, "ring_color": (40.0, 40.0, 40.0)}
    silver = rl.BodyGeometry(**common, w_box=30.0, h_box=30.0, box_color=(180.0, 180.0, 180.0))
    dark = rl.BodyGeometry(**common, w_box=30.0, h_box=30.0, box_color=(42.0, 42.0, 42.0))
    seen = rl.render_rig(cam, rl.Rig(body=silver), supersample=2)
    hidden = rl.render_rig(cam, rl.Rig(body=dark), supersample=2)
    assert (seen.labels == rl.LABELS["box"]).sum() > 100  # the box shows around the barrel
    assert _reflection_visible(seen, cam.image_size)
    assert not _reflection_visible(hidden, cam.image_size)  # dark front on a dark box
    assert not _reflection_visible(rl.render_rig(cam, rl.Rig(), 2), cam.image_size)


def test_clipped_frame_really_clips_the_rim():
    case = next(c for c in rl.stress_cases(40, 3, image_size=(480, 360)) if "clipped" in c.flags)
    r = rl.render_case(case)
    h = r.image.shape[0]
    rim = r.camera.rim_image_points(360)
    assert rim[:, 1].min() < 0 and rim[:, 1].max() > h - 1  # the rim overflows top and bottom
    mirror = np.isin(r.labels, MIRROR_LABELS)
    assert mirror[0].any() and mirror[-1].any()  # the mirror is cut by the frame


def test_struts_occlude_radial_stripes_of_the_mirror():
    cam = _rig(size=(400, 400))
    struts = rl.random_struts(np.random.default_rng(5), cam, count=3)
    bare = rl.render_rig(cam, rl.Rig(), supersample=2)
    ren = rl.render_rig(cam, rl.Rig(struts=struts), supersample=2)
    strut = ren.labels == rl.LABELS["strut"]
    inside_rim = bare.coverage == 1.0
    assert (strut & inside_rim).sum() > 200  # the struts hide part of the mirror
    _, d = cam.unproject(np.argwhere(strut & inside_rim)[:, ::-1].astype(float))
    assert np.isfinite(d).all()  # ... which omnicam says the camera would otherwise see
    changed = np.abs(ren.image - bare.image).max(axis=2) > 1
    near = cv2.dilate(np.isin(ren.labels, (2, 9)).astype(np.uint8), np.ones((3, 3), np.uint8))
    assert not (changed & ~near.astype(bool)).any()  # nothing else changed
    # each stripe is radial: long in radius, narrow in angle about the rim centre
    n, comp = cv2.connectedComponents((strut & inside_rim).astype(np.uint8))
    centre = cam.rim_image_points(90).mean(axis=0)
    r_rim = np.linalg.norm(cam.rim_image_points(90) - centre, axis=1).mean()
    assert n - 1 >= 3
    for k in range(1, n):
        ys, xs = np.nonzero(comp == k)
        rad = np.hypot(xs - centre[0], ys - centre[1])
        ang = np.unwrap(np.sort(np.arctan2(ys - centre[1], xs - centre[0])))
        assert rad.max() - rad.min() > 0.3 * r_rim
        assert np.ptp(ang) < math.radians(25)


def test_dark_floor_darkens_exactly_the_directions_below_its_elevation():
    cam = _rig(size=(400, 400))
    room = rl.RoomScene(dark_floor_deg=-65.0)
    ren = rl.render_rig(cam, rl.Rig(room=room, mirror_gain=1.0), supersample=2)
    gy, gx = np.mgrid[0:400, 0:400]
    pix = np.stack([gx.ravel(), gy.ravel()], axis=1).astype(float)
    _, d = cam.unproject(pix)  # independent directions
    el = np.degrees(np.arcsin(np.clip(d[:, 2], -1, 1)))
    grey = ren.image.reshape(-1, 3).mean(axis=1)
    below = el < -66.0
    above = (el > -64.0) & (el < -40.0)
    assert below.sum() > 500 and above.sum() > 500
    assert grey[below].max() < 16
    assert np.median(grey[above]) > 50
    labels = ren.labels.ravel()
    assert (labels[below] == rl.LABELS["dark_floor"]).all()
    assert not (labels[above] == rl.LABELS["dark_floor"]).any()


@pytest.mark.parametrize("kind", ["white", "black", "metal"])
def test_holder_ring_lies_outside_the_rim_within_its_outer_edge(kind):
    cam = _rig(size=(400, 400))
    holder = rl.Holder(outer_axes=(36.0, 34.0), angle_deg=30.0, kind=kind)
    ren = rl.render_rig(cam, rl.Rig(holder=holder), supersample=2)
    ring = ren.labels == rl.LABELS["holder"]
    assert ring.sum() > 2000
    _, d = cam.unproject(np.argwhere(ring)[:, ::-1].astype(float))
    assert np.isnan(d).all()  # outside the rim (omnicam)
    # the outer edge: the ellipse in the rim plane, projected with the truth posture
    phi = np.linspace(0, 2 * np.pi, 720)
    ca, sa = math.cos(math.radians(30)), math.sin(math.radians(30))
    e = np.stack([36 * np.cos(phi), 34 * np.sin(phi)], axis=1)
    X = np.stack(
        [
            ca * e[:, 0] - sa * e[:, 1],
            sa * e[:, 0] + ca * e[:, 1],
            np.full(len(phi), cam.mirror.z_rim),
        ],
        axis=1,
    )
    outer, _ = cv2.projectPoints(X, cam.rvec, cam.tvec, cam.K, None)
    poly = outer.reshape(-1, 2).astype(np.float32)
    ys, xs = np.nonzero(ring)
    inside = [cv2.pointPolygonTest(poly, (float(x), float(y)), True) for x, y in zip(xs, ys)]
    assert min(inside) > -1.0
    grey = ren.image[ring].mean(axis=1)
    if kind == "white":
        assert np.median(grey) > 200
    elif kind == "black":
        assert np.median(grey) < 30
    else:
        assert np.ptp(grey) > 60  # brushed metal: brightness varies around the ring


def test_photometric_degradations_do_what_they_say():
    cam = _rig(size=(320, 320))
    clean = rl.render_rig(cam, rl.Rig(), supersample=2).image
    plain = rl.degrade(clean, rl.Photometric())
    assert np.abs(plain.astype(float) - clean).max() <= 0.5
    blur = rl.degrade(clean, rl.Photometric(blur_sigma=1.5))
    lap = [
        cv2.Laplacian(cv2.cvtColor(x, cv2.COLOR_BGR2GRAY), cv2.CV_64F).var() for x in (plain, blur)
    ]
    assert lap[1] < 0.5 * lap[0]
    noisy = rl.degrade(clean, rl.Photometric(noise_sigma=4.0), seed=1)
    assert 3.0 < np.std(noisy.astype(float) - plain) < 6.0
    assert np.array_equal(noisy, rl.degrade(clean, rl.Photometric(noise_sigma=4.0), seed=1))
    vig = rl.degrade(np.full((100, 100, 3), 200.0, np.float32), rl.Photometric(vignette=0.4))
    assert vig[50, 50, 0] >= 199 and abs(int(vig[0, 0, 0]) - 120) <= 1
    jpg = rl.degrade(clean, rl.Photometric(jpeg_quality=75))
    err = np.abs(jpg.astype(float) - plain)
    assert 0 < err.mean() < 4


# -- the stress cases -------------------------------------------------------------------------
def test_stress_cases_are_reproducible_and_cover_every_variant():
    a = list(rl.stress_cases(40, 7))
    b = list(rl.stress_cases(40, 7))
    assert [(c.flags, c.K, c.tilt_deg, c.offset_mm) for c in a] == [
        (c.flags, c.K, c.tilt_deg, c.offset_mm) for c in b
    ]
    assert (
        a[0].flags != next(rl.stress_cases(1, 8)).flags or a[0].K != next(rl.stress_cases(1, 8)).K
    )
    for v in rl.VARIANTS:
        assert any(c.flags == {v} for c in a), v  # each variant alone
        assert any(v in c.flags and len(c.flags) > 2 for c in a), v  # and in combinations
    for c in a:
        assert 0 <= c.tilt_deg <= 5 and np.linalg.norm(c.offset_mm) <= 5
        cam = c.camera()
        assert math.degrees(math.acos(cam.R[2, 2])) == pytest.approx(c.tilt_deg, abs=1e-9)
        if c.body is not None:
            assert 5 <= c.body.r_barrel <= 25 and 5 <= c.body.z_barrel <= 40
            assert c.body.z_box < c.body.z_barrel and c.body.w_box >= c.body.r_barrel
        assert (c.D is not None) == ("distortion" in c.flags)


def test_render_case_returns_the_truth_with_the_image():
    case = next(
        c
        for c in rl.stress_cases(8, 1, image_size=(400, 400))
        if {"body", "struts"} <= c.flags or c.flags == {"body"}
    )
    r = rl.render_case(case)
    assert r.image.dtype == np.uint8 and r.image.shape == (400, 400, 3)
    assert isinstance(r.camera, MisalignedHyperbolicCamera) and r.flags == case.flags
    assert r.body_circles[0] == (case.body.r_barrel, case.body.z_barrel)
    assert len(r.far_lines) >= 1 and len(r.far_lines) == len(r.far_line_normals)
    for px, n in zip(r.far_lines, r.far_line_normals):
        _, d = r.camera.unproject(px)
        assert np.abs(d @ n).max() < 1e-4
        lab = r.labels[np.round(px[:, 1]).astype(int), np.round(px[:, 0]).astype(int)]
        assert (lab == rl.LABELS["scene"]).all()  # never on the body, a strut or the floor


def test_bad_input_raises_value_error_naming_the_argument():
    with pytest.raises(ValueError, match="case"):
        rl.render_case("not a case")
    with pytest.raises(ValueError, match="supersample"):
        rl.render_rig(_rig(), supersample=0)
    with pytest.raises(ValueError, match="image_size"):
        rl.render_rig(_rig().replace(image_size=None))


# -- the estimator on a small stress matrix ---------------------------------------------------
def test_small_stress_matrix_has_no_silent_failure():
    silent = []
    cases = list(rl.stress_cases(24, 11, image_size=(400, 400)))
    picked = [c for c in cases if "body" in c.flags][:6]
    for case in picked:
        r = rl.render_case(case)
        truth = r.camera
        try:
            cam, report = MisalignedHyperbolicCamera.calibrate(
                truth.K, truth.mirror, image=r.image, D=truth.D
            )
        except ValueError:
            continue  # a clear refusal is not a silent failure
        a, b = cam.R[:, 2], truth.R[:, 2]
        err = math.degrees(math.atan2(np.linalg.norm(np.cross(a, b)), a @ b))
        if err > 0.1 and not report.warnings:
            silent.append((case.index, sorted(case.flags), round(err, 3)))
    assert not silent, f"silent failures (case, flags, axis error deg): {silent}"
