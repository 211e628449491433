"""The HTML report (omnicam.html_report, omnicam report, omnicam calibrate --report): one
self-contained page with every section, every embedded image decodable, nothing external."""

from __future__ import annotations

import base64
import re

import cv2
import numpy as np
import pytest

import omnicam
from omnicam import synthetic
from omnicam.calibration import calibrate
from omnicam.cli import main
from omnicam.formats.intrinsics import write_intrinsics
from omnicam.formats.point_files import write_far_lines
from omnicam.html_report import (
    IMAGE_SECTIONS,
    PATTERN_SECTIONS,
    image_report_html,
    pattern_report_html,
    write_report,
)
from omnicam.html_report.redetect import redetected_pattern_report
from omnicam.synthetic import boards
from omnicam.synthetic.demo import demo_environment, demo_far_lines

PATTERN, SQUARE = (7, 5), 60.0
SIZE = (480, 480)
RIG = synthetic.misaligned_rig(3.0, 30.0, (1.5, -2.0, 1.9), image_size=SIZE)
_URI = re.compile(r'src="data:image/(png|jpeg);base64,([A-Za-z0-9+/=]+)"')


def check_page(page, sections):
    """The page's sections in order, no external reference, every image a decodable data
    URI; returns the decoded images."""
    ids = re.findall(r'<section id="([a-z-]+)">', page)
    assert tuple(ids) == tuple(sections)
    assert page.startswith("<!DOCTYPE html>") and page.rstrip().endswith("</html>")
    assert not re.search(r"https?://", page)
    assert not re.search(r"<(script|link|iframe)\b", page)
    srcs = re.findall(r'\bsrc="([^"]*)"', page)
    uris = _URI.findall(page)
    assert srcs and len(uris) == len(srcs)  # every image is embedded
    decoded = []
    for kind, data in uris:
        img = cv2.imdecode(np.frombuffer(base64.b64decode(data), np.uint8), cv2.IMREAD_COLOR)
        assert img is not None and img.size > 0, kind
        decoded.append(img)
    return decoded


@pytest.fixture(scope="module")
def chessboard(tmp_path_factory):
    """Six board views, their calibration (3-fold held-out) and its file."""
    folder = tmp_path_factory.mktemp("report-boards")
    poses = boards.random_board_poses(
        RIG, 6, PATTERN, SQUARE, distance=(350.0, 700.0), max_tilt_deg=40.0, rng=11
    )
    images = [boards.render_board(RIG, PATTERN, SQUARE, *p, supersample=2) for p in poses]
    paths = []
    for i, im in enumerate(images):
        paths.append(str(folder / f"board{i}.png"))
        cv2.imwrite(paths[-1], im)
    camera, report = omnicam.MisalignedHyperbolicCamera.calibrate_pattern(
        images, PATTERN, SQUARE, RIG.mirror, dist_model="none", heldout=3
    )
    calib = folder / "rig.yaml"
    camera.save(calib, report)
    return {"images": images, "paths": paths, "camera": camera, "report": report, "calib": calib}


@pytest.fixture(scope="module")
def one_image(tmp_path_factory):
    """One image of the demo scene (far lines drawn in), its K and far-line files."""
    folder = tmp_path_factory.mktemp("report-one")
    truth = synthetic.misaligned_rig(3.0, 30.0, (1.5, -1.0, 1.0), image_size=(400, 400))
    image = synthetic.render_environment(truth, demo_environment(), supersample=2, seed=1)
    path = folder / "mirror.png"
    cv2.imwrite(str(path), image)
    lines = demo_far_lines(truth)
    write_far_lines(folder / "lines.json", lines)
    write_intrinsics(folder / "k.yaml", truth.K, None, truth.image_size)
    return {
        "truth": truth,
        "image": image,
        "path": str(path),
        "lines": lines,
        "folder": folder,
    }


def test_chessboard_page_has_every_section_and_only_embedded_images(chessboard):
    names = [f"board{i}.png" for i in range(6)]
    page = pattern_report_html(
        chessboard["camera"],
        chessboard["report"],
        chessboard["images"],
        names=names,
        pattern_size=PATTERN,
    )
    images = check_page(page, PATTERN_SECTIONS)
    assert len(images) >= 8
    # the per-view table, the held-out errors beside cv2.omnidir's, the stated uncertainty
    assert "board5.png" in page and "cv2.omnidir held-out px" in page
    held = chessboard["report"].heldout
    assert f"{held.rms[0]:.3f}" in page and f"{held.omnidir[0]:.3f}" in page
    assert f"median {chessboard['report'].ray_std_deg[0]:.3f} deg" in page
    assert "No colour map" in page  # said why, not left out silently
    assert re.search(r"magnified \d+ times", page)  # the residuals' scale is stated


