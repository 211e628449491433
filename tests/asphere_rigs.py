"""Misaligned rigs with mirrors of revolution other than the hyperboloid (even aspheres).

Each rig: a camera below the mirror looking up at it, 640 x 480, focal length such that the
rim's image is about 400 px across, the mirror tilted by about 2 deg and off the optical axis
by about a millimetre (the posture is misaligned, as the library's rigs are).
"""

import math

import numpy as np

from omnicam import MisalignedCatadioptricCamera
from omnicam.asphere import AsphericMirror, equiangular_profile

SIZE = (640, 480)
RIM_IMAGE_RADIUS = 200.0  # px


def equiangular_mirror(alpha, r0=30.0, fraction=0.6):
    """Chahl & Srinivasan's mirror, rim at ``fraction`` of the profile's polar range."""
    theta = fraction * math.pi / (1.0 + alpha)
    rim = float(equiangular_profile(alpha, r0, theta)[0])
    return AsphericMirror.equiangular(alpha, r0, rim)


#: name -> (mirror, camera height on the axis, mirror frame)
MIRRORS = {
    "sphere": lambda: (AsphericMirror.sphere(30.0, 18.0, vertex_z=40.0), 0.0),
    "paraboloid": lambda: (AsphericMirror.paraboloid(20.0, 25.0, vertex_z=45.0), 0.0),
    "prolate ellipsoid": lambda: (AsphericMirror.ellipsoid(25.0, -0.5, 22.0, vertex_z=40.0), 0.0),
    "equiangular 3": lambda: (equiangular_mirror(3.0), 0.0),
    "equiangular 5": lambda: (equiangular_mirror(5.0), 0.0),
    "equiangular 7": lambda: (equiangular_mirror(7.0), 0.0),
    "equiangular 11": lambda: (equiangular_mirror(11.0), 0.0),
}


def rig(name, misaligned=True):
    """The camera of rig ``name``: K from the rim's angle, posture tilted and shifted."""
    mirror, cz = MIRRORS[name]()
    C = np.array([0.7, -0.5, cz]) if misaligned else np.array([0.0, 0.0, cz])
    theta_rim = math.atan2(mirror.rim_radius, mirror.z_rim - cz)
    f = RIM_IMAGE_RADIUS / math.tan(theta_rim)
    K = np.array([[f, 0.0, 319.5], [0.0, f, 239.5], [0.0, 0.0, 1.0]])
    rvec = np.array([0.03, -0.02, 0.0]) if misaligned else np.zeros(3)
    # the camera looks up the mirror axis: camera +z along mirror +Z, then the small tilt
    import cv2

    R = cv2.Rodrigues(rvec)[0]
    tvec = -R @ C
    return MisalignedCatadioptricCamera(K, mirror, rvec, tvec, image_size=SIZE)
