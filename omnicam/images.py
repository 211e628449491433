"""Images as the library takes them: one reader of image files, one grey conversion.

Every function that takes an image accepts a numpy array, grey ``(H, W)`` or ``(H, W, 1)`` or
BGR / BGRA ``(H, W, 3|4)``, of any integer or float dtype (not bool), as ``cv2.imread`` gives
them; the detectors that accept a file name read it with :func:`read_image`.

Two scalings serve two kinds of use:

- ``"levels"``: the 0-255 scale of 8 bits, whatever the dtype (16-bit divided by 257, floats
  in [0, 1] times 255, other values as they are). Thresholds on absolute grey levels (the
  camera's dark reflection) and drawings use it, and so do OpenCV's corner detectors, which
  take 8 bits.
- ``"range"``: the image's own minimum and maximum stretched to [0, 1] (a uniform image is
  all 0). Edge detectors whose thresholds are relative to the image's contrast (the rim) use
  it, and so do OpenCV's corner detectors on images of more than 8 bits (a 12-bit image in a
  16-bit file would be nearly black on the ``"levels"`` scale).

NaN and infinite values are read as 0 in both. Colour is converted with OpenCV's weights
(``cv2.COLOR_BGR2GRAY``); an alpha channel is ignored.
"""

from __future__ import annotations

import os

import cv2
import numpy as np
import numpy.typing as npt

from ._quiet import opencv_silenced
from ._validate import check_readable, file_path, regular_file, shown

__all__ = [
    "MAX_FRAME_ASPECT",
    "SCALES",
    "aspect_note",
    "check_image",
    "file_kind",
    "image_problem",
    "read_image",
    "to_bgr8",
    "to_gray",
]

SCALES = ("levels", "range")
#: Wider (or taller) than any camera's frame of a mirror: 16:9 is 1.78, cinema's 2.39, two
#: fisheyes side by side 2.
MAX_FRAME_ASPECT = 3.0


def aspect_note(image_size) -> str:
    """``"; the image is 4000x500 (8.0:1), ..."`` for an image too wide or too tall to be a
    camera's frame of a mirror (whose image is round), else ``""``: what a failed rim search
    (:func:`omnicam.detect_rim`) and ``omnicam calibrate`` add to their message."""
    w, h = image_size
    ratio = max(w, h) / max(min(w, h), 1)
    if ratio <= MAX_FRAME_ASPECT:
        return ""
    side = min(w, h)
    return (
        f"; the image is {w}x{h} ({ratio:.1f}:1), no camera's frame of a mirror: the mirror's "
        f"round image would fill at most {side}x{side} px of it (a panorama already unwarped, "
        f"or a crop?); give the camera's own image"
    )


def check_image(image, name="image") -> np.ndarray:
    """``image`` as an image array: ``(H, W)`` or ``(H, W, 3|4)``, ``(H, W, 1)`` squeezed.

    Parameters
    ----------
    image : numpy.ndarray
        Grey or BGR(A), any integer or float dtype but bool, not empty.
    name : str
        How messages name it (``"images[3]"``, say).

    Returns
    -------
    numpy.ndarray
        The same array, or a view of it without the single channel axis.

    Raises
    ------
    ValueError
        Not an array, a shape that is no image, an empty one, or a dtype that holds no grey
        levels (bool, complex, object, strings).
    """
    if not isinstance(image, np.ndarray):
        raise ValueError(f"{name} must be a numpy array (grey or BGR), got {type(image).__name__}")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (3, 4)):
        raise ValueError(
            f"{name} must be grey (H, W) or BGR/BGRA (H, W, 3|4), got shape {image.shape}"
        )
    if image.size == 0:
        raise ValueError(f"{name} is empty (shape {image.shape})")
    if image.dtype == np.bool_ or image.dtype.kind not in "uif":
        raise ValueError(f"{name} must be uint8, uint16 or float, got dtype {image.dtype}")
    return image


