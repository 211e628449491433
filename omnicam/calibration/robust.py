"""Robust scale: the one ``1.4826 * MAD`` of omnicam's fits.

For Gaussian residuals the median of their absolute deviation times 1.4826 estimates their
standard deviation, and outliers barely move it. The rim fit, the reflection detection and the
refinement's reweighting all use :func:`mad_sigma` for their thresholds.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MAD_TO_SIGMA", "mad_sigma"]

MAD_TO_SIGMA = 1.4826  # 1 / Phi^-1(3/4): MAD -> sigma of a normal distribution


def mad_sigma(abs_deviations) -> float:
    """``1.4826 * median(|d|)`` of absolute deviations (NaN entries ignored); NaN if none."""
    d = np.asarray(abs_deviations, dtype=np.float64)
    if d.size == 0 or np.isnan(d).all():
        return float("nan")
    return MAD_TO_SIGMA * float(np.nanmedian(d))
