"""The rim ellipse Q_I (eqs. 20-22): fit to given points, and detection in images."""

import cv2
import numpy as np
import pytest
from conftest import REAL_PHOTO, white_holder_render

import omnicam
from omnicam import synthetic
from omnicam.calibration import rim as rim_module
from omnicam.calibration.rim import (
    RimFit,
    RimRejected,
    conic_distance,
    conic_from_ellipse,
    detect_rim,
    ellipse_from_conic,
    fit_rim,
)


def _conic_residual(Q, pts):
    ph = np.c_[pts, np.ones(len(pts))]
    return np.einsum("ni,ij,nj->n", ph, Q, ph)


# -- fit_rim on given points ---------------------------------------------------------------------
@pytest.mark.parametrize("robust", [True, False])
def test_fit_rim_exact_points_recovers_conic(robust):
    cam = synthetic.misaligned_rig()
    truth = cam.rim_image_points(360)
    fit = fit_rim(truth, robust=robust)
    assert isinstance(fit, RimFit)
    assert fit.rms < 1e-9
    assert np.abs(fit.distance(cam.rim_image_points(1000))).max() < 1e-9
    Q = fit.conic
    assert Q.shape == (3, 3) and Q.dtype == np.float64
    np.testing.assert_allclose(Q, Q.T, atol=0)
    assert np.linalg.norm(Q) == pytest.approx(1.0)
    # interior negative (eq. 21 sign convention): exactly one negative eigenvalue
    assert _conic_residual(Q, fit.center[None])[0] < 0
    assert np.sum(np.linalg.eigvalsh(Q) < 0) == 1
    assert fit.points.shape == (360, 2) and fit.inliers.all()


def test_fit_rim_accepts_opencv_shape_and_float32():
    truth = synthetic.aligned_rig().rim_image_points(100)
    fit = fit_rim(truth[:, None, :].astype(np.float32))
    assert fit.points.shape == (100, 2) and fit.points.dtype == np.float64
    assert fit.rms < 1e-3  # float32 rounding of ~250 px coordinates


def test_fit_rim_conic_matches_geometry():
    center, S = np.array([250.3, 240.7]), np.array([[200.0, 7.0], [7.0, 180.0]])
    Q = conic_from_ellipse(center, S)
    c2, S2 = ellipse_from_conic(-3.0 * Q)  # scale and sign do not matter
    np.testing.assert_allclose(c2, center, atol=1e-9)
    np.testing.assert_allclose(S2, S, atol=1e-9)
    t = np.linspace(0, 2 * np.pi, 50)
    pts = center + np.c_[np.cos(t), np.sin(t)] @ S.T
    fit = fit_rim(pts)
    np.testing.assert_allclose(fit.conic, Q, atol=1e-12)
    np.testing.assert_allclose(fit.axes[0] * fit.axes[1], np.linalg.det(S), rtol=1e-9)


def test_fit_rim_partial_arc():
    """A rim clipped by the image border leaves an arc; the fit still recovers the ellipse."""
    cam = synthetic.misaligned_rig()
    arc = cam.rim_image_points(360)[30:150]
    fit = fit_rim(arc)
    assert np.abs(fit.distance(cam.rim_image_points(720))).max() < 1e-8


def test_fit_rim_rejects_outliers_and_is_geometric_under_noise():
    cam = synthetic.misaligned_rig()
    rng = np.random.default_rng(5)
    truth = cam.rim_image_points(400)
    noisy = truth + rng.normal(0.0, 0.3, truth.shape)
    outliers = rng.uniform(0, 500, (200, 2))  # a third of the points
    fit = fit_rim(np.r_[noisy, outliers])
    assert fit.inliers[:400].all()
    far = np.abs(fit.distance(outliers)) > 3.0
    assert not (fit.inliers[400:] & far).any()
    assert fit.rms == pytest.approx(0.3, rel=0.15)
    # the true rim lies within a small fraction of the noise of the fitted one
    assert np.sqrt(np.mean(fit.distance(cam.rim_image_points(720)) ** 2)) < 0.05


def test_fit_rim_without_robust_uses_every_point():
    cam = synthetic.aligned_rig()
    pts = np.r_[cam.rim_image_points(50), [[10.0, 10.0]]]
    fit = fit_rim(pts, robust=False)
    assert fit.inliers.all() and len(fit.points) == 51 and fit.rms > 0.1