def _levels(image: np.ndarray) -> npt.NDArray[np.float32]:
    """The image on the 0-255 scale of 8 bits, float32, non-finite values as 0."""
    img = np.nan_to_num(image.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    if image.dtype == np.uint16:
        return img / np.float32(257.0)
    if image.dtype.kind == "f" and float(img.max()) <= 1.0:
        return img * np.float32(255.0)
    return img


def _grey_float(image: np.ndarray) -> npt.NDArray[np.float32]:
    """float32 grey of a checked image (OpenCV's weights), its values as they are."""
    img = image.astype(np.float32, copy=False)
    if img.ndim == 3:
        return np.asarray(cv2.cvtColor(img[:, :, :3], cv2.COLOR_BGR2GRAY), np.float32)
    return img


def to_gray(image, scale="levels", dtype=np.float32, name="image") -> np.ndarray:
    """The grey image of ``image`` on one of the two scales (see the module's docstring).

    Parameters
    ----------
    image : numpy.ndarray
        Grey or BGR(A) (:func:`check_image`).
    scale : {"levels", "range"}
        ``"levels"``: the 0-255 scale of 8 bits; ``"range"``: min..max to 0..1.
    dtype : numpy.float32 or numpy.uint8
        ``uint8`` rounds and clips to 0..255 (``"range"``: min..max to 0..255), for OpenCV's
        detectors; an 8-bit image then comes back on the ``"levels"`` scale as
        ``cv2.cvtColor`` gives it.
    name : str
        How messages name the image.

    Returns
    -------
    numpy.ndarray
        ``(H, W)`` grey of ``dtype``.

    Raises
    ------
    ValueError
        A bad image (:func:`check_image`), or an unknown ``scale`` / ``dtype``.
    """
    image = check_image(image, name)
    if scale not in SCALES:
        raise ValueError(f"scale must be one of {SCALES}, got {scale!r}")
    if np.dtype(dtype) not in (np.float32, np.uint8):
        raise ValueError(f"dtype must be numpy.float32 or numpy.uint8, got {dtype!r}")
    if np.dtype(dtype) == np.uint8:
        if image.dtype == np.uint8 and scale == "levels":
            return image if image.ndim == 2 else cv2.cvtColor(image[:, :, :3], cv2.COLOR_BGR2GRAY)
        g = to_gray(image, scale, np.float32, name)
        return np.clip(np.round(g * np.float32(255.0) if scale == "range" else g), 0, 255).astype(
            np.uint8
        )
    if scale == "levels":
        return _grey_float(_levels(image))
    g = np.nan_to_num(_grey_float(image), nan=0.0, posinf=0.0, neginf=0.0)
    lo, hi = float(g.min()), float(g.max())
    if not hi > lo:
        return np.zeros_like(g)
    return (g - lo) * np.float32(1.0 / (hi - lo))


def to_bgr8(image, name="image") -> npt.NDArray[np.uint8]:
    """An 8-bit BGR copy of ``image`` to draw on, on the ``"levels"`` scale.

    Parameters
    ----------
    image : numpy.ndarray
        Grey or BGR(A) (:func:`check_image`).
    name : str
        How messages name the image.

    Returns
    -------
    numpy.ndarray
        ``(H, W, 3)`` uint8, a new array.
    """
    image = check_image(image, name)
    if image.dtype != np.uint8:
        image = np.clip(_levels(image), 0, 255).astype(np.uint8)
    if image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    return image[:, :, :3].copy()


def read_image(path, flags=cv2.IMREAD_UNCHANGED, name="image") -> np.ndarray:
    """``cv2.imread`` of a regular file, with a message that says why it cannot be read.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    flags : int
        ``cv2.imread``'s flags.
    name : str
        How messages name the file beside its path (``"image"``, ``"images[3]"``).

    Returns
    -------
    numpy.ndarray
        The image as ``cv2.imread`` gives it.

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        A name that is not UTF-8, not a regular file, empty, unreadable (no permission), or not
        an image OpenCV decodes (in full: a JPEG cut short is refused).
    """
    path = file_path(path, name)
    label = f"{name} {shown(path)}"
    st = regular_file(path, label)
    if st.st_size == 0:
        raise ValueError(f"cannot read {label}: the file is empty")
    check_readable(path, label)
    try:
        with opencv_silenced():
            image = cv2.imread(path, flags)
    except cv2.error as e:
        raise ValueError(f"cannot read {label}: {e.err or e}") from None
    problem = image_problem(path, image, flags)
    if problem:
        raise ValueError(f"cannot read {label}: {problem}")
    return image


# the first bytes of the files given for an image or a video: (offset, bytes, what it is)
_SIGNATURES = (
    (0, b"\x89PNG\r\n\x1a\n", "a PNG image"),
    (0, b"\xff\xd8\xff", "a JPEG image"),
    (0, b"II*\0", "a TIFF image"),
    (0, b"MM\0*", "a TIFF image"),
    (0, b"GIF8", "a GIF image"),
    (8, b"WEBP", "a WebP image"),
    (4, b"ftypavif", "an AVIF image"),
    (4, b"ftypheic", "a HEIC image"),
    (8, b"AVI ", "an AVI video"),
    (4, b"ftyp", "an MP4 or QuickTime video"),
    (0, b"\x1a\x45\xdf\xa3", "a Matroska or WebM video"),
    (0, b"BM", "a BMP image"),
)
_TEXT_CONTROLS = set(range(32)) - {9, 10, 12, 13}  # bytes that no text file holds


def file_kind(path) -> str | None:
    """What the file at ``path`` is by its first bytes, in words: ``"a text file"``,
    ``"a PNG image"``, ``"an MP4 or QuickTime video"``, ...; None if they tell nothing.

    Raises ``OSError`` (``PermissionError``, ...) if the file cannot be read.
    """
    with open(path, "rb") as f:
        head = f.read(4096)
    if head and not _TEXT_CONTROLS.intersection(head):
        try:
            head.decode("utf-8")
            return "a text file"
        except UnicodeDecodeError as e:
            if e.start >= len(head) - 3 and len(head) == 4096:  # a character cut at the end
                return "a text file"
    for offset, magic, what in _SIGNATURES:
        if head[offset : offset + len(magic)] == magic:
            return what
    return None


def image_problem(path, image, flags=cv2.IMREAD_UNCHANGED) -> str | None:
    """Why ``cv2.imread(path, flags)``, which gave ``image``, did not read the file whole, in
    words; None when it did.

    ``cv2.imread`` decodes a JPEG cut short (an interrupted copy or download) in part and fills
    the rest with grey, without a word: such a file lacks the end marker ``FF D9`` after its
    data and ``cv2.imdecode`` of its bytes gives nothing (data appended after a complete
    JPEG, as phones append a video, leaves it readable). When ``imread`` gave nothing, the file's
    first bytes say what it is (text, a video, an image format it could not decode).
    """
    size = os.stat(path).st_size
    kind = file_kind(path)
    if image is None or image.size == 0:
        if kind == "a text file":
            return "it is a text file, not an image"
        if kind is not None and kind.endswith("image"):
            return (
                f"{kind} OpenCV cannot decode ({size} bytes): truncated, corrupt or in a "
                f"variant this OpenCV build lacks"
            )
        if kind is not None:
            return f"it is {kind}, not an image"
        return f"not an image format OpenCV reads ({size} bytes)"
    if kind != "a JPEG image":
        return None
    with open(path, "rb") as f:  # the end alone first: a whole JPEG is not read twice
        f.seek(max(0, size - 4096))
        if f.read().rstrip(b"\0").endswith(b"\xff\xd9"):
            return None
        f.seek(0)
        data = f.read()
    with opencv_silenced():
        whole = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    if whole is not None:
        return None
    return (
        f"a truncated JPEG ({size} bytes, without its end marker FF D9): OpenCV decodes only "
        f"its first part and fills the rest with grey; copy or export it again"
    )
