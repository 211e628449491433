"""The command line with any mirror of revolution: the mirror options, format 2 files, info,
--from, the views and the exports."""

from __future__ import annotations

import json

import numpy as np
import pytest
from asphere_rigs import rig

import omnicam
import omnicam.formats.calibration_file
from omnicam.asphere import AsphericMirror
from omnicam.cli import main
from omnicam.formats.central_fit import fit_ocamcalib, fit_omnidir


def _k_args(cam):
    K = cam.K
    return [
        "--fx",
        repr(float(K[0, 0])),
        "--fy",
        repr(float(K[1, 1])),
        "--cx",
        repr(float(K[0, 2])),
        "--cy",
        repr(float(K[1, 2])),
    ]


@pytest.fixture(scope="module")
def sphere(tmp_path_factory):
    """A misaligned spherical rig: its format 2 file, its rim pixels and an image."""
    import cv2

    from omnicam.synthetic import render_environment

    folder = tmp_path_factory.mktemp("sphere")
    cam = rig("sphere")
    omnicam.save_camera(cam, folder / "rig2.yaml")
    pts = cam.rim_image_points(300) + np.random.default_rng(0).normal(0, 0.2, (300, 2))
    (folder / "rim.json").write_text(json.dumps(pts.tolist()))
    cv2.imwrite(str(folder / "dome.png"), render_environment(cam, supersample=1, seed=0))
    return cam, folder


def test_info_shows_the_mirror_kind_and_parameters_of_a_format_2_file(sphere, capsys):
    cam, folder = sphere
    assert main(["info", str(folder / "rig2.yaml")]) == 0
    out = capsys.readouterr().out
    assert "even asphere: R = 30 mm, k = 0" in out and "vertex at Z = 40 mm" in out
    assert "rim radius = 18 mm" in out and "format_version 2" in out
    assert "from the nominal camera position (0, 0, 0)" in out
    assert "omnidir" in out and "px RMS" in out


@pytest.mark.parametrize(
    "mirror_args",
    [
        ["--sphere", "30", "18", "--vertex-z", "40"],
        ["--asphere", "30", "0", "18", "--vertex-z", "40"],
        ["--mirror-file", "{folder}/rig2.yaml"],
    ],
    ids=["sphere", "asphere", "mirror-file"],
)
def test_calibrate_a_sphere_from_its_data_writes_format_2(sphere, tmp_path, capsys, mirror_args):
    cam, folder = sphere
    out = tmp_path / "out.yaml"
    argv = [str(folder / "dome.png"), *[a.format(folder=folder) for a in mirror_args]]
    argv += [*_k_args(cam), "--boundary-points", str(folder / "rim.json"), "-o", str(out)]
    assert main(["calibrate", *argv]) == 0, capsys.readouterr().err
    got = omnicam.load_camera(out)
    assert got.mirror == cam.mirror
    assert "format_version: 2" in out.read_text()
    axis, _ = omnicam.gauge.posture_error(got, cam)
    assert axis < 1.0


def test_calibrate_from_a_format_2_file(sphere, tmp_path, capsys):
    cam, folder = sphere
    out = tmp_path / "new.yaml"
    argv = ["calibrate", str(folder / "dome.png"), "--from", str(folder / "rig2.yaml")]
    assert main([*argv, "-o", str(out)]) == 0, capsys.readouterr().err
    assert "the posture differs from its by" in capsys.readouterr().out
    assert omnicam.load_camera(out).mirror == cam.mirror


def test_equiangular_option_is_the_constructor():
    import argparse

    from omnicam.cli.mirror_args import add_mirror_options, mirror_of_args

    p = argparse.ArgumentParser()
    p.add_argument("--mirror", nargs=3, type=float)
    add_mirror_options(p)
    args = p.parse_args(["--equiangular", "7", "30", "8"])
    assert mirror_of_args(args) == AsphericMirror.equiangular(7.0, 30.0, 8.0)
    assert mirror_of_args(p.parse_args(["--mirror", "1", "2", "3"])) is None  # --mirror's own


