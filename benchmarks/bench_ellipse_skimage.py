"""scikit-image against omnicam's hand-written ellipse pieces on clipped noisy rims.

Both methods of each piece run in one process on the same data; times are medians.
omnicam/calibration/ellipse.py states the choice this benchmark supports.

1. Direct fit: ``direct_ellipse`` (now ``skimage.measure.EllipseModel.from_estimate``) against
   the hand-written Halir-Flusser fit it replaced (kept below as ``handwritten_direct``): RMS
   distance of the true rim to the fitted ellipse, and time.
2. RANSAC on 1080p-sized rims (about 3000 points, rows clipped to 8-92 % of the height, 0.3 px
   noise, 10-70 % outliers: half spread around the rim, half on three radial holder arms):
   omnicam's batched ``ransac_conic`` against ``skimage.measure.ransac`` with the same
   five-point conic model and Sampson distance (``SampsonConic``); the mask of each goes through
   the rest of :func:`fit_rim`; failures are fits that raise or miss the true rim by > 1 px.
3. Orthogonal distances: ``orthogonal_residuals`` against ``EllipseModel.residuals``.
4. Geometric refinement: ``fit_rim(robust=False)`` (direct fit, then orthogonal LM) against
   ``EllipseModel`` alone on short arcs, where an algebraic fit is biased.
5. End to end, interleaved: ``detect_rim`` and ``calibrate`` on a rendered 1920x1080 rig and on
   the shared real photograph (if present), with the hand-written direct fit and RANSAC, with
   scikit-image's direct fit (the library now), and with scikit-image's RANSAC too; the time of
   the direct fits within ``calibrate``, and how far the rim and Chen's candidates move.
6. The one-time cost of importing scikit-image's fitting module (it loads scipy.optimize and
   scipy.spatial) in a fresh process, before and after scipy.optimize is loaded.
7. Image profiles along rim normals (:mod:`omnicam.calibration.edges`): one ``cv2.remap``
   against ``skimage.measure.profile_line`` per normal.

    python benchmarks/bench_ellipse_skimage.py [--rigs 30] [--repeat 5] [--photo PATH]
"""

import argparse
import math
import os
import statistics
import subprocess
import sys
import time
import warnings

import cv2
import numpy as np
from skimage.measure import EllipseModel, profile_line, ransac

import omnicam
from omnicam import synthetic
from omnicam.calibration import rim, rim_coarse, rim_fit
from omnicam.calibration.ellipse import (
    coeffs_to_conic,
    conic_distance,
    conic_from_ellipse,
    conics_through_5,
    direct_ellipse,
    ellipse_from_conic,
    hartley_normalization,
    orthogonal_residuals,
    ransac_conic,
    sampson_distances,
)
from omnicam.calibration.rim_fit import fit_rim, fit_with_mask

HERE = os.path.dirname(os.path.abspath(__file__))
PHOTO = os.path.join(
    HERE, "..", "..", "shared", "data", "real", "office_catadioptric_1920x1080.jpg"
)


def handwritten_direct(pts):
    """The hand-written fit ``direct_ellipse`` was before scikit-image (commit e6d24f4)."""
    x, y = pts[:, 0], pts[:, 1]
    D1 = np.stack([x * x, x * y, y * y], axis=1)
    D2 = np.stack([x, y, np.ones_like(x)], axis=1)
    S1, S2, S3 = D1.T @ D1, D1.T @ D2, D2.T @ D2
    try:
        T = -np.linalg.solve(S3, S2.T)
    except np.linalg.LinAlgError:
        return None
    M = S1 + S2 @ T
    M = np.stack([M[2] / 2.0, -M[1], M[0] / 2.0])
    w, V = np.linalg.eig(M)
    V = np.real(V)
    cond = 4.0 * V[0] * V[2] - V[1] ** 2
    ok = np.flatnonzero(cond > 0)
    if ok.size == 0:
        return None
    a1 = V[:, ok[np.argmin(np.abs(np.real(w[ok])))]]
    return coeffs_to_conic(np.concatenate([a1, T @ a1]))


class SampsonConic:
    """``skimage.measure.ransac`` model: the conic through 5 points (least squares through
    more), Sampson distances as residuals; non-ellipses are failed estimates."""

    def __init__(self, Q):
        self.Q = Q

    @classmethod
    def from_estimate(cls, pts):
        if len(pts) == 5:
            Q = conics_through_5(pts[None])[0]
        else:
            x, y = pts[:, 0], pts[:, 1]
            D = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=1)
            Q = coeffs_to_conic(np.linalg.svd(D, full_matrices=False)[2][-1])
        A = Q[:2, :2]
        return cls(Q) if A[0, 0] * A[1, 1] - A[0, 1] ** 2 > 0 else None

    def residuals(self, pts):
        ph = np.concatenate([pts, np.ones((len(pts), 1))], axis=1)
        return sampson_distances(self.Q[None], ph)[0]


