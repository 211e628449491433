"""The central start on real images: Taylor (library and reference), Mei (cv2.omnidir), and
the even-asphere mirror the central start gives from the Taylor fit.

    python benchmarks/bench_central_start.py FOLDER --pattern 6x7 --glob 'VMR*.jpg'
        [--rim-radius 30] [--folds 5] [--heldout ../shared/tools/heldout.py]
        [--reference ../shared/tools/taylor.py]

FOLDER holds the images (e.g. OCamCalib's public samples); nothing is committed. All views with
a detected board are used; the rim is detected in the first image (its image radius about the
Taylor centre: the geometric mean of the ellipse's distances from it). With no data sheet the
rim radius is nominal (30 mm): it scales the mirror and the posture, not the shape (R / rim, k).
The start is given at the default f (the rim at 20 deg) and, when Mei's xi < 1, at Mei's
pinhole f = gamma / sqrt(1 - xi^2).
"""

import argparse
import glob
import importlib.util
import math
import os
import sys

import cv2
import numpy as np

from omnicam.calibration.rim import detect_rim
from omnicam.chessboard.board_pose import object_points
from omnicam.chessboard.central_start import central_start, unified_directions
from omnicam.chessboard.detect import detect_pattern
from omnicam.chessboard.profile import fit_even_asphere
from omnicam.chessboard.taylor import fit_taylor


def _module(name, path):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _rim_px(image, centre):
    rim = detect_rim(image)
    t = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    a, b = rim.axes
    c, s = math.cos(rim.angle), math.sin(rim.angle)
    pts = rim.center + np.stack(
        [a * np.cos(t) * c - b * np.sin(t) * s, a * np.cos(t) * s + b * np.sin(t) * c], 1
    )
    d = np.linalg.norm(pts - centre, axis=1)
    return float(np.exp(np.mean(np.log(d)))), rim


def _show(label, st, rim_radius):
    c = fit_even_asphere(st.profile.r, st.profile.z, rim_radius, 0)
    print(
        f"  {label}, the conic alone: R {c.R:.3f} (R/rim {c.R / rim_radius:.4f}), k {c.k:.4f}, "
        f"error {c.max_error:.2e}"
    )
    m = st.mirror
    print(
        f"  {label}: f {st.f:.1f} px (rim at {math.degrees(st.profile.phi[-1]):.1f} deg), "
        f"R {m.R:.3f} (R/rim {m.R / rim_radius:.4f}), k {m.k:.4f}, "
        f"{len(m.alphas)} terms {np.round(m.alphas, 5).tolist()}, fit error {m.max_error:.2e} "
        f"(conic alone {m.conic_error:.2e}), direction error {st.direction_error_deg:.4f} deg, "
        f"convex {m.convex}, camera-vertex {st.tvec[2]:.3f}, "
        f"z_rim - vertex {st.profile.z[-1] - st.profile.z[0]:.3f}"
    )


def _heldout(H, views, obj, size, k):
    """shared/tools/heldout.py's protocol: fit on k-1 folds, each held-out view's pose alone."""
    rms = {"taylor": [], "mei": []}
    for fold in H.folds(len(views), k):
        train = [v for i, v in enumerate(views) if i not in fold]
        t = fit_taylor(train, obj, size)
        m = H.omnidir_fit(train, obj, size)
        for i in fold:
            rms["taylor"].append(H.heldout_rms(t.project_board, t.directions, views[i], obj))
            rms["mei"].append(H.heldout_rms(m["project"], m["directions"], views[i], obj))
    for name, v in rms.items():
        print(f"  {k}-fold held-out {name}: median {np.median(v):.4f} px, max {np.max(v):.4f} px")