@pytest.mark.parametrize(
    "extra, words",
    [
        (["--mirror", "23.4", "28.1", "30", "--sphere", "30", "18"], "one mirror"),
        (["--sphere", "30", "18", "--paraboloid", "20", "25"], "one mirror"),
        (["--sphere", "30", "18", "--alpha", "0.1"], "--alpha goes with --asphere"),
        (["--mirror", "23.4", "28.1", "30", "--vertex-z", "3"], "--vertex-z goes with"),
        (["--sphere", "30", "40"], "--sphere: RIM must be below"),
        (["--asphere", "30", "0", "18", "--alpha", "-50"], "--asphere: alpha"),
        (["--mirror-file", "missing.yaml"], "--mirror-file: mirror file missing.yaml"),
    ],
)
def test_bad_mirror_options_are_one_line(sphere, tmp_path, capsys, extra, words):
    cam, folder = sphere
    argv = [
        "calibrate",
        str(folder / "dome.png"),
        *extra,
        *_k_args(cam),
        "-o",
        str(tmp_path / "o.yaml"),
    ]
    assert main(argv) != 0
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1
    assert not (tmp_path / "o.yaml").exists()


def test_mirror_options_are_refused_beside_from(sphere, tmp_path, capsys):
    cam, folder = sphere
    argv = [
        "calibrate",
        str(folder / "dome.png"),
        "--from",
        str(folder / "rig2.yaml"),
        "--sphere",
        "30",
        "18",
        "-o",
        str(tmp_path / "o.yaml"),
    ]
    assert main(argv) == 2
    assert "do not give --sphere with it" in capsys.readouterr().err


@pytest.mark.parametrize(
    "extra, words",
    [
        (["--rim-radius", "18"], "--sphere gives the rim's radius"),
        (["--mirror", "23.4", "28.1", "30"], "give one mirror, not --sphere and --mirror"),
    ],
)
def test_a_mirror_beside_chessboards_is_one_mirror_that_gives_the_scale(
    sphere, tmp_path, capsys, extra, words
):
    cam, folder = sphere
    argv = ["calibrate", "--chessboard", "9x6", "--square", "25", str(folder / "dome.png")]
    assert main([*argv, "--sphere", "30", "18", *extra, "-o", str(tmp_path / "o.yaml")]) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1
    assert not (tmp_path / "o.yaml").exists()


def test_chessboards_with_a_sphere_data_sheet_calibrate_its_rig(sphere, tmp_path):
    """A data sheet of any mirror beside --chessboard (issue 28 item 4), as --mirror's: held
    (the boards trade the focal length with a sphere's radius), its rim's radius the scale, a
    format 2 file, the rays within 3x their stated std. The corners come from a file (the rim
    from the images)."""
    import shutil

    from omnicam.chessboard.board_pose import object_points
    from omnicam.synthetic import boards

    cam, folder = sphere
    pattern, square = (7, 5), 25.0
    rng = np.random.default_rng(3)
    poses = boards.random_board_poses(
        cam, 8, pattern, square, distance=(150.0, 400.0), max_tilt_deg=35.0, rng=rng, body=None
    )
    obj = object_points(pattern, square)
    corners, paths = [], []
    for i, (rvec, tvec) in enumerate(poses):
        corners.append((cam.project(obj, rvec, tvec) + rng.normal(0, 0.15, (len(obj), 2))).tolist())
        paths.append(str(tmp_path / f"b{i}.png"))
        shutil.copy(folder / "dome.png", paths[-1])
    (tmp_path / "c.json").write_text(json.dumps(corners))
    out = tmp_path / "rig.yaml"
    sheet = ["--sphere", "30", "18", "--vertex-z", "40"]
    argv = ["calibrate", "--chessboard", "7x5", "--square", "25", *paths, *sheet, "-q"]
    argv += ["--corners", str(tmp_path / "c.json"), "--heldout", "0", "-o", str(out)]
    assert main(argv) == 0
    fitted = omnicam.load_camera(out)
    assert isinstance(fitted.mirror, AsphericMirror) and fitted.mirror.rim_radius == 18.0
    assert fitted.mirror.R == 30.0
    assert fitted.K[0, 0] == pytest.approx(cam.K[0, 0], rel=0.05)
    grid = np.stack(np.meshgrid(np.arange(130, 510, 15.0), np.arange(50, 430, 15.0)), -1)
    _, d_true = cam.unproject(grid.reshape(-1, 2))
    _, d_fit = fitted.unproject(grid.reshape(-1, 2))
    ok = np.isfinite(d_true).all(1) & np.isfinite(d_fit).all(1)
    assert ok.sum() > 200
    err = np.degrees(np.arccos(np.clip(np.sum(d_true[ok] * d_fit[ok], 1), -1.0, 1.0)))
    median_std, worst_std = omnicam.formats.calibration_file.read_verdict(out).ray_std_deg
    assert np.median(err) < 3.0 * median_std and err.max() < 3.0 * worst_std


