"""Shared fixtures and helpers: the canonical rigs every generic model test runs over, random
misaligned rigs for the calibration tests, and a rig in a white holder for the rim tests."""

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from omnicam import MisalignedHyperbolicCamera, synthetic
from omnicam.calibration import chen

#: A real photograph (MIT, shipped with the tests: tests/data/README.md).
REAL_PHOTO = Path(__file__).resolve().parent / "data" / "office_catadioptric_1920x1080.jpg"


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


# -- random misaligned rigs and helpers shared by the calibration tests --------------------
def axis_angle_deg(a, b):
    """Angle between two directions, accurate near 0 (atan2, not arccos)."""
    return math.degrees(math.atan2(np.linalg.norm(np.cross(a, b)), float(np.dot(a, b))))


def random_rigs(n, seed=20261122, min_lateral=0.1):
    """Random misalignments (tilt <= 5 deg, offset <= 5 mm), camera >= 0.1 mm off the axis."""
    rng = np.random.default_rng(seed)
    rigs = []
    while len(rigs) < n:
        cam = synthetic.random_misaligned_rig(rng, 5.0, 5.0)
        C = cam.camera_center
        if math.hypot(C[0], C[1]) >= min_lateral:  # reject-sample (closer: candidates merge)
            rigs.append(cam)
    return rigs


RANDOM_RIGS = random_rigs(100)  # Chen, selection and calibration tests share them


def candidates_of(cam):
    Q_I = chen.rim_conic(cam.K, cam.R, cam.tvec, cam.mirror)
    return chen.chen_candidates(chen.normalized_conic(Q_I, cam.K), cam.mirror)


def white_holder_render(
    size=400, rim_px=130, holder_px=167, struts=(20, 140, 260), noise=0.0, seed=0, holder=235.0
):
    """A rig in a white holder ring (``holder_px`` outer radius) on a darker textured room, three
    dark struts crossing holder and mirror (radial bars), rendered by ``omnicam.synthetic``
    (environment at infinity, camera's reflection): ``(image, camera)``. The mirror's content
    near the rim (bright sky) is only ~25 grey levels darker than the holder, while the holder's
    outer edge is a 165-level step: the edge a bright-mirror detector takes for the rim."""
    cam = synthetic.misaligned_rig(
        2.0, 40.0, (1.0, -0.5, 0.5), image_size=(size, size), fill=2 * rim_px / size
    )
    c = cam.rim_image_points(720).mean(axis=0)
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float32)
    rng = np.random.default_rng(seed)
    room = 70 + 25 * np.sin(xx / 23.0) * np.cos(yy / 31.0) + rng.normal(0, 3, (size, size))
    bg = np.repeat(room[..., None], 3, axis=2)
    ring = np.hypot(xx - c[0], yy - c[1]) < holder_px
    bg[ring] = (
        (holder(xx, yy) if callable(holder) else holder)[..., None][ring]
        if callable(holder)
        else holder
    )
    img = synthetic.render_environment(cam, background=bg, noise=noise, seed=seed)
    q = np.stack([xx - c[0], yy - c[1]], -1)
    for ang in struts:
        u = np.array([np.cos(np.deg2rad(ang)), np.sin(np.deg2rad(ang))])
        img[(np.abs(q @ np.array([-u[1], u[0]])) < 0.02 * size) & (q @ u > 0.35 * rim_px)] = 45
    return img, cam


# -- helpers of the CLI tests -----------------------------------------------------------
def make_frame(i, size=(200, 200)):
    """A textured frame with a moving bright square, so frames differ and compress honestly."""
    w, h = size
    y, x = np.mgrid[0:h, 0:w]
    img = np.stack([(x * 255 // w), (y * 255 // h), np.full_like(x, 40 * (i % 6))], axis=-1)
    img = img.astype(np.uint8)
    s = 10 * i % (w - 20)
    img[s : s + 20, s : s + 20] = 255
    return img


def write_video(path, n, size=(200, 200), fps=10):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, size)
    assert writer.isOpened()
    for i in range(n):
        writer.write(make_frame(i, size))
    writer.release()
    return path


def one_error_line(err):
    """The stderr of a failed command: exactly one line, ours."""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("omnicam: error: "), err
    assert "Traceback" not in err
    return lines[0]


def leftovers(folder):
    """Temporary files the CLI may have left behind."""
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))
