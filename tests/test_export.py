"""Central approximations (cv2.omnidir / Kalibr / camodocal / OCamCalib) and their files."""

import math
import re

import cv2
import numpy as np
import pytest

from omnicam import synthetic
from omnicam.formats.central_export import camodocal_text, export
from omnicam.formats.central_fit import (
    F_OMNI,
    fit_ocamcalib,
    fit_omnidir,
    omnidir_project,
    sample_pixels,
)

ALIGNED = synthetic.aligned_rig(image_size=(320, 320))
TILTED = synthetic.misaligned_rig(3.0, 30.0, (3.0, 0.0, 0.0), image_size=(320, 320))


@pytest.fixture(scope="module")
def aligned_fit():
    return fit_omnidir(ALIGNED)


@pytest.fixture(scope="module")
def tilted_fit():
    return fit_omnidir(TILTED)


def _cv_project(fit, dirs):
    Xo = (dirs @ fit.M.T).reshape(1, -1, 3)
    ip, _ = cv2.omnidir.projectPoints(Xo, np.zeros(3), np.zeros(3), fit.K, fit.xi, fit.D)
    return ip.reshape(-1, 2)


def test_numpy_unified_model_is_cv2_omnidir_projectPoints():
    rng = np.random.default_rng(1)
    X = rng.normal(size=(200, 3))
    X[:, 2] = np.abs(X[:, 2]) + 0.1
    K = np.array([[300.0, 1.5, 250.0], [0.0, 310.0, 240.0], [0.0, 0.0, 1.0]])
    D = np.array([[0.1, -0.02, 0.003, 0.004]])
    ours = omnidir_project(X, K, 0.8, D)
    ref, _ = cv2.omnidir.projectPoints(X.reshape(1, -1, 3), np.zeros(3), np.zeros(3), K, 0.8, D)
    np.testing.assert_allclose(ours, ref.reshape(-1, 2), atol=1e-9)


def test_aligned_rig_is_reproduced_by_cv2_omnidir_to_1e6_px(aligned_fit):
    pix, _, d = sample_pixels(ALIGNED, max_points=5000)
    err = np.linalg.norm(_cv_project(aligned_fit, d) - pix, axis=1)
    assert err.max() < 1e-6
    assert aligned_fit.rms_px < 1e-6 and aligned_fit.max_px < 1e-6


def test_aligned_rig_xi_is_the_mirror_eccentricity_formula(aligned_fit):
    # Mei/Geyer-Daniilidis: xi = 2e / (1 + e^2) with e = c / b for the camera at the other focus
    m = ALIGNED.mirror
    e = m.c / m.b
    assert aligned_fit.xi == pytest.approx(2 * e / (1 + e * e), abs=1e-9)
    np.testing.assert_allclose(aligned_fit.D, 0.0, atol=1e-9)
    np.testing.assert_allclose(aligned_fit.origin, [0.0, 0.0, m.c], atol=1e-6)


