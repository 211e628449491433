"""Shared fixtures: the canonical rigs every generic model test runs over."""

import cv2
import numpy as np
import pytest

from omnicam import MisalignedHyperbolicCamera, synthetic


def _rigs():
    rng = np.random.default_rng(20261122)
    rigs = {"aligned": synthetic.aligned_rig(), "misaligned": synthetic.misaligned_rig()}
    for i in range(3):
        rigs[f"random{i}"] = synthetic.random_misaligned_rig(rng, 5.0, 5.0)
    rigs["max_tilt_offset"] = synthetic.misaligned_rig(5.0, 200.0, (3.0, -4.0, 0.0))
    base = synthetic.misaligned_rig(4.0, 100.0, (-2.0, 1.0, 2.0))
    K = base.K.copy()
    K[0, 1] = 0.8  # skew
    K[1, 1] *= 1.02  # non-square pixels
    rigs["skew"] = base.replace(K=K)
    rigs["distorted"] = base.replace(D=[-0.12, 0.05, 0.001, -0.0015, -0.01])
    rigs["rational"] = base.replace(D=[0.05, -0.02, 0.0, 0.0, 0.0, 0.02, -0.01, 0.003])
    return rigs


RIGS = _rigs()


@pytest.fixture(params=sorted(RIGS), ids=sorted(RIGS))
def rig(request) -> MisalignedHyperbolicCamera:
    """Every canonical rig: aligned, misaligned (tilt <= 5 deg, offset <= 5 mm), skew, D."""
    return RIGS[request.param]


def annulus_pixels(cam, step=4.0, rim_samples=720, inset=(0.05, 0.5, 1.0)):
    """Pixels over the whole visible annulus: a grid inside the rim plus rings just inside it."""
    rim = cam.rim_image_points(rim_samples)
    lo, hi = rim.min(axis=0), rim.max(axis=0)
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0], step), np.arange(lo[1], hi[1], step))
    grid = np.stack([gx.ravel(), gy.ravel()], axis=1)
    centre = rim.mean(axis=0)
    rings = [
        centre + (rim - centre) * (1 - s / np.linalg.norm(rim - centre, axis=1))[:, None]
        for s in inset
    ]
    pix = np.concatenate([grid, *rings])
    _, d = cam.unproject(pix)
    return pix[np.isfinite(d[:, 0])]


def video_frames(path):
    """``(count, (width, height))`` of a video as OpenCV decodes it."""
    cap = cv2.VideoCapture(str(path))
    assert cap.isOpened(), f"{path} is not a readable video"
    n, size = 0, None
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        n, size = n + 1, (frame.shape[1], frame.shape[0])
    cap.release()
    return n, size