@pytest.mark.parametrize(
    "points, match",
    [
        (np.zeros((4, 2)), "at least 6"),
        (np.zeros((10, 3)), "shape"),
        (np.full((10, 2), np.nan), "finite"),
        (np.c_[np.arange(10.0), 2 * np.arange(10.0)], "ellipse"),
        (np.c_[np.arange(10.0), np.arange(10.0) ** 2], "ellipse"),
        (np.zeros((10, 2)), "ellipse"),
        ("rim", "array"),
    ],
)
def test_fit_rim_bad_input_raises_value_error(points, match):
    with pytest.raises(ValueError, match=match):
        fit_rim(points)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"threshold": 0.0}, "threshold"),
        ({"threshold": float("nan")}, "threshold"),
        ({"max_trials": 0}, "max_trials"),
    ],
)
def test_fit_rim_bad_parameters_raise_value_error(kwargs, match):
    with pytest.raises(ValueError, match=match):
        fit_rim(synthetic.aligned_rig().rim_image_points(20), **kwargs)


def test_fit_rim_too_few_points_non_robust():
    pts = synthetic.aligned_rig().rim_image_points(5)
    assert fit_rim(pts, robust=False).rms < 1e-9
    with pytest.raises(ValueError, match="at least 5"):
        fit_rim(pts[:4], robust=False)


# -- detect_rim on images ------------------------------------------------------------------------

# A careful manual fit of the real photograph's rim (the outer edge of the bright mirror against
# the black holder), made before detect_rim was written. How it was made: radial intensity
# profiles (grey, averaged over 5 px across) and 12-20x magnified crops were inspected every
# 5-10 deg around the guess centre (981, 554), radius 595 px of the data README, and at each
# angle the edge was read by eye as the level half-way between the mirror just inside the edge
# and the holder just outside it. Angles where the rim is out of frame (top, bottom), where the
# mirror content next to the rim is as dark as the holder (40-55 deg, 245-300 deg) or where a
# specular streak or a two-step edge made the reading ambiguous (20, -50, 235, 240 deg) were left
# out. Angle (deg, image y down) -> offset (px) from radius 595:
MANUAL_PICKS = {
    -65: 4.1,
    -60: 4.1,
    -55: 4.4,
    -40: -0.5,
    -30: 0.1,
    -20: -0.6,
    -10: 0.3,
    0: -1.6,
    10: -0.9,
    30: -0.6,
    60: 2.3,
    120: 2.4,
    125: 1.85,
    130: 1.35,
    140: 0.25,
    150: 0.07,
    160: -1.1,
    170: -1.85,
    180: -2.3,
    190: -1.55,
    200: -0.5,
    210: -0.6,
    220: 0.6,
    230: 1.0,
}
# fit_rim(manual points, robust=False): centre, semi-axes, mean diameter (px); residual RMS 0.65 px
MANUAL_CENTER = (981.31, 553.52)
MANUAL_AXES = (599.22, 593.39)
MANUAL_DIAMETER = 1192.61


def _manual_points():
    a = np.deg2rad(np.array(list(MANUAL_PICKS), float))
    r = 595.0 + np.array(list(MANUAL_PICKS.values()))
    return np.array([981.0, 554.0]) + r[:, None] * np.c_[np.cos(a), np.sin(a)]


def _texture(d):
    """Smooth bright texture of the scene by direction: grey levels 115..235."""
    az = np.arctan2(d[:, 1], d[:, 0])
    el = np.arcsin(np.clip(d[:, 2], -1, 1))
    return 175 + 45 * np.sin(7 * az) * np.cos(5 * el) + 15 * np.cos(23 * az + 3 * el)