def test_guess_k_with_a_mirror_that_does_not_say_where_the_camera_sits(sphere, tmp_path, capsys):
    cam, folder = sphere
    argv = [
        "calibrate",
        str(folder / "dome.png"),
        "--sphere",
        "30",
        "18",
        "--guess-k",
        "--boundary-points",
        str(folder / "rim.json"),
        "-o",
        str(tmp_path / "o.yaml"),
    ]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "--guess-k" in err and "does not say where the camera sits" in err
    assert "--vertex-z" in err


def test_mirror_file_of_the_mirror_alone(tmp_path):
    from omnicam.formats.calibration_file import read_mirror

    (tmp_path / "m.yaml").write_text(
        "%YAML:1.0\n---\nmirror:\n   kind: even_asphere\n   R: 30.\n   k: 0.\n"
        "   vertex_z: 40.\n   rim_radius: 18.\n"
    )
    assert read_mirror(tmp_path / "m.yaml") == AsphericMirror.sphere(30.0, 18.0, vertex_z=40.0)
    (tmp_path / "h.json").write_text('{"mirror": {"a": 23.4, "b": 28.1, "rim_radius": 30}}')
    assert read_mirror(tmp_path / "h.json") == omnicam.HyperbolicMirror(23.4, 28.1, 30.0)
    (tmp_path / "t.json").write_text('{"mirror": {"kind": "toroid"}}')
    with pytest.raises(ValueError, match="field 'mirror.kind' must be one of"):
        read_mirror(tmp_path / "t.json")


@pytest.mark.parametrize("target", ["omnidir", "kalibr", "camodocal", "ocamcalib"])
def test_export_of_an_asphere_rig_states_a_finite_error(sphere, tmp_path, capsys, target):
    cam, folder = sphere
    out = tmp_path / ("out.txt" if target == "ocamcalib" else "out.yaml")
    argv = ["export", str(folder / "rig2.yaml"), "--to", target, "-o", str(out)]
    assert main(argv) == 0, capsys.readouterr().err
    text = capsys.readouterr().out
    assert "RMS" in text and "max" in text and "nan" not in text.lower()
    assert out.stat().st_size > 0


def test_central_fits_of_asphere_rigs_are_finite():
    for name in ("sphere", "equiangular 7", "paraboloid"):
        cam = rig(name)
        om = fit_omnidir(cam)
        assert np.isfinite(om.rms_px) and np.isfinite(om.max_px)
        oc = fit_ocamcalib(cam, omnidir=om)
        assert np.isfinite(oc.world2cam_rms_px) and np.isfinite(oc.cam2world_rms_px)


def test_views_of_a_format_2_file(sphere, tmp_path, capsys):
    cam, folder = sphere
    argv = [
        "unwarp",
        str(folder / "dome.png"),
        "-c",
        str(folder / "rig2.yaml"),
        "--panorama",
        "400x100",
        "-o",
        str(tmp_path / "pano.png"),
    ]
    assert main(argv) == 0, capsys.readouterr().err
    argv = [
        "maps",
        str(folder / "rig2.yaml"),
        "--perspective",
        "120x90",
        "--fov",
        "60",
        "--npy",
        "-o",
        str(tmp_path / "m"),
    ]
    assert main(argv) == 0, capsys.readouterr().err
    assert (tmp_path / "pano.png").stat().st_size > 0


def test_report_page_of_a_format_2_file(sphere, tmp_path, capsys):
    cam, folder = sphere
    page = tmp_path / "p.html"
    argv = ["report", str(folder / "rig2.yaml"), str(folder / "dome.png"), "-o", str(page)]
    assert main(argv) == 0, capsys.readouterr().err
    assert "even asphere" in page.read_text()
