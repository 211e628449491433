"""Validators of the model's parameters, shared by the camera, io, views and calibration.

The lowest layer of omnicam with :mod:`omnicam.mirror` and :mod:`omnicam.gauge`: it imports
nothing from the package. Each function returns the value in its canonical form (float64 arrays,
tuples of ints) or raises ``ValueError`` naming the argument and what it must be
(``docs/conventions.md``).

Sane magnitudes (a camera outside them is refused at construction and at load):

* focal lengths ``fx, fy`` in ``[FOCAL_RANGE]`` = [1e-2, 1e7] px, principal point and skew at
  most ``PIXEL_LIMIT`` = 1e7 px in magnitude;
* image sizes at most ``MAX_SIDE`` = 100000 px per side and ``MAX_PIXELS`` = 2**31 pixels;
* distortion coefficients at most ``MAX_DISTORTION`` = 1e6 in magnitude;
* the mirror's ``a, b, rim_radius`` in ``LENGTH_RANGE`` = [1e-3, 1e6] (see
  :mod:`omnicam.mirror`), the mirror's origin at most ``MAX_DISTANCE`` = 1e7 from the camera;
* the posture physical: the camera centre below the mirror sheet, every rim point in front of
  the camera, and the rim's image between ``MIN_RIM_SPAN`` = 8 and ``MAX_RIM_SPAN`` = 20000 px
  across (every pixel inside it can be enumerated, as the best-fit viewpoint does, and there
  are enough of them);
* integers in YAML and XML files within 32 bits (OpenCV's parser wraps larger ones around:
  4294967297 reads as 1), see :mod:`omnicam.formats.filestorage`.
"""

from __future__ import annotations

import math
import numbers
import os
import stat
from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = [
    "validate_K",
    "validate_D",
    "validate_image_size",
    "finite_array",
    "float_array",
    "real_number",
    "positive_number",
    "refuse_complex",
    "validate_rng",
    "validate_posture",
    "shown",
    "file_path",
    "file_kind_of_mode",
    "regular_file",
    "check_readable",
    "D_LENGTHS",
    "FOCAL_RANGE",
    "LENGTH_RANGE",
    "MAX_SIDE",
    "MAX_PIXELS",
    "MAX_RIM_SPAN",
]

D_LENGTHS = (4, 5, 8, 12, 14)  # as cv2.projectPoints takes them
FOCAL_RANGE = (1e-2, 1e7)  # px
PIXEL_LIMIT = 1e7  # px, |cx|, |cy|, |skew|
LENGTH_RANGE = (1e-3, 1e6)  # a, b, rim_radius (mirror units)
MAX_DISTANCE = 1e7  # |tvec| (mirror units)
MAX_DISTORTION = 1e6
MAX_SIDE = 100_000  # px per side of an image
MAX_PIXELS = 2**31
MAX_RIM_SPAN = 20_000  # px across the rim's image
_COS, _SIN = (
    np.cos(np.linspace(0.0, 2.0 * math.pi, 72, endpoint=False)),
    np.sin(np.linspace(0.0, 2.0 * math.pi, 72, endpoint=False)),
)
MIN_RIM_SPAN = 8  # px: a smaller mirror image holds too few pixels for any use


def float_array(value: Any, name: str, expected: str, copy: bool = True) -> npt.NDArray[np.float64]:
    """``value`` as a float64 array; only real numbers (no complex, bool, str, None).

    With ``copy=False`` a float64 array is returned as it is (no copy), for the arithmetic of
    the numpy reference code on arrays it makes itself.
    """
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name} must be {expected}, got {value!r}") from None
    if arr.dtype.kind == "O":  # Python ints too large for int64, or mixed objects
        items = arr.ravel().tolist()
        if not all(isinstance(v, numbers.Real) and not isinstance(v, bool) for v in items):
            raise ValueError(f"{name} must be {expected}, got {value!r}")
        try:
            arr = np.array([float(v) for v in items], dtype=np.float64).reshape(arr.shape)
        except OverflowError:
            raise ValueError(f"{name} must be finite, got {value!r}") from None
    if arr.dtype.kind == "c":  # astype would keep the real part, with only a ComplexWarning
        raise ValueError(
            f"{name} must be {expected} (real numbers), got complex numbers "
            f"(dtype {arr.dtype}, shape {arr.shape})"
        )
    if arr.dtype.kind not in "iuf":
        raise ValueError(f"{name} must be {expected} (real numbers), got {value!r}")
    return arr.astype(np.float64, copy=copy)