def _render(
    cam, supersample=8, housing=30.0, lens_frac=0.25, clutter=False, struts=(), noise=0.0, seed=0
):
    """A rendered catadioptric image with an exact rim (float64 grey, 0..255).

    Pixels whose ray (``cam.unproject``) is finite see the textured scene, the others the dark
    housing; pixels within 1.5 px of the rim are averaged over ``supersample**2`` subpixels, so the
    edge is area-true. A dark disk about the rim centre stands for the camera's reflection;
    ``clutter`` adds bright boxes outside the rim (the room behind the housing), ``struts`` dark
    holder arms 14 px wide at these angles (deg) from outside the rim to 60 % of its radius.
    """
    w, h = cam.image_size
    truth = fit_rim(cam.rim_image_points(4000), robust=False)
    gx, gy = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    pix = np.stack([gx.ravel(), gy.ravel()], 1)
    _, d = cam.unproject(pix)
    inside = np.isfinite(d[:, 0])
    val = np.full(len(pix), housing)
    val[inside] = _texture(d[inside])
    band = np.abs(truth.distance(pix)) < 1.5
    sub = (np.arange(supersample) + 0.5) / supersample - 0.5
    sx, sy = np.meshgrid(sub, sub)
    bp = (pix[band][:, None, :] + np.stack([sx.ravel(), sy.ravel()], 1)[None]).reshape(-1, 2)
    _, db = cam.unproject(bp)
    vb = np.full(len(bp), housing)
    ok = np.isfinite(db[:, 0])
    vb[ok] = _texture(db[ok])
    val[band] = vb.reshape(-1, supersample**2).mean(1)
    img = val.reshape(h, w)
    img[np.hypot(gx - truth.center[0], gy - truth.center[1]) < lens_frac * truth.axes.mean()] = 12
    for ang in struts:
        u = np.array([np.cos(np.deg2rad(ang)), np.sin(np.deg2rad(ang))])
        q = np.stack([gx - truth.center[0], gy - truth.center[1]], -1)
        img[(np.abs(q @ (-u[1], u[0])) < 7) & (q @ u > 0.6 * truth.axes.mean())] = housing
    rng = np.random.default_rng(seed)
    if clutter:
        far = truth.distance(pix).reshape(h, w) > 6
        for _ in range(12):
            x0, y0 = rng.uniform(0, w), rng.uniform(0, h)
            ww, hh = rng.uniform(5, 60, 2)
            img[(np.abs(gx - x0) < ww) & (np.abs(gy - y0) < hh) & far] = rng.uniform(120, 255)
    if noise:
        img = img + rng.normal(0, noise, img.shape)
    return np.clip(img, 0, 255)


def _rms_to_conic(Q, pts):
    """RMS geometric distance of points to the ellipse of the conic ``Q`` (eqs. 20-22), px."""
    return float(np.sqrt(np.mean(conic_distance(Q, pts) ** 2)))


RIGS = {
    "aligned": lambda: synthetic.aligned_rig(),
    "misaligned": lambda: synthetic.misaligned_rig(),
    "random": lambda: synthetic.random_misaligned_rig(np.random.default_rng(3)),
    "tilted_far": lambda: synthetic.misaligned_rig(5.0, 250.0, (-4.0, 3.0, 2.5)),
}


@pytest.mark.parametrize("rig", sorted(RIGS))
def test_detect_rim_rendered_image_within_0p05px(rig):
    cam = RIGS[rig]()
    img = np.round(_render(cam)).astype(np.uint8)
    fit = detect_rim(img)
    truth = cam.rim_image_points(2000)
    assert _rms_to_conic(fit.conic, truth) < 0.05
    assert np.abs(fit.distance(truth)).max() < 0.1
    assert fit.rms < 0.1 and len(fit.points) > 1000  # per-point precision


def test_detect_rim_ignores_lens_reflection_and_clipping():
    """Rim clipped by three image borders, a big dark lens blob, three dark holder arms across
    the rim, bright clutter outside."""
    cam = synthetic.misaligned_rig(5.0, 0.0, (5.0, 0.0, 0.0), image_size=(640, 400), fill=1.2)
    rim = cam.rim_image_points(2000)
    assert rim[:, 1].min() < 0 and rim[:, 1].max() > 399 and rim[:, 0].max() > 639  # clipped
    img = np.round(
        _render(cam, lens_frac=0.45, clutter=True, struts=(200, 290, 340), seed=1)
    ).astype(np.uint8)
    fit = detect_rim(img)
    assert _rms_to_conic(fit.conic, rim) < 0.05
    # every point used is on the rim, in the frame, none on the border, the lens or the clutter
    true_conic = fit_rim(rim, robust=False).conic
    assert np.abs(conic_distance(true_conic, fit.points)).max() < 1.0
    assert (fit.points[:, 0] > 1).all() and (fit.points[:, 0] < 638).all()
    assert (fit.points[:, 1] > 1).all() and (fit.points[:, 1] < 398).all()