def skimage_ransac(pts_n, thr_n, rng, max_trials, confidence=0.999):
    """``ransac_conic``'s interface on ``skimage.measure.ransac``."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="No inliers found")
        _, inliers = ransac(
            pts_n,
            SampsonConic,
            5,
            thr_n,
            max_trials=max_trials,
            stop_probability=confidence,
            rng=rng,
        )
    return inliers


def skimage_conic(m):
    c, s = math.cos(m.theta), math.sin(m.theta)
    R = np.array([[c, -s], [s, c]])
    return conic_from_ellipse(np.asarray(m.center), R @ np.diag(m.axis_lengths) @ R.T)


def rms(d):
    return float(np.sqrt(np.mean(np.square(d))))


def clocked(fn, *args, **kwargs):
    t = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t


def summary(errs, times, fails=None):
    out = f"median {np.median(errs):.4f} px, max {np.max(errs):.4f} px"
    if fails is not None:
        out += f", {fails} failed"
    return out + f"; time median {1e3 * np.median(times):.2f} ms"


def rim_scene(rng, outliers, n=3000, size=(1920, 1080), noise=0.3):
    """True rim (4000 points) and noisy clipped rim points with ``outliers`` of them wrong."""
    cam = synthetic.random_misaligned_rig(rng, 5.0, 5.0, image_size=size)
    true = cam.rim_image_points(4000)
    pts = cam.rim_image_points(n)
    h = size[1]
    pts = pts[(pts[:, 1] > 0.08 * h) & (pts[:, 1] < 0.92 * h)]
    pts = pts + rng.normal(0.0, noise, pts.shape)
    k = int(round(outliers / (1.0 - outliers) * len(pts)))
    c = true.mean(axis=0)
    r = 0.5 * float(np.ptp(true[:, 0]))
    a = rng.uniform(0.0, 2.0 * np.pi, k // 2)
    rr = r * rng.uniform(0.7, 1.3, k // 2)
    spread = c + np.stack([rr * np.cos(a), rr * np.sin(a)], axis=1)
    arms = rng.uniform(0.0, 2.0 * np.pi, 3)
    m = k - k // 2
    aa = arms[rng.integers(0, 3, m)]
    t = r * rng.uniform(0.7, 1.3, m)
    side = rng.normal(0.0, noise, m)
    arm = c + np.stack(
        [t * np.cos(aa) - side * np.sin(aa), t * np.sin(aa) + side * np.cos(aa)], axis=1
    )
    allp = np.concatenate([pts, spread, arm])
    return true, allp[rng.permutation(len(allp))]


def section_direct(rigs):
    print("1. direct fit on 420 of 500 rows of a rim, 0.3 px noise (true rim to the fit, RMS)")
    rng = np.random.default_rng(0)
    e_h, e_s, t_h, t_s = [], [], [], []
    for _ in range(rigs):
        cam = synthetic.random_misaligned_rig(rng, 5.0, 5.0)
        true = cam.rim_image_points(2000)
        pts = cam.rim_image_points(400)
        pts = pts[(pts[:, 1] > 40) & (pts[:, 1] < 460)]
        pts = pts + rng.normal(0, 0.3, pts.shape)
        N = hartley_normalization(pts)
        pts_n = pts * N[0, 0] + N[:2, 2]
        for fn, errs, times in ((handwritten_direct, e_h, t_h), (direct_ellipse, e_s, t_s)):
            Qn, dt = clocked(fn, pts_n)
            errs.append(rms(conic_distance(N.T @ Qn @ N, true)))
            times.append(dt)
    print(f"   hand-written Halir-Flusser        {summary(e_h, t_h)}")
    print(f"   skimage EllipseModel (now)        {summary(e_s, t_s)}")


def section_ransac(rigs):
    print(
        "2. RANSAC (max 2000 trials, 0.999 confidence) then fit_rim's refinement, 1080p rims "
        "of ~3000 points with outliers"
    )
    for outliers in (0.1, 0.3, 0.5, 0.7):
        rng = np.random.default_rng(1)
        res = {"hand": ([], [], [0]), "skimage": ([], [], [0])}
        for i in range(rigs):
            true, pts = rim_scene(rng, outliers)
            N = hartley_normalization(pts)
            s = N[0, 0]
            pts_n = pts * s + N[:2, 2]
            for name, fn in (("hand", ransac_conic), ("skimage", skimage_ransac)):
                mask, dt = clocked(fn, pts_n, 2.0 * s, np.random.default_rng(i), 2000)
                res[name][1].append(dt)
                try:
                    if mask is None or mask.sum() < 5:
                        raise ValueError("no consensus")
                    err = rms(conic_distance(fit_with_mask(pts, N, mask, True, 2.0).conic, true))
                except ValueError:
                    err = np.inf
                if not err <= 1.0:
                    res[name][2][0] += 1
                res[name][0].append(err)
        n = len(pts)
        for name, label in (("hand", "omnicam ransac_conic (batched)"), ("skimage", "skimage")):
            e, t, f = res[name]
            ok = [v for v in e if np.isfinite(v)]
            print(
                f"   {outliers:3.0%} outliers ({n} pts) {label:31s}"
                f"{summary(ok, t, f[0])} (max {1e3 * np.max(t):.1f} ms)"
            )


def section_distances():
    print("3. orthogonal point-to-ellipse distances, 3000 points of a 1080p rim, 0.3 px noise")
    rng = np.random.default_rng(2)
    true, pts = rim_scene(rng, 0.0)
    center, S = ellipse_from_conic(fit_rim(pts, robust=False).conic)
    ax = np.linalg.eigh(S)
    m = EllipseModel(center, ax[0][::-1], math.atan2(ax[1][1, 1], ax[1][0, 1]))
    (d_h, _, _), t_h = clocked(orthogonal_residuals, pts, center, S)
    d_s, t_s = clocked(m.residuals, pts)
    print(
        f"   orthogonal_residuals {1e3 * t_h:.2f} ms, EllipseModel.residuals {1e3 * t_s:.1f} ms "
        f"({t_s / t_h:.0f}x); largest difference {np.abs(np.abs(d_h) - d_s).max():.1e} px"
    )


def section_refinement(rigs):
    print("4. geometric refinement on short arcs, 0.5 px noise (true rim to the fit, RMS)")
    for frac in (0.5, 0.3):
        rng = np.random.default_rng(3)
        e_g, e_s, t_g, t_s = [], [], [], []
        for _ in range(rigs):
            cam = synthetic.random_misaligned_rig(rng, 5.0, 5.0)
            true = cam.rim_image_points(2000)
            t0 = rng.uniform(0, 2 * np.pi)
            k = int(2000 * frac)
            idx = (np.arange(k) + int(t0 / (2 * np.pi) * 2000)) % 2000
            pts = true[idx[::4]] + rng.normal(0, 0.5, (len(idx[::4]), 2))
            fit, dt = clocked(lambda p: fit_rim(p, robust=False), pts)
            e_g.append(rms(conic_distance(fit.conic, true)))
            t_g.append(dt)
            m, dt = clocked(EllipseModel.from_estimate, pts)
            e_s.append(rms(conic_distance(skimage_conic(m), true)))
            t_s.append(dt)
        print(f"   {frac:.0%} of the rim, fit_rim (direct + orthogonal LM)  {summary(e_g, t_g)}")
        print(f"   {frac:.0%} of the rim, EllipseModel alone (algebraic)  {summary(e_s, t_s)}")


def candidate_gap(a, b):
    """Axis angle (deg) and origin distance between two of Chen's candidates."""
    ax = math.degrees(math.acos(min(1.0, abs(float(a.axis @ b.axis)))))
    return ax, float(np.linalg.norm(a.tvec - b.tvec))