def test_omnidir_frame_is_a_reflection_of_the_mirror_frame(aligned_fit, tilted_fit):
    for fit in (aligned_fit, tilted_fit):
        np.testing.assert_allclose(fit.M @ fit.M.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(fit.M) == pytest.approx(-1.0, abs=1e-12)
    np.testing.assert_allclose(aligned_fit.M, F_OMNI, atol=1e-9)


def test_to_omnidir_returns_the_six_tuple():
    K, xi, D, M, origin, rms = ALIGNED.to_omnidir()
    assert K.shape == (3, 3) and D.shape == (1, 4) and M.shape == (3, 3) and origin.shape == (3,)
    assert rms < 1e-6 and 0.0 < xi < 1.0


def test_aligned_rig_fit_at_a_depth_maps_those_points_exactly():
    fit = fit_omnidir(ALIGNED, depth=2000.0)
    pix, P, d = sample_pixels(ALIGNED, max_points=3000)
    # points 2 m from the viewpoint along each ray
    w = P - fit.origin
    b = np.einsum("ij,ij->i", w, d)
    t = -b + np.sqrt(b * b - (np.einsum("ij,ij->i", w, w) - 2000.0**2))
    X = P + t[:, None] * d
    np.testing.assert_allclose(np.linalg.norm(X - fit.origin, axis=1), 2000.0)
    assert np.abs(fit.project(X) - pix).max() < 1e-6


def test_tilted_rig_states_its_error_honestly(tilted_fit):
    """The stated RMS/max are what cv2.omnidir gives on every mirror pixel, and no direct
    least-squares fit of all 13 parameters from another start does better."""
    from scipy.optimize import least_squares

    epix, _, ed = sample_pixels(TILTED, max_points=10**6)
    err = np.linalg.norm(_cv_project(tilted_fit, ed) - epix, axis=1)
    assert tilted_fit.rms_px == pytest.approx(float(np.sqrt(np.mean(err**2))), rel=1e-6)
    assert tilted_fit.max_px == pytest.approx(float(err.max()), rel=1e-6)
    assert tilted_fit.rms_px > 1e-3  # a non-central rig is not central: it costs something

    # the direct fit: numerical Jacobian, start from the aligned rig's model
    pix, _, d = sample_pixels(TILTED, max_points=3000)
    a = fit_omnidir(ALIGNED)
    p0 = np.array([a.K[0, 0], a.K[1, 1], 0.0, a.K[0, 2], a.K[1, 2], a.xi, 0, 0, 0, 0, 0, 0, 0])
    Y = (d @ F_OMNI.T).reshape(1, -1, 3)

    def resid(p):
        K = np.array([[p[0], p[2], p[3]], [0.0, p[1], p[4]], [0.0, 0.0, 1.0]])
        ip, _ = cv2.omnidir.projectPoints(
            Y, p[10:13].copy(), np.zeros(3), K, float(p[5]), p[6:10].reshape(1, 4).copy()
        )
        return (ip.reshape(-1, 2) - pix).ravel()

    direct = least_squares(resid, p0, method="trf", x_scale="jac", xtol=1e-12, ftol=1e-12)
    direct_rms = float(np.sqrt(np.mean(direct.fun**2) * 2))  # per-point distance
    ours = np.linalg.norm(_cv_project(tilted_fit, d) - pix, axis=1)
    ours_rms = float(np.sqrt(np.mean(ours**2)))
    assert ours_rms <= direct_rms * 1.01 + 1e-9


def test_kalibr_camchain_reads_back_with_the_fit_and_its_errors(tmp_path):
    from omnicam.formats.other_tools import parse_yaml

    path = tmp_path / "camchain.yaml"
    fit = export(TILTED, "kalibr", path)
    doc = parse_yaml(path.read_text())
    cam = doc["cam0"]
    assert cam["camera_model"] == "omni" and cam["distortion_model"] == "radtan"
    xi, fu, fv, pu, pv = cam["intrinsics"]
    assert (xi, fu, fv, pu, pv) == pytest.approx(
        (fit.xi, fit.K[0, 0], fit.K[1, 1], fit.K[0, 2], fit.K[1, 2]), rel=1e-15
    )
    assert cam["distortion_coeffs"] == pytest.approx(np.ravel(fit.D).tolist(), rel=1e-15)
    assert cam["resolution"] == [320, 320]
    text = path.read_text()
    m = re.search(r"RMS (\S+) px, max (\S+) px", text)
    assert float(m.group(1)) == pytest.approx(fit.rms_px, rel=1e-2)
    assert float(m.group(2)) == pytest.approx(fit.max_px, rel=1e-2)


def test_camodocal_yaml_is_read_by_cv2_filestorage(tmp_path):
    path = tmp_path / "camera.yaml"
    fit = export(ALIGNED, "camodocal", path)
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert fs.getNode("model_type").string() == "MEI"
    assert fs.getNode("mirror_parameters").getNode("xi").real() == pytest.approx(fit.xi)
    proj = fs.getNode("projection_parameters")
    assert proj.getNode("gamma1").real() == pytest.approx(fit.K[0, 0])
    assert proj.getNode("v0").real() == pytest.approx(fit.K[1, 2])
    assert fs.getNode("image_width").real() == 320
    fs.release()
    assert "RMS" in path.read_text()


def test_skewed_fit_is_refused_by_skew_free_formats(tilted_fit):
    fit = tilted_fit
    if abs(fit.K[0, 1]) < 1e-9:
        pytest.skip("the fit has no skew")
    with pytest.raises(ValueError, match="skew"):
        camodocal_text(fit, (320, 320))


def _read_ocam(path):
    """calib_results.txt as ocam_functions.cpp's get_ocam_model reads it (C transliteration)."""
    lines = path.read_text().splitlines()
    nums = [ln for ln in lines if ln.strip() and not ln.startswith("#")]
    pol = [float(v) for v in nums[0].split()]
    inv = [float(v) for v in nums[1].split()]
    xc, yc = (float(v) for v in nums[2].split())
    c, d, e = (float(v) for v in nums[3].split())
    h, w = (int(v) for v in nums[4].split())
    assert int(pol[0]) == len(pol) - 1 and int(inv[0]) == len(inv) - 1
    return pol[1:], inv[1:], xc, yc, c, d, e, (w, h)


def _world2cam_c(P, invpol, xc, yc, c, d, e):
    out = []
    for X, Y, Z in P:
        norm = math.sqrt(X * X + Y * Y)
        theta = math.atan(Z / norm)
        rho, t_i = invpol[0], 1.0
        for a in invpol[1:]:
            t_i *= theta
            rho += t_i * a
        x, y = X / norm * rho, Y / norm * rho
        out.append((x * e + y + yc, x * c + y * d + xc))  # (column, row)
    return np.array(out)


def test_ocamcalib_file_reproduces_the_aligned_rig(tmp_path):
    path = tmp_path / "calib_results.txt"
    fit = export(ALIGNED, "ocamcalib", path)
    pol, inv, xc, yc, c, d, e, size = _read_ocam(path)
    assert size == (320, 320)
    pix, _, dirs = sample_pixels(ALIGNED, max_points=2000)
    keep = np.hypot(dirs[:, 0], dirs[:, 1]) > 1e-9
    got = _world2cam_c(dirs[keep] @ fit.M.T, inv, xc, yc, c, d, e)
    err = np.linalg.norm(got - pix[keep], axis=1)
    assert err.max() < 0.01
    assert fit.world2cam_max_px < 0.01 and fit.cam2world_max_px < 0.05
    assert pol[1] == 0.0 and pol[0] < 0  # OCamCalib's a1 = 0 and its frame's sign


def test_ocamcalib_error_figures_are_measured_on_the_tilted_rig(tmp_path):
    fit = fit_ocamcalib(TILTED)
    from omnicam.formats.central_fit import ocam_world2cam

    epix, _, ed = sample_pixels(TILTED, max_points=10**6)
    err = np.linalg.norm(
        ocam_world2cam(ed @ fit.M.T, fit.invpol, fit.xc, fit.yc, fit.c, fit.d, fit.e) - epix, axis=1
    )
    assert fit.world2cam_rms_px == pytest.approx(float(np.sqrt(np.mean(err**2))), rel=1e-6)
    assert fit.world2cam_max_px == pytest.approx(float(err.max()), rel=1e-6)
    # no tangential terms in Scaramuzza's model: the tilted rig costs more than with omnidir
    assert fit.world2cam_rms_px > fit_omnidir(TILTED, skew=False).rms_px


def test_omnidir_file_round_trips_through_filestorage(tmp_path, aligned_fit):
    path = tmp_path / "omni.yaml"
    export(ALIGNED, "omnidir", path)
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    np.testing.assert_allclose(fs.getNode("K").mat(), aligned_fit.K, atol=1e-9)
    assert fs.getNode("xi").real() == pytest.approx(aligned_fit.xi, abs=1e-12)
    np.testing.assert_allclose(fs.getNode("M").mat(), aligned_fit.M, atol=1e-9)
    assert fs.getNode("rms_px").real() < 1e-6
    fs.release()


def test_export_refuses_unknown_format(tmp_path):
    with pytest.raises(ValueError, match="fmt"):
        export(ALIGNED, "fisheye", tmp_path / "x.yaml")


@pytest.mark.parametrize(
    "fmt, name",
    [
        ("omnidir", "omni.yaml"),
        ("kalibr", "camchain.yaml"),
        ("camodocal", "mei.yaml"),
        ("ocamcalib", "calib_results.txt"),
    ],
)
def test_cli_export_writes_the_file_and_prints_its_error(tmp_path, capsys, fmt, name):
    from omnicam.cli import main

    calib = tmp_path / "rig.yaml"
    ALIGNED.save(calib)
    out = tmp_path / name
    assert main(["export", str(calib), "--to", fmt, "-o", str(out)]) == 0, capsys.readouterr().err
    printed = capsys.readouterr().out
    assert out.exists() and "RMS" in printed and "max" in printed
    assert main(["export", str(calib), "--to", fmt, "-o", str(out)]) == 1  # exists
    assert "exists" in capsys.readouterr().err


# A YAML 1.1 float as PyYAML (so Kalibr) resolves it (yaml/resolver.py's implicit float rule,
# base 10): a point is required, and an exponent needs its sign. Anything else is an int or a
# string, which Kalibr's ConfigReader refuses ("invalid focalLength", "invalid principalPoint").
YAML11_FLOAT = re.compile(r"[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+][0-9]+)?")
YAML11_INT = re.compile(r"[-+]?(?:0|[1-9][0-9_]*)")


def _flow_numbers(text, key):
    return re.search(rf"^\s*{key}: \[(.*)\]$", text, re.MULTILINE).group(1).split(", ")


@pytest.mark.parametrize(
    "value, text",
    [
        (500.0, "500.0"),
        (0.0, "0.0"),
        (-0.0, "-0.0"),
        (1e-05, "1.0e-05"),
        (1.5e-05, "1.5e-05"),
        (1e16, "1.0e+16"),
        (-2.5e300, "-2.5e+300"),
        (0.1, "0.1"),
        (1 / 3, "0.3333333333333333"),
    ],
)
def test_numbers_are_written_as_yaml_floats_that_read_back_exactly(value, text):
    from omnicam.formats.central_export import _fmt

    assert _fmt(value) == text
    assert YAML11_FLOAT.fullmatch(_fmt(value)) and float(_fmt(value)) == value


def test_a_non_finite_number_is_refused_not_written():
    from omnicam.formats.central_export import _fmt

    with pytest.raises(ValueError, match="non-finite"):
        _fmt(math.nan)


def test_kalibr_whole_number_intrinsics_are_floats_and_resolution_integers():
    from omnicam.formats.central_export import kalibr_text
    from omnicam.formats.central_fit import OmnidirFit
    from omnicam.formats.other_tools import parse_yaml

    K = np.array([[500.0, 0.0, 160.0], [0.0, 500.0, 160.0], [0.0, 0.0, 1.0]])
    fit = OmnidirFit(K, 1.0, np.zeros((1, 4)), F_OMNI, np.zeros(3), 0.0, 0.0, 100)
    text = kalibr_text(fit, (320, 320))
    numbers = _flow_numbers(text, "intrinsics") + _flow_numbers(text, "distortion_coeffs")
    assert numbers == ["1.0", "500.0", "500.0", "160.0", "160.0"] + ["0.0"] * 4
    assert all(YAML11_FLOAT.fullmatch(t) and not YAML11_INT.fullmatch(t) for t in numbers)
    assert all(YAML11_INT.fullmatch(t) for t in _flow_numbers(text, "resolution"))
    cam = parse_yaml(text)["cam0"]
    assert all(type(v) is float for v in cam["intrinsics"] + cam["distortion_coeffs"])
    assert all(type(v) is int for v in cam["resolution"])


def test_kalibr_file_of_a_fit_has_only_yaml_floats_exact_to_the_bit(tmp_path):
    path = tmp_path / "camchain.yaml"
    fit = export(TILTED, "kalibr", path)
    text = path.read_text()
    numbers = _flow_numbers(text, "intrinsics") + _flow_numbers(text, "distortion_coeffs")
    assert all(YAML11_FLOAT.fullmatch(t) for t in numbers)
    want = [fit.xi, fit.K[0, 0], fit.K[1, 1], fit.K[0, 2], fit.K[1, 2], *np.ravel(fit.D)]
    assert [float(t) for t in numbers] == want


def test_camodocal_numbers_are_floats_too(tmp_path):
    text = camodocal_text(fit_omnidir(ALIGNED, skew=False), (320, 320))
    values = re.findall(r"^\s+(?:xi|k1|k2|p1|p2|gamma1|gamma2|u0|v0): (\S+)$", text, re.MULTILINE)
    assert len(values) == 9 and all(YAML11_FLOAT.fullmatch(t) for t in values)


def test_an_export_far_from_the_rig_warns_naming_the_best_format(tmp_path):
    path = tmp_path / "calib_results.txt"
    with pytest.warns(RuntimeWarning, match="ocamcalib export is off") as caught:
        fit = export(TILTED, "ocamcalib", path)
    assert path.exists()  # written all the same
    message = str(caught[0].message)
    rms = max(fit.world2cam_rms_px, fit.cam2world_rms_px)
    assert rms > 0.5  # the 3 degree, 3 mm rig: Scaramuzza's model has no tangential term
    assert f"RMS {rms:.3g} px" in message
    best = fit_omnidir(TILTED)  # what the message names, measured the same way
    assert best.rms_px < 0.5 and best.max_px < 1.0
    assert f"best is omnidir (cv2.omnidir, with skew): RMS {best.rms_px:.3g} px" in message
    assert "remap tables" in message and "omnicam maps" in message


@pytest.mark.parametrize("fmt", ["omnidir", "kalibr"])
def test_an_export_within_a_pixel_does_not_warn(tmp_path, fmt):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fit = export(TILTED, fmt, tmp_path / "x.yaml")
    assert fit.rms_px <= 0.5 and fit.max_px <= 1.0


def test_ocamcalib_states_the_pixels_cam2world_sends_above_the_rim():
    from omnicam.formats.central_fit import ocam_cam2world

    fit = fit_ocamcalib(TILTED)
    epix, _, _ = sample_pixels(TILTED, max_points=10**6)
    back = ocam_cam2world(epix, fit.pol, fit.xc, fit.yc, fit.c, fit.d, fit.e) @ fit.M
    unseen = ~np.isfinite(TILTED.project_directions(back)).all(axis=1)
    assert fit.cam2world_unseen == unseen.sum() > 0
    # they are the rim's own pixels: the model's horizon is a little above the mirror's
    rim = TILTED.rim_image_points(3600)
    gap = np.linalg.norm(epix[unseen][:, None, :] - rim[None], axis=2).min(axis=1)
    assert gap.max() < 3.0
    line = fit.summary()
    assert f"over {fit.n_points - fit.cam2world_unseen} pixels" in line
    assert f"at {fit.cam2world_unseen} more, next to the rim" in line
    assert "above the mirror's rim" in line