def test_image_page_shows_the_four_candidates_and_the_choice(one_image):
    camera, report = calibrate(
        one_image["truth"].K,
        one_image["truth"].mirror,
        image=one_image["image"],
        far_lines=one_image["lines"],
    )
    page = image_report_html(camera, report, one_image["image"])
    check_page(page, IMAGE_SECTIONS)
    for i in range(4):
        assert f"[{i}] l=" in page
    assert f"[{report.chosen}] " in page and "CHOSEN" in page
    assert f"confidence {report.confidence:.4f}" in page
    assert "far lines (drawn in colour)" in page


def test_write_report_is_atomic_and_refuses_to_overwrite_unless_told(tmp_path):
    path = tmp_path / "page.html"
    write_report(path, "<!DOCTYPE html><html></html>")
    with pytest.raises(omnicam._atomic.OutputError, match="exists"):
        write_report(path, "other", overwrite=False)
    assert path.read_text() == "<!DOCTYPE html><html></html>"
    assert [p.name for p in tmp_path.iterdir()] == ["page.html"]


def test_redetected_report_keeps_the_camera_and_names_the_views_without_a_board(chessboard):
    verdict = omnicam.read_verdict(chessboard["calib"])
    blank = np.full_like(chessboard["images"][0], 128)
    images = [chessboard["images"][0], blank, *chessboard["images"][1:]]
    rep = redetected_pattern_report(chessboard["camera"], images, PATTERN, SQUARE, verdict=verdict)
    assert sorted(rep.view_rms) == [0, 2, 3, 4, 5, 6]
    assert rep.dropped == {1: "no board found"}
    page = pattern_report_html(chessboard["camera"], rep, images, pattern_size=PATTERN)
    check_page(page, PATTERN_SECTIONS)
    assert "dropped: no board found" in page
    # the poses fitted alone under the calibrated camera reproduce the adjustment's residuals
    assert rep.rms == pytest.approx(chessboard["report"].rms, abs=0.05)
    assert rep.std["axis_deg"] == pytest.approx(verdict.axis_std_deg)
    assert rep.camera is chessboard["camera"]


def test_cli_report_of_a_chessboard_calibration(chessboard, tmp_path, capsys):
    page = tmp_path / "rig.html"
    args = ["report", str(chessboard["calib"]), *chessboard["paths"], "-o", str(page)]
    assert main(args) == 2  # the file does not record the board
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--chessboard COLSxROWS --square MM" in err
    assert main([*args, "--chessboard", "7x5", "--square", "60"]) == 0
    assert "6 of 6 boards found" in capsys.readouterr().out
    text = page.read_text()
    check_page(text, PATTERN_SECTIONS)
    assert "from the calibration file" in text  # held-out figures: the file's
    assert main([*args, "--chessboard", "7x5", "--square", "60"]) == 1  # exists
    assert "exists; pass --overwrite" in capsys.readouterr().err


def test_cli_calibrate_report_option_for_one_image(one_image, tmp_path, capsys):
    f = one_image["folder"]
    base = [
        "calibrate",
        one_image["path"],
        "--intrinsics",
        str(f / "k.yaml"),
        "--mirror",
        "23.4",
        "28.1",
        "30",
        "--far-lines",
        str(f / "lines.json"),
        "-o",
        str(tmp_path / "rig.yaml"),
    ]
    assert main([*base, "--report", str(tmp_path / "rig.txt")]) == 1
    err = capsys.readouterr().err
    assert err.strip() == "omnicam: error: report " + str(tmp_path / "rig.txt") + (
        ": extension must be .html or .htm"
    )
    assert not (tmp_path / "rig.yaml").exists()  # refused before any work
    assert main([*base, "--report", str(tmp_path / "rig.html")]) == 0
    assert f"wrote the report {tmp_path / 'rig.html'}" in capsys.readouterr().out
    check_page((tmp_path / "rig.html").read_text(), IMAGE_SECTIONS)
    # and omnicam report on the file it wrote: the image calibrated again
    out = tmp_path / "again.html"
    assert main(["report", str(tmp_path / "rig.yaml"), one_image["path"], "-o", str(out)]) == 0
    text = out.read_text()
    check_page(text, IMAGE_SECTIONS)
    assert "the image calibrated again with the file&#x27;s K, D and mirror" in text


def test_cli_calibrate_report_option_with_chessboards(chessboard, tmp_path, capsys):
    page = tmp_path / "rig.html"
    args = ["calibrate", "--chessboard", "7x5", "--square", "60", *chessboard["paths"]]
    args += ["--mirror", "23.4", "28.1", "30", "--dist-model", "none", "--heldout", "0"]
    assert main([*args, "-o", str(tmp_path / "rig.yaml"), "--report", str(page)]) == 0
    assert f"wrote the report {page}" in capsys.readouterr().out
    text = page.read_text()
    check_page(text, PATTERN_SECTIONS)
    assert "not computed (calibrate with --heldout K" in text  # said why it is missing
