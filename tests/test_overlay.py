"""The calibration overlay (``CalibrationReport.draw``): a legend of what is drawn, readable on
any image (issue 18 item 7)."""

import cv2
import numpy as np

from omnicam import MisalignedHyperbolicCamera, synthetic

SIZE = (320, 240)


def _scene():
    truth = synthetic.misaligned_rig(3.0, 30.0, (1.5, -1.0, 1.0), image_size=SIZE)
    return truth, synthetic.render_environment(truth, seed=1)


def test_the_overlay_legend_names_only_what_is_drawn(monkeypatch):
    """Without far lines the curves are the horizon under each posture; no far-line entry."""
    calibrate = MisalignedHyperbolicCamera.calibrate
    truth, image = _scene()
    _, plain = calibrate(truth.K, truth.mirror, image=image)
    _, lined = calibrate(
        truth.K, truth.mirror, image=image, far_lines=synthetic.far_line_pixels(truth)
    )
    texts = []
    real = cv2.putText
    monkeypatch.setattr(
        cv2, "putText", lambda img, text, *a: (texts.append(text), real(img, text, *a))[1]
    )
    plain.draw(image)
    labels, texts[:] = list(texts), []
    lined.draw(image)
    assert "far-line pixels" not in labels
    assert "horizon under the chosen posture" in labels
    assert not any("far lines" in t for t in labels)
    assert "far-line pixels" in texts and "far lines under the chosen posture" in texts


def test_the_overlay_text_is_on_a_dark_box_on_a_white_image():
    """White text on a white image was unreadable: the legend's box is darkened."""
    truth, _ = _scene()
    _, report = MisalignedHyperbolicCamera.calibrate(
        truth.K, truth.mirror, boundary_points=truth.rim_image_points(360)
    )
    white = np.full((SIZE[1], SIZE[0], 3), 255, np.uint8)
    overlay = report.draw(white)
    corner = overlay[-12:-5, 5:8]  # inside the legend's box, left of its colour squares
    assert corner.max() < 100, corner.max()
    top = overlay[5:8, 5:8]
    assert top.max() < 100