def refuse_complex(value: Any, name: str, expected: str) -> None:
    """``ValueError`` naming ``name`` for a complex value, numpy's complex scalars and arrays
    included (``float()`` of them keeps the real part, with only a ``ComplexWarning``)."""
    if isinstance(value, complex) or np.iscomplexobj(value):
        raise ValueError(f"{name} must be {expected}, got {value!r} (a complex number)")


def finite_array(
    value: Any, name: str, shape: tuple[int, ...], expected: str
) -> npt.NDArray[np.float64]:
    arr = float_array(value, name, expected)
    if arr.size != int(np.prod(shape)):
        raise ValueError(f"{name} must be {expected}, got shape {arr.shape}")
    arr = arr.reshape(shape)
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite, got {arr.ravel().tolist()}")
    return arr


def real_number(
    value: Any,
    name: str,
    lo: float = -math.inf,
    hi: float = math.inf,
    expected: str | None = None,
    lo_open: bool = False,
) -> float:
    """``float(value)`` for a real, finite number in ``[lo, hi]`` (``(lo, hi]`` if ``lo_open``)."""
    expected = expected or "a finite number"
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be {expected}, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name} must be {expected}, got {value!r}") from None
    if not math.isfinite(v) or v < lo or v > hi or (lo_open and v == lo):
        raise ValueError(f"{name} must be {expected}, got {value!r}")
    return v


def positive_number(value: Any, name: str, expected: str = "a positive number") -> float:
    """``float(value)`` when it is finite and above 0, or ``ValueError`` naming ``name``.

    Unlike :func:`real_number`, anything ``float()`` takes is taken (a numeric string such as
    ``"2.5"`` as well): the lengths and limits checked here always were. ``expected`` ends the
    message ("square_size must be a positive number, got 0").
    """
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {expected}, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be {expected}, got {value!r}")
    return v


def validate_K(K: Any, name: str = "K") -> npt.NDArray[np.float64]:
    """Return ``K`` as a (3, 3) float64 array or raise ``ValueError`` naming ``name``.

    ``fx, fy`` must lie in ``FOCAL_RANGE`` px, ``|cx|, |cy|, |skew|`` at most 1e7 px.
    """
    arr = float_array(K, name, "a 3x3 camera matrix")
    if arr.shape != (3, 3):
        raise ValueError(f"{name} must be a 3x3 camera matrix, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite")
    if np.abs(arr[2] - (0.0, 0.0, 1.0)).max() > 1e-8:
        raise ValueError(f"{name} must have last row (0, 0, 1), got {arr[2].tolist()}")
    lo, hi = FOCAL_RANGE
    for label, f in (("fx", arr[0, 0]), ("fy", arr[1, 1])):
        if not lo <= f <= hi:
            raise ValueError(
                f"{name} must be non-singular with {label} in [{lo:g}, {hi:g}] px, got {f:g}"
            )
    if np.abs(arr[:2, 1:]).max() > PIXEL_LIMIT:
        raise ValueError(
            f"{name} must have |cx|, |cy| and |skew| at most {PIXEL_LIMIT:g} px, "
            f"got {arr[:2, 1:].ravel().tolist()}"
        )
    if abs(np.linalg.det(arr)) < 1e-12:
        raise ValueError(f"{name} must be non-singular")
    return arr