def section_end_to_end(repeat, photo):
    print("5. end to end, interleaved medians (hand = main before this change)")
    variants = {
        "hand direct + hand RANSAC": (handwritten_direct, ransac_conic),
        "skimage direct + hand RANSAC (now)": (direct_ellipse, ransac_conic),
        "skimage direct + skimage RANSAC": (direct_ellipse, skimage_ransac),
    }
    cases = []
    cam = synthetic.misaligned_rig(image_size=(1920, 1080))
    cases.append(("rendered 1920x1080", synthetic.render_environment(cam), cam.K, cam.mirror))
    if os.path.exists(photo):
        img = cv2.imread(photo)
        fit = omnicam.detect_rim(img)
        mirror = synthetic.default_mirror()
        r = math.sqrt(fit.axes[0] * fit.axes[1])
        f = r * (mirror.z_rim + mirror.c) / mirror.rim_radius
        K = np.array([[f, 0, fit.center[0]], [0, f, fit.center[1]], [0, 0, 1.0]])
        cases.append(("real photo 1920x1080", img, K, mirror))
    calibrate = omnicam.MisalignedHyperbolicCamera.calibrate
    fitters = (rim_fit, rim_coarse)  # the modules that call the two fits
    saved = [(m.direct_ellipse, m.ransac_conic) for m in fitters]
    fits = [0, 0.0]  # direct fits in the last calibrate and their time

    def counted(direct):
        def fit(pts):
            out, dt = clocked(direct, pts)
            fits[0] += 1
            fits[1] += dt
            return out

        return fit

    try:
        for label, img, K, mirror in cases:
            times = {v: ([], [], [], []) for v in variants}
            outs = {}
            for rep in range(repeat + 1):  # the first round warms up
                for v, (direct, rsc) in variants.items():
                    for m in fitters:
                        m.direct_ellipse, m.ransac_conic = counted(direct), rsc
                    fit, t_rim = clocked(rim.detect_rim, img)
                    fits[:] = [0, 0.0]
                    (_, report), t_cal = clocked(calibrate, K, mirror, image=img)
                    if rep:
                        times[v][0].append(t_rim)
                        times[v][1].append(t_cal)
                        times[v][2].append(fits[1])
                        times[v][3].append(fits[0])
                    outs[v] = fit, report
            ref_fit, ref_rep = outs["hand direct + hand RANSAC"]
            for v in variants:
                fit, rep = outs[v]
                # the candidates index by index: the choice among mirror-image postures
                # without a cue is a tie broken by rounding (see the report's warnings)
                gaps = [candidate_gap(c, r) for c, r in zip(rep.candidates, ref_rep.candidates)]
                print(
                    f"   {label}: {v:35s} detect_rim {1e3 * statistics.median(times[v][0]):6.1f}"
                    f" ms, calibrate {1e3 * statistics.median(times[v][1]):6.1f} ms (its "
                    f"{max(times[v][3])} direct fits {1e3 * statistics.median(times[v][2]):4.1f} "
                    f"ms); from hand: "
                    f"rim centre {np.linalg.norm(fit.center - ref_fit.center):.1e} px, "
                    f"candidates axis {max(g[0] for g in gaps):.1e} deg, origin "
                    f"{max(g[1] for g in gaps):.1e} mm; chosen {rep.chosen}"
                    + (" (ambiguous)" if rep.ambiguous else "")
                )
    finally:
        for m, (direct, rsc) in zip(fitters, saved):
            m.direct_ellipse, m.ransac_conic = direct, rsc