def test_detect_rim_same_result_for_grey_bgr_uint8_uint16_float():
    cam = synthetic.misaligned_rig()
    img = _render(cam)
    ref = detect_rim(np.round(img).astype(np.uint8))
    variants = {
        "bgr": np.round(np.dstack([img, 0.9 * img, 0.8 * img])).astype(np.uint8),
        "bgra": np.round(np.dstack([img, img, img, np.full_like(img, 255)])).astype(np.uint8),
        "uint16": np.round(img * 257).astype(np.uint16),
        "float32_unit": (img / 255).astype(np.float32),
        "float64": img,
        "grey_hw1": np.round(img).astype(np.uint8)[:, :, None],
    }
    truth = cam.rim_image_points(1000)
    for name, im in variants.items():
        fit = detect_rim(im)
        assert _rms_to_conic(fit.conic, truth) < 0.05, name
        np.testing.assert_allclose(fit.center, ref.center, atol=0.02, err_msg=name)


def test_detect_rim_noisy_image_degrades_gracefully():
    cam = synthetic.misaligned_rig()
    img = np.round(_render(cam, noise=10.0, seed=4)).astype(np.uint8)
    fit = detect_rim(img)
    assert _rms_to_conic(fit.conic, cam.rim_image_points(1000)) < 0.05


def test_detect_rim_any_circular_rim_strongly_oblique_ellipse():
    """Not tied to the hyperbolic model: an area-true bright ellipse (axis ratio 0.75, any mirror
    seen obliquely) on a dark background with a dark blob off centre."""
    h, w = 420, 560
    center, S = np.array([291.3, 205.8]), np.array([[190.0, 25.0], [25.0, 150.0]])
    Q = conic_from_ellipse(center, S)
    n = 8
    sub = (np.arange(n) + 0.5) / n - 0.5
    ys, xs = np.mgrid[0:h, 0:w].astype(float)
    cover = np.zeros((h, w))
    Sinv = np.linalg.inv(S)
    for dy in sub:
        for dx in sub:
            q = np.stack([xs + dx - center[0], ys + dy - center[1]], -1) @ Sinv.T
            cover += (q**2).sum(-1) < 1
    cover /= n * n
    img = 40 + 160 * cover + 30 * cover * np.sin(xs / 9.0) * np.cos(ys / 13.0)
    img[np.hypot(xs - 270, ys - 215) < 45] = 10
    fit = detect_rim(np.round(img).astype(np.uint8))
    t = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    assert np.abs(fit.distance(center + np.c_[np.cos(t), np.sin(t)] @ S.T)).max() < 0.1
    np.testing.assert_allclose(fit.conic, Q, atol=1e-4)
    np.testing.assert_allclose(fit.center, center, atol=0.05)


def test_detect_rim_real_photo_matches_manual_fit():
    manual = fit_rim(_manual_points(), robust=False)  # the constants are what this gives
    np.testing.assert_allclose(manual.center, MANUAL_CENTER, atol=0.01)
    np.testing.assert_allclose(manual.axes, MANUAL_AXES, atol=0.01)
    img = cv2.imread(str(REAL_PHOTO))
    fit = detect_rim(img)  # no hints
    assert np.linalg.norm(fit.center - np.array(MANUAL_CENTER)) < 4.0
    assert abs(fit.diameter / MANUAL_DIAMETER - 1.0) < 0.01
    # the rim is clipped top and bottom: the detector only used points inside the frame
    assert fit.points[:, 1].min() > 1 and fit.points[:, 1].max() < 1078


@pytest.mark.parametrize("variant", ["half_size_grey", "cropped_more", "flipped_jpeg_q40"])
def test_detect_rim_real_photo_variants_match_manual_fit(variant):
    """The same photograph halved, clipped harder (100 px off top and bottom, 300 px off the
    left), or flipped and recompressed: the rim still matches the manual fit."""
    img = cv2.imread(str(REAL_PHOTO))
    center, diameter = np.array(MANUAL_CENTER), MANUAL_DIAMETER
    if variant == "half_size_grey":
        img = cv2.cvtColor(
            cv2.resize(img, (960, 540), interpolation=cv2.INTER_AREA), cv2.COLOR_BGR2GRAY
        )
        center, diameter = (center + 0.5) / 2 - 0.5, diameter / 2
    elif variant == "cropped_more":
        img = img[100:-100, 300:]
        center = center - (300, 100)
    else:
        _, buf = cv2.imencode(".jpg", img[::-1, ::-1], [cv2.IMWRITE_JPEG_QUALITY, 40])
        img = cv2.imdecode(buf, cv2.IMREAD_COLOR)
        center = np.array([1919.0, 1079.0]) - center
    fit = detect_rim(img)
    scale = diameter / MANUAL_DIAMETER
    assert np.linalg.norm(fit.center - center) < 4.0 * scale
    assert abs(fit.diameter / diameter - 1.0) < 0.01