def validate_D(D: Any, name: str = "D") -> npt.NDArray[np.float64] | None:
    """Return ``D`` as a flat float64 array of an OpenCV length, or ``None``."""
    if D is None:
        return None
    expected = "None or 4, 5, 8, 12 or 14 numbers"
    arr = float_array(D, name, expected).ravel()
    if arr.size not in D_LENGTHS:
        raise ValueError(
            f"{name} must have 4, 5, 8, 12 or 14 coefficients (as "
            f"cv2.projectPoints), got {arr.size}"
        )
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite")
    if np.abs(arr).max() > MAX_DISTORTION:
        raise ValueError(
            f"{name} coefficients must be at most {MAX_DISTORTION:g} in magnitude, "
            f"got {arr.tolist()}"
        )
    return arr


def validate_image_size(image_size: Any, name: str = "image_size") -> tuple[int, int] | None:
    """Return ``(width, height)`` as a tuple of positive ints, or ``None``.

    At most ``MAX_SIDE`` px per side and ``MAX_PIXELS`` pixels in all.
    """
    if image_size is None:
        return None
    expected = "(width, height), two positive integers"
    if isinstance(image_size, (str, bytes)):
        raise ValueError(f"{name} must be {expected}, got {image_size!r}")
    try:
        values = list(image_size)
    except TypeError:
        raise ValueError(f"{name} must be {expected}, got {image_size!r}") from None
    if len(values) != 2:
        raise ValueError(f"{name} must be {expected}, got {image_size!r}")
    out = []
    for v in values:
        v = real_number(v, name, expected=expected)  # refuses str, bool, complex, inf, NaN
        if v != int(v) or v <= 0:
            raise ValueError(f"{name} must be {expected}, got {image_size!r}")
        out.append(int(v))
    w, h = out
    if w > MAX_SIDE or h > MAX_SIDE or w * h > MAX_PIXELS:
        raise ValueError(
            f"{name} must be at most {MAX_SIDE} px per side and {MAX_PIXELS} "
            f"pixels, got {image_size!r}"
        )
    return (w, h)


def validate_rng(
    rng: Any, name: str = "rng"
) -> int | np.random.Generator | np.random.BitGenerator | np.random.SeedSequence | None:
    """A seed for ``numpy.random.default_rng``: None, a non-negative int or a Generator."""
    if rng is None or isinstance(
        rng, (np.random.Generator, np.random.BitGenerator, np.random.SeedSequence)
    ):
        return rng
    if isinstance(rng, numbers.Integral) and not isinstance(rng, bool) and int(rng) >= 0:
        return int(rng)
    raise ValueError(
        f"{name} must be None, a non-negative integer seed or a numpy.random.Generator, got {rng!r}"
    )


def validate_posture(
    R: npt.NDArray[np.float64],
    tvec: npt.NDArray[np.float64],
    mirror: Any,  # a HyperbolicMirror or AsphericMirror, which sit above this module
    rim_points: Callable[[], npt.NDArray[np.float64]],
) -> None:
    """Refuse a posture no real rig has (``ValueError`` naming ``rvec``/``tvec``).

    Parameters
    ----------
    R : (3, 3) float64 ndarray
        ``cv2.Rodrigues(rvec)``, mirror -> camera.
    tvec : (3,) float64 ndarray
    mirror : HyperbolicMirror
    rim_points : callable
        ``rim_points()`` -> (n, 2) pixels of the rim (the camera's ``rim_image_points``), called
        only once the rim is known to be in front of the camera.

    Checks: ``R`` finite and a rotation, ``|tvec| <= MAX_DISTANCE``; the camera centre
    ``C = -R^T tvec`` below the mirror sheet (``C_z < mirror.surface_z(C_x, C_y)``, eq. 13
    for the hyperboloid), so it looks at the mirror from outside; every rim point in front of
    the camera (camera-frame z > 0); the rim's image between ``MIN_RIM_SPAN`` and
    ``MAX_RIM_SPAN`` px across.
    """
    if not np.isfinite(R).all() or np.abs(R @ R.T - np.eye(3)).max() > 1e-9:
        raise ValueError("rvec must give a finite rotation matrix")
    if np.abs(tvec).max() > MAX_DISTANCE or np.linalg.norm(tvec) > MAX_DISTANCE:
        raise ValueError(
            f"tvec must be at most {MAX_DISTANCE:g} from the camera (mirror "
            f"units), got {tvec.tolist()}"
        )
    C = -R.T @ tvec
    sheet = float(mirror.surface_z(C[0], C[1]))
    if not C[2] < sheet:
        raise ValueError(
            f"tvec, rvec: the camera centre {C.tolist()} (mirror frame) must lie "
            f"below the mirror sheet (Z < {sheet:g} there), looking up at it"
        )
    # camera-frame z of rim points: R[2] . (r cos t, r sin t, z_rim) + tvec[2]
    z = mirror.rim_radius * (R[2, 0] * _COS + R[2, 1] * _SIN) + R[2, 2] * mirror.z_rim + tvec[2]
    if not (z > 0).all():
        raise ValueError(
            "rvec, tvec: the mirror's rim must lie in front of the camera "
            "(camera-frame z > 0 at every rim point)"
        )
    pix = rim_points()
    span = np.ptp(pix, axis=0) if np.isfinite(pix).all() else np.array([np.inf, np.inf])
    if not span.max() <= MAX_RIM_SPAN:
        raise ValueError(
            f"K, tvec: the rim's image must span at most {MAX_RIM_SPAN} px, got "
            f"{np.round(span, 1).tolist()} px (a scale mistake?)"
        )
    if not span.min() >= MIN_RIM_SPAN:
        raise ValueError(
            f"K, tvec: the rim's image must span at least {MIN_RIM_SPAN} px, got "
            f"{np.round(span, 3).tolist()} px (a scale mistake?)"
        )


