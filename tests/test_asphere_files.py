"""Calibration files of any mirror: format 2 for an even asphere, format 1 unchanged."""

import numpy as np
import pytest
from asphere_rigs import rig
from conftest import RIGS

import omnicam
from omnicam import MisalignedCatadioptricCamera, MisalignedHyperbolicCamera
from omnicam.formats.calibration_file import FORMAT_VERSION_ASPHERE, MODEL_NAME_ASPHERE


@pytest.mark.parametrize("ext", [".yaml", ".xml", ".json"])
@pytest.mark.parametrize("name", ["sphere", "equiangular 7", "prolate ellipsoid"])
def test_asphere_camera_round_trip_is_exact_in_format_2(tmp_path, ext, name):
    cam = rig(name)
    cam = MisalignedCatadioptricCamera(
        cam.K,
        cam.mirror,
        cam.rvec,
        cam.tvec,
        D=[0.01, -0.002, 0.0, 0.0, 0.0],
        image_size=cam.image_size,
        camera_reflection=(9.0, 12.0),
    )
    path = tmp_path / f"rig{ext}"
    omnicam.save_camera(cam, path)
    loaded = omnicam.load_camera(path)
    assert type(loaded) is MisalignedCatadioptricCamera
    assert loaded.mirror == cam.mirror  # every parameter exact, alpha included
    assert loaded == cam
    text = path.read_text()
    assert MODEL_NAME_ASPHERE in text and "even_asphere" in text
    assert "misaligned_hyperbolic" not in text


def test_format_2_text_names_version_model_and_mirror_kind(tmp_path):
    path = tmp_path / "rig.yaml"
    omnicam.save_camera(rig("equiangular 7"), path)
    text = path.read_text()
    assert f"format_version: {FORMAT_VERSION_ASPHERE}" in text
    assert "model: misaligned_catadioptric" in text and "kind: even_asphere" in text
    assert "alpha:" in text  # the equiangular fit's polynomial terms


def test_a_hyperboloid_saved_through_the_general_class_stays_format_1(tmp_path):
    cam = RIGS["misaligned"]
    general = MisalignedCatadioptricCamera(
        cam.K, cam.mirror, cam.rvec, cam.tvec, cam.D, cam.image_size
    )
    a, b = tmp_path / "a.yaml", tmp_path / "b.yaml"
    cam.save(a)
    omnicam.save_camera(general, b)
    assert a.read_bytes() == b.read_bytes()
    assert "format_version: 1" in a.read_text() and "misaligned_hyperbolic" in a.read_text()
    assert "kind" not in a.read_text()


def test_a_format_1_reader_refuses_a_format_2_file_naming_the_version(tmp_path):
    # the reader of format 1 alone (omnicam 0.4 and before) checks format_version first and
    # says "field 'format_version' is 2; this omnicam reads 1": the version is what it sees
    path = tmp_path / "rig.yaml"
    omnicam.save_camera(rig("sphere"), path)
    from omnicam.formats.filestorage import reading

    r = reading(path, "calibration file")
    assert r.number("format_version") == 2  # what a format 1 reader refuses, first of all
    # and this reader names both versions it reads for any other
    path.write_text(path.read_text().replace("format_version: 2", "format_version: 3"))
    with pytest.raises(ValueError, match=r"'format_version' is 3; this omnicam reads 1 and 2"):
        omnicam.load_camera(path)


def test_hyperbolic_class_load_of_an_asphere_file_says_to_use_load_camera(tmp_path):
    path = tmp_path / "rig.yaml"
    omnicam.save_camera(rig("sphere"), path)
    with pytest.raises(ValueError, match=r"rig\.yaml.*even asphere.*omnicam\.load_camera"):
        MisalignedHyperbolicCamera.load(path)


@pytest.mark.parametrize(
    "edit, field",
    [
        (lambda t: t.replace("kind: even_asphere", "kind: toroid"), "mirror.kind"),
        (
            lambda t: t.replace("model: misaligned_catadioptric", "model: misaligned_hyperbolic"),
            "model",
        ),
        (lambda t: t.replace("   R: 30.", "   R: -30."), "mirror"),
        (lambda t: t.replace("   k: 0.", "   k: zero"), "mirror.k"),
        (
            lambda t: t.replace("kind: even_asphere", "kind: even_asphere\n   alpha: [ a ]"),
            "mirror.alpha",
        ),
    ],
)
def test_format_2_malformed_fields_are_refused_by_name(tmp_path, edit, field):
    path = tmp_path / "rig.yaml"
    omnicam.save_camera(rig("sphere"), path)
    path.write_text(edit(path.read_text()))
    with pytest.raises(ValueError, match=f"field '{field}'"):
        omnicam.load_camera(path)


def test_format_1_file_with_an_asphere_model_tag_is_refused(tmp_path):
    path = tmp_path / "rig.yaml"
    RIGS["misaligned"].save(path)
    path.write_text(path.read_text().replace("misaligned_hyperbolic", "misaligned_catadioptric"))
    with pytest.raises(ValueError, match="field 'model' must be 'misaligned_hyperbolic'"):
        omnicam.load_camera(path)


def test_alpha_of_one_term_round_trips_in_xml(tmp_path):
    m = omnicam.AsphericMirror(30.0, -0.3, 18.0, alpha=(0.01,), vertex_z=40.0)
    cam = rig("sphere")
    cam = MisalignedCatadioptricCamera(cam.K, m, cam.rvec, cam.tvec, image_size=cam.image_size)
    for ext in (".xml", ".yaml", ".json"):
        omnicam.save_camera(cam, tmp_path / f"one{ext}")
        assert omnicam.load_camera(tmp_path / f"one{ext}").mirror.alpha == (0.01,)
    np.testing.assert_array_equal(cam.K, omnicam.load_camera(tmp_path / "one.xml").K)
