"""The report pages the command line writes: ``--report PAGE.html`` of ``omnicam calibrate``
and ``omnicam report`` (:mod:`omnicam.html_report` builds them)."""

from __future__ import annotations

import os

from .._atomic import OutputError
from ..html_report import image_report_html, pattern_report_html, write_report
from ._common import CliError, check_output, one_line, user_terms

PAGE_SUFFIXES = (".html", ".htm")


def check_report_output(path, overwrite):
    """Refuse a report path we must not or cannot write, before any work."""
    if path is None:
        return
    if os.path.splitext(path)[1].lower() not in PAGE_SUFFIXES:
        raise CliError(f"report {path}: extension must be .html or .htm")
    check_output(path, overwrite, "report")


def _write(path, page, overwrite, say):
    try:
        write_report(path, page, overwrite=overwrite)
    except OutputError as e:
        raise CliError(one_line(e)) from None
    if say:
        print(f"wrote the report {path}", flush=True)


def write_pattern_page(
    path, camera, report, images, names, pattern_size, overwrite, say=True, **kw
):
    """Build and write the chessboard page (:func:`pattern_report_html`); ``say``: print
    where."""
    page = pattern_report_html(
        camera, report, images, names=names, pattern_size=pattern_size, terms=user_terms, **kw
    )
    _write(path, page, overwrite, say)


def write_image_page(path, camera, report, image, overwrite, notes=(), say=True):
    """Build and write the one-image page (:func:`image_report_html`); ``say``: print
    where."""
    _write(path, image_report_html(camera, report, image, notes=notes), overwrite, say)


def add_report_option(group):
    """``--report PAGE.html`` of ``omnicam calibrate`` on the argparse ``group``."""
    group.add_argument(
        "--report",
        metavar="PAGE.html",
        help="also write a self-contained HTML report of the calibration (images embedded, "
        "opens offline): with --chessboard the boards' coverage, residuals, per-view and "
        "held-out errors, the rim, a panorama with the boards and the posture; for one image "
        "the rim, the four candidate postures as panoramas, the choice and the posture",
    )
