"""Fingerprint of every remap table the sample calibrations give: one sha1 per table.

A refactor that must leave the maps byte-identical (issue 27 item 7) is checked by running this
before and after and diffing the output::

    python benchmarks/map_fingerprint.py > before.txt   # on the old commit
    python benchmarks/map_fingerprint.py > after.txt    # on the new one
    diff before.txt after.txt
"""

import hashlib

import cv2
import numpy as np

import omnicam
from omnicam import samples

VIEWS = {
    "panorama cylindrical": omnicam.PanoramaView((640, 160)),
    "panorama equirectangular": omnicam.PanoramaView((512, 128), projection="equirectangular"),
    "panorama depth 2000": omnicam.PanoramaView((400, 100), depth=2000.0),
    "perspective 90": omnicam.PerspectiveView((320, 240), fov=90.0),
    "perspective tilted": omnicam.PerspectiveView((240, 180), fov=70.0, yaw=40, pitch=-10, roll=5),
    "perspective depth 1500": omnicam.PerspectiveView((200, 150), fov=60.0, depth=1500.0, yaw=-120),
}
M1TYPES = {"16SC2": cv2.CV_16SC2, "32FC1": cv2.CV_32FC1, "32FC2": cv2.CV_32FC2}


def sha1(*arrays):
    h = hashlib.sha1()
    for a in arrays:
        if a is not None:
            h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def main():
    for name in samples.names():
        camera = samples.load(name)
        for view_name, view in VIEWS.items():
            for m1_name, m1type in M1TYPES.items():
                map1, map2 = view.maps(camera, m1type)
                print(f"{name:24s} {view_name:26s} {m1_name:6s} {sha1(map1, map2)}")


if __name__ == "__main__":
    main()