@pytest.mark.parametrize("scene, noise", [("environment", 0.0), ("room", 8.0)])
def test_detect_rim_on_synthetic_renderer_images(scene, noise):
    """The project's renderer (paper Fig. 6): environment at infinity, and a checker room with
    sensor noise; dark housing and the camera's own reflection in both."""
    render = getattr(synthetic, f"render_{scene}", None)
    if render is None:
        pytest.skip(f"omnicam.synthetic.render_{scene} not available")
    cam = synthetic.misaligned_rig(4.0, 200.0, (-3.0, 3.0, -3.0))
    fit = detect_rim(render(cam, noise=noise, seed=7))
    assert _rms_to_conic(fit.conic, cam.rim_image_points(1000)) < 0.05


@pytest.mark.parametrize(
    "image, match",
    [
        (np.zeros((200, 200), np.uint8), "no ellipse"),
        (np.random.default_rng(0).integers(0, 255, (200, 200)).astype(np.uint8), "no ellipse"),
        (np.zeros((10, 10), np.uint8), "too small"),
        (np.zeros((200, 200, 2), np.uint8), "grey"),
        (np.zeros((200, 200), bool), "dtype"),
        ([[0, 1], [1, 0]], "numpy array"),
    ],
)
def test_detect_rim_bad_input_raises_value_error(image, match):
    with pytest.raises(ValueError, match=match):
        detect_rim(image)


def test_detect_rim_no_circle_in_image_raises():
    """A bright square on dark: edges but no elliptic rim."""
    img = np.full((300, 300), 20, np.uint8)
    img[60:240, 60:240] = 200
    with pytest.raises(ValueError, match="no ellipse"):
        detect_rim(img)


# -- a white holder ring with struts; hints and the expected size --------------------------------
@pytest.fixture(scope="module")
def holder():
    return white_holder_render()


def test_white_holder_render_has_the_holder_edge_outside_the_rim(holder):
    img, cam = holder
    fit_true = fit_rim(cam.rim_image_points(720), robust=False)
    assert 125 < fit_true.axes.mean() < 135
    # the ring outside the rim is the white holder, the room beyond it is darker
    cx, cy = np.rint(fit_true.center).astype(int)
    assert img[cy, cx + 150, 1] == 235 and img[cy, cx + 185, 1] < 110


def test_detect_rim_unguided_takes_a_white_holders_outer_edge(holder):
    """Without a size or a hint, detect_rim looks for a mirror brighter than its housing: in a
    white holder that is the holder's outer edge (calibrate passes the expected size)."""
    assert abs(detect_rim(holder[0]).axes.mean() - 167.0) < 1.5


@pytest.mark.parametrize(
    "kwargs",
    [{"expected": (115.0, 150.0)}, {"expected": 130.0}],
    ids=["expected_range", "expected_radius"],
)
def test_detect_rim_white_holder_finds_the_rim_not_the_holder_edge(holder, kwargs):
    img, cam = holder
    fit = detect_rim(img, **kwargs)
    truth = cam.rim_image_points(2000)
    assert _rms_to_conic(fit.conic, truth) < 0.1
    assert abs(fit.axes.mean() - 129.3) < 0.5  # the holder's edge is at 167 px


def test_detect_rim_white_holder_with_noise(holder):
    img, cam = white_holder_render(noise=4.0, seed=3)
    fit = detect_rim(img, expected=(115.0, 150.0))
    assert _rms_to_conic(fit.conic, cam.rim_image_points(2000)) < 0.1


def test_detect_rim_hint_decides_between_circles(holder):
    """The hint names the circle: near the rim it finds the rim, near the holder's outer edge
    (what the user asked for) the holder's edge."""
    img, cam = holder
    c = fit_rim(cam.rim_image_points(720), robust=False).center
    rim = detect_rim(img, hint=(c[0] + 8, c[1] - 6, 140.0))
    assert _rms_to_conic(rim.conic, cam.rim_image_points(2000)) < 0.1
    edge = detect_rim(img, hint=(c[0], c[1], 160.0))
    assert abs(edge.axes.mean() - 167.0) < 1.5


