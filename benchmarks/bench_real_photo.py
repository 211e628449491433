"""The shared real photograph: the rim, the camera's reflection, the choice, and the time.

Its rig's K and mirror are not published: K is guessed from the rim (f = r (z_rim + c) /
rim_radius for the default HyperOmni-style mirror; three guesses of the principal point and the
pixel aspect, :func:`guessed_K`), so the posture is only as right as that guess; the report
says how well the camera's reflection fits each. Writes the panorama of the most confident
result to ``--out`` (default benchmarks/out/office_panorama.png).

    python benchmarks/bench_real_photo.py [--photo PATH] [--repeat 3]
"""

import argparse
import math
import os
import time

import cv2
import numpy as np

import omnicam
from omnicam import synthetic, views

HERE = os.path.dirname(os.path.abspath(__file__))
PHOTO = os.path.join(
    HERE, "..", "..", "shared", "data", "real", "office_catadioptric_1920x1080.jpg"
)


def guessed_K(rim, mirror, image_shape):
    """The K hypotheses a user without a calibration would try (no truth exists).

    ``f`` from the rim's size for the default mirror, ``f = r (z_rim + c) / rim_radius``, and

    * ``rim centre``: the principal point at the rim centre, square pixels;
    * ``image centre``: the principal point at the image centre (``calibrate_pattern``'s start);
    * ``rim aspect``: the principal point at the rim centre, ``fx / fy`` from the rim's axes
      (pixels that are not square: the rim of an aligned rig is then a circle).
    """
    r = math.sqrt(rim.axes[0] * rim.axes[1])
    f = r * (mirror.z_rim + mirror.c) / mirror.rim_radius
    cx, cy = rim.center
    h, w = image_shape[:2]
    # the rim's extent along x and y (its shape matrix maps the unit circle onto it)
    ex, ey = np.linalg.norm(rim.shape_matrix, axis=1)
    return {
        "rim centre": np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]]),
        "image centre": np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]]),
        "rim aspect": np.array(
            [[f * math.sqrt(ex / ey), 0, cx], [0, f * math.sqrt(ey / ex), cy], [0, 0, 1.0]]
        ),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photo", default=PHOTO)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default=os.path.join(HERE, "out", "office_panorama.png"))
    args = ap.parse_args()
    img = cv2.imread(args.photo)
    if img is None:
        raise SystemExit(f"cannot read {args.photo}")
    rim = omnicam.detect_rim(img)
    mirror = synthetic.default_mirror()
    print(f"rim centre {np.round(rim.center, 1)}, axes {np.round(rim.axes, 1)}")
    hyps = guessed_K(rim, mirror, img.shape)
    K = hyps["rim centre"]
    times = []
    for _ in range(args.repeat):
        t = time.perf_counter()
        cam, report = omnicam.MisalignedHyperbolicCamera.calibrate(K, mirror, image=img)
        times.append(time.perf_counter() - t)
    print(f"calibrate (K: rim centre): median {np.median(times):.3f} s over {args.repeat} runs")
    print(report.summary())
    print("\nK hypotheses (no truth exists; the camera's reflection says which is consistent):")
    print(
        f"{'K':<14}{'fx':>8}{'fy':>8}{'cx':>8}{'cy':>8}{'tilt':>7}{'offset':>8}"
        f"{'refl.RMS':>9}{'conf':>6}  warnings"
    )
    best = None
    for name, K in hyps.items():
        cam, rep = omnicam.MisalignedHyperbolicCamera.calibrate(K, mirror, image=img)
        tilt = math.degrees(math.acos(min(1.0, abs(float(cam.R[2, 2])))))
        offset = float(np.linalg.norm(cam.camera_center - np.array([0, 0, -mirror.c])))
        rms = rep.lens_rms if np.isfinite(getattr(rep, "lens_rms", math.nan)) else math.nan
        print(
            f"{name:<14}{K[0, 0]:8.1f}{K[1, 1]:8.1f}{K[0, 2]:8.1f}{K[1, 2]:8.1f}{tilt:7.2f}"
            f"{offset:8.2f}{rms:9.2f}{rep.confidence:6.2f}  {len(rep.warnings)}"
        )
        for w in rep.warnings:
            print(f"{'':14}- {w[:150]}")
        if best is None or rep.confidence > best[2].confidence:
            best = (name, cam, rep)
    name, cam, rep = best
    if rep.lens_points is not None:
        print(f"\nthe default panorama (2048x512, K: {name}) and the camera's reflection:")
        for label, c in (
            ("fixed -60 deg", cam.replace(camera_reflection=None)),
            ("as detected", cam),
        ):
            for projection in views.PROJECTIONS:
                rows, pixels = lens_share(c, rep.lens_points, (2048, 512), projection)
                band = views.default_elevation_range(c, projection).describe()
                print(
                    f"  {label:<14}{projection:<16}{band}: {rows:.1%} of its rows and "
                    f"{pixels:.1%} of its pixels inside the detected outline"
                )
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    pano = cv2.remap(img, *cam.init_panorama_maps((2048, 512)), cv2.INTER_LINEAR)
    cv2.imwrite(args.out, pano)
    print(f"wrote {args.out} (K: {name}, confidence {rep.confidence:.2f})")


def lens_share(cam, outline, size, projection):
    """Fractions of the default panorama's rows and pixels whose source pixel lies inside the
    detected outline of the camera's reflection (a polygon of its points by angle)."""
    c = outline.mean(axis=0)
    order = np.argsort(np.arctan2(outline[:, 1] - c[1], outline[:, 0] - c[0]))
    poly = outline[order].astype(np.float32)
    m1, _ = cam.init_panorama_maps(size, projection=projection, m1type=cv2.CV_32FC2)
    src = m1.reshape(-1, 2)
    inside = np.array(
        [cv2.pointPolygonTest(poly, (float(x), float(y)), False) >= 0 for x, y in src]
    ).reshape(m1.shape[:2])
    return float(inside.any(axis=1).mean()), float(inside.mean())


if __name__ == "__main__":
    main()