# -- files ------------------------------------------------------------------------------------
def shown(path):
    r"""``path`` as text that can always be printed (undecodable bytes as ``\xNN``)."""
    if isinstance(path, bytes):
        return path.decode("utf-8", "backslashreplace")
    return str(path).encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")


def file_path(path, what):
    """``os.fspath(path)`` as str; a name that is not UTF-8 is refused (it crashes OpenCV)."""
    try:
        path = os.fspath(path)
    except TypeError:
        raise ValueError(
            f"{what} path must be a file name (str or os.PathLike), got {path!r}"
        ) from None
    if isinstance(path, bytes):
        path = os.fsdecode(path)
    if "\0" in path:
        raise ValueError(f"{what} {shown(path)}: the name contains a NUL character")
    try:
        path.encode("utf-8")
    except UnicodeEncodeError:
        raise ValueError(
            f"{what} {shown(path)}: the file name is not valid UTF-8 "
            f"(OpenCV cannot handle it); rename the file"
        ) from None
    return path


def file_kind_of_mode(mode) -> str:
    """What a ``st_mode`` that is not a regular file's is, in words."""
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a file"


def regular_file(path, label) -> os.stat_result:
    """``os.stat(path)`` of a regular file, else the error that says what is there.

    Parameters
    ----------
    path : str
        The file (:func:`file_path`).
    label : str
        The file as messages name it ("calibration file x.yaml", "image a.png").

    Raises
    ------
    FileNotFoundError
        Nothing at ``path`` (or a parent that is not a folder).
    ValueError
        Something else there (a folder, FIFO, device, socket), or ``stat`` refused (its reason).
    """
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise FileNotFoundError(f"{label} does not exist") from None
    except NotADirectoryError:
        raise FileNotFoundError(f"{label} does not exist (a parent is not a folder)") from None
    except OSError as e:
        raise ValueError(f"cannot read {label}: {e.strerror or e}") from None
    if not stat.S_ISREG(st.st_mode):
        raise ValueError(f"{label} is not a regular file ({file_kind_of_mode(st.st_mode)})")
    return st


def check_readable(path, label) -> None:
    """``ValueError`` "cannot read {label}: permission denied" (or the system's reason) when
    ``path`` cannot be opened for reading: OpenCV would only say it is no image or video."""
    try:
        with open(path, "rb"):
            pass
    except PermissionError:
        raise ValueError(f"cannot read {label}: permission denied") from None
    except OSError as e:
        raise ValueError(f"cannot read {label}: {e.strerror or e}") from None