def main(argv=None):
    here = os.path.dirname(os.path.abspath(__file__))
    tools = os.path.join(here, "..", "..", "shared", "tools")
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder")
    ap.add_argument("--pattern", default="6x7")
    ap.add_argument("--glob", default="*.jpg")
    ap.add_argument("--square", type=float, default=30.0)
    ap.add_argument("--rim-radius", type=float, default=30.0)
    ap.add_argument("--heldout", default=os.path.join(tools, "heldout.py"))
    ap.add_argument("--reference", default=os.path.join(tools, "taylor.py"))
    ap.add_argument("--folds", type=int, default=5, help="held-out folds (0: none)")
    a = ap.parse_args(argv)
    pattern = tuple(int(v) for v in a.pattern.lower().split("x"))
    paths = sorted(glob.glob(os.path.join(a.folder, a.glob)))
    if not paths:
        sys.exit(f"no images matching {a.glob} in {a.folder}")
    images = [cv2.imread(p) for p in paths]
    size = (images[0].shape[1], images[0].shape[0])
    dets = [detect_pattern(im, pattern) for im in images]
    views = [d.corners.reshape(-1, 2).astype(np.float64) for d in dets if d is not None]
    obj = object_points(pattern, a.square)
    print(f"{len(views)} of {len(paths)} boards, image {size[0]}x{size[1]}")

    ours = fit_taylor(views, obj, size)
    ref = _module("taylor_reference", a.reference).fit(views, obj, size)
    print(
        f"Taylor: library RMS {ours.rms:.4f} px (degree {ours.degree}, centre "
        f"{ours.centre.round(2).tolist()}), reference {ref['rms']:.4f} px (degree {ref['degree']})"
    )
    print(f"  a = {np.array2string(ours.coefficients, precision=6)}")
    H = _module("heldout", a.heldout)
    mei = H.omnidir_fit(views, obj, size)
    op = [obj.reshape(1, -1, 3) for _ in views]
    ip = [v.reshape(1, -1, 2) for v in views]
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-8)
    _, K_u, xi, D_u, _, _, _ = cv2.omnidir.calibrate(op, ip, size, None, None, None, 0, crit)
    xi = float(np.ravel(xi)[0])
    print(
        f"Mei (cv2.omnidir, flags 0, heldout.omnidir_fit): xi {xi:.4f}, gamma "
        f"{K_u[0, 0]:.1f} / {K_u[1, 1]:.1f} px, RMS {mei['rms']:.4f} px ({mei['used']} views)"
    )
    if a.folds:
        _heldout(H, views, obj, size, a.folds)

    reach = max(np.linalg.norm(v - ours.centre, axis=1).max() for v in views)
    rho_rim, rim = _rim_px(images[0], ours.centre)
    print(
        f"rim: ellipse centre {rim.center.round(1).tolist()}, axes {rim.axes.round(1).tolist()}; "
        f"{rho_rim:.1f} px about the Taylor centre; the corners reach {reach:.1f} px"
    )
    st = central_start(ours.directions, ours.centre, rho_rim, a.rim_radius)
    print(f"central start from Taylor (rim radius {a.rim_radius} nominal, up to 6 terms):")
    print(
        f"  alpha from {math.degrees(st.alpha[1]):.1f} to {math.degrees(st.alpha[-1]):.1f} deg, "
        f"spread over azimuth max {math.degrees(st.alpha_spread.max()):.3f} deg"
    )
    _show("default f", st, a.rim_radius)
    if 0 < xi < 1:
        f_mei = math.sqrt(K_u[0, 0] * K_u[1, 1]) / math.sqrt(1 - xi * xi)
        _show(
            "Mei's f",
            central_start(ours.directions, ours.centre, rho_rim, a.rim_radius, f=f_mei),
            a.rim_radius,
        )
    try:  # the same start from Mei's directions (its own principal point), for comparison
        mei_dirs = unified_directions(K_u, xi, D_u)
        st_mei = central_start(mei_dirs, K_u[:2, 2], rho_rim, a.rim_radius, f=st.f)
        _show("from Mei's model, default f", st_mei, a.rim_radius)
    except ValueError as e:
        print(f"  from Mei's model: {e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