def section_import(repeat):
    print("6. importing skimage.measure's EllipseModel in a fresh process (median)")
    code = (
        "import time, omnicam.calibration.rim{}\n"
        "t = time.perf_counter()\n"
        "from skimage.measure import EllipseModel\n"
        "print(time.perf_counter() - t)"
    )
    for label, pre in (
        ("first detect_rim (nothing of scipy.optimize loaded yet)", ""),
        ("with scipy.optimize loaded (calibrate loads it to refine)", ", scipy.optimize"),
    ):
        t = [
            float(
                subprocess.run(
                    [sys.executable, "-c", code.format(pre)],
                    capture_output=True,
                    text=True,
                    check=True,
                ).stdout
            )
            for _ in range(repeat)
        ]
        print(f"   {label}: {1e3 * statistics.median(t):.0f} ms")


def section_profiles():
    print("7. image profiles along 3000 normals of a 1080p rim (edges.edge_points_along_normals)")
    rng = np.random.default_rng(7)
    G = cv2.GaussianBlur(rng.random((1080, 1920)).astype(np.float32), (0, 0), 2.0)
    t = np.linspace(0.0, 2.0 * np.pi, 3000, endpoint=False)
    nrm = np.c_[np.cos(t), np.sin(t)]
    e = np.array([960.0, 540.0]) + 450.0 * nrm
    tau = np.arange(-8.25, 8.25 + 0.375, 0.25)  # half width 8 px, 0.25 px steps
    mx = (e[:, :1] + nrm[:, :1] * tau).astype(np.float32)
    my = (e[:, 1:] + nrm[:, 1:] * tau).astype(np.float32)
    cv2.remap(G, mx, my, cv2.INTER_LINEAR)  # warm-up
    prof, t_cv = clocked(cv2.remap, G, mx, my, cv2.INTER_LINEAR)
    lines, t_sk = clocked(
        lambda: [
            profile_line(G, (my[i, 0], mx[i, 0]), (my[i, -1], mx[i, -1]), order=1)
            for i in range(len(e))
        ]
    )
    print(
        f"   cv2.remap, all normals at once: {1e3 * t_cv:.1f} ms ({prof.shape[1]} samples a "
        f"normal); skimage profile_line, a call a normal: {1e3 * t_sk:.0f} ms "
        f"({len(lines[0])} samples a normal: 1 px apart, not settable)"
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rigs", type=int, default=30)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--photo", default=PHOTO)
    args = ap.parse_args()
    section_direct(args.rigs)
    section_ransac(args.rigs)
    section_distances()
    section_refinement(args.rigs)
    section_end_to_end(args.repeat, args.photo)
    section_import(args.repeat)
    section_profiles()


if __name__ == "__main__":
    main()
