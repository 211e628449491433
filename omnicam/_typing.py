"""Type aliases of the public API (annotations only; nothing here runs at import time)."""

from __future__ import annotations

import os
from typing import Union

import numpy as np
import numpy.typing as npt

__all__ = ["ArrayLike", "FloatArray", "PathLike", "Size", "Maps"]

ArrayLike = npt.ArrayLike
FloatArray = npt.NDArray[np.float64]
PathLike = Union[str, "os.PathLike[str]"]
Size = tuple[int, int]
Maps = tuple[np.ndarray, np.ndarray | None]
