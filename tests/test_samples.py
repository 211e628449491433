"""Shipped calibration files: loadable, and the package copies equal the top-level source."""

import pathlib

import pytest

import omnicam
from omnicam import synthetic

ROOT = pathlib.Path(__file__).resolve().parent.parent


def test_every_calib_file_is_shipped_identically_in_the_package():
    source = sorted((ROOT / "calib_files").glob("*.yaml"))
    assert [p.stem for p in source] == omnicam.samples.names()
    for p in source:
        with omnicam.samples.path(p.stem) as shipped:
            assert pathlib.Path(shipped).read_bytes() == p.read_bytes()


def test_sample_files_are_the_canonical_rigs():
    assert omnicam.samples.load("hyperomni_aligned") == synthetic.aligned_rig()
    assert omnicam.samples.load("hyperomni_misaligned") == synthetic.misaligned_rig()


def test_unknown_sample_name_raises_value_error():
    with pytest.raises(ValueError, match="hyperomni_aligned"):
        omnicam.samples.load("nope")