def test_detect_rim_expected_size_far_off_falls_back_to_any_size():
    """Only short arcs of the expected size (a K for another resolution): the longest arc of
    any size is taken, as without ``expected``."""
    cam = synthetic.misaligned_rig()
    img = np.round(_render(cam)).astype(np.uint8)
    fit = detect_rim(img, expected=(50.0, 65.0))
    assert _rms_to_conic(fit.conic, cam.rim_image_points(2000)) < 0.05


def test_detect_rim_no_rim_near_the_hint_raises(holder):
    img, _ = holder
    with pytest.raises(ValueError, match="hint"):
        detect_rim(img, hint=(60.0, 60.0, 40.0))


@pytest.mark.parametrize(
    "hint, match",
    [
        ((500.0, 200.0, 100.0), "outside"),
        ((200.0, -3.0, 100.0), "outside"),
        ((float("nan"), 200.0, 100.0), "finite"),
        ((200.0, 200.0, float("inf")), "finite"),
        ((200.0, 200.0, 0.0), "positive"),
        ((200.0, 200.0, -5.0), "positive"),
        ((200.0, 200.0, 1000.0), "diagonal"),
        ((200.0, 200.0), r"\(cx, cy, r\)"),
        ("centre", r"\(cx, cy, r\)"),
    ],
)
def test_detect_rim_bad_hint_raises_value_error_naming_hint(holder, hint, match):
    img, _ = holder
    with pytest.raises(ValueError, match="hint") as err:
        detect_rim(img, hint=hint)
    assert err.match(match)


@pytest.mark.parametrize(
    "expected", [(0.0, 10.0), (20.0, 10.0), (float("nan"), 5.0), -3.0, (1.0, 2.0, 3.0), "big"]
)
def test_detect_rim_bad_expected_raises_value_error_naming_it(holder, expected):
    with pytest.raises(ValueError, match="expected"):
        detect_rim(holder[0], expected=expected)


def test_detect_rim_metal_holder_whose_contrast_changes_sign_along_the_rim():
    """A grey ring shading from 90 (left) to 250 (right): the mirror's content near the rim
    (~200) is brighter than the ring on one side and darker on the other."""
    img, cam = white_holder_render(holder=lambda x, y: 90.0 + 160.0 * x / 400.0)
    rim = cam.rim_image_points(2000)
    cx, cy = np.rint(rim.mean(axis=0)).astype(int)
    inside_l, inside_r = img[cy, cx - 120, 1], img[cy, cx + 120, 1]  # mirror near the rim
    ring_l, ring_r = img[cy, cx - 150, 1], img[cy, cx + 150, 1]
    assert ring_l < inside_l - 40 and ring_r > inside_r + 10  # the sign changes
    fit = detect_rim(img, expected=(115.0, 150.0))
    assert _rms_to_conic(fit.conic, rim) < 0.1


def _jagged_disc(jitter, seed=1):
    """A bright disc of radius 100 px whose edge zigzags by up to ``jitter`` px."""
    rng = np.random.default_rng(seed)
    img = np.zeros((320, 320), np.uint8)
    t = np.linspace(0.0, 2.0 * np.pi, 90, endpoint=False)
    r = 100.0 + rng.uniform(-jitter, jitter, len(t))
    cv2.fillPoly(
        img, [np.stack([160 + r * np.cos(t), 160 + r * np.sin(t)], 1).astype(np.int32)], 200
    )
    return img


@pytest.mark.parametrize("jitter", [5.0, 8.0], ids=["too rough", "no ellipse"])
def test_no_private_class_reaches_a_user_through_detect_rim(jitter):
    """Every exception detect_rim raises on a valid image is a ValueError whose classes are
    public names of omnicam (issue 29): a boundary too rough to be a rim is a
    :class:`RimRejected`, an :class:`omnicam.EstimationError` that says what was found."""
    with pytest.raises(ValueError, match="no ellipse found") as err:
        detect_rim(_jagged_disc(jitter))
    for cls in type(err.value).__mro__:
        if cls.__module__.startswith("omnicam"):
            assert not cls.__name__.startswith("_"), cls
            assert (
                getattr(rim_module, cls.__name__, None) is cls
                or getattr(omnicam, cls.__name__) is cls
            )
    if jitter == 5.0:
        assert isinstance(err.value, RimRejected) and isinstance(err.value, omnicam.EstimationError)
        assert isinstance(err.value.fit, RimFit) and 0.3 <= err.value.support <= 1.0
        assert err.value.fit.rms > 1.5 and "px RMS" in str(err.value)
