"""Robust scale: the one ``1.4826 * MAD`` of omnicam's fits.

For Gaussian residuals the median of their absolute deviation times 1.4826 estimates their
standard deviation, and outliers barely move it. The rim fit, the reflection detection and the
refinement's reweighting all use :func:`mad_sigma` for their thresholds.

Not ``scipy.stats.median_abs_deviation(x, scale="normal")``: the deviations here are from a
fitted model (their centre is 0), where that function takes them from their median (on the
rim's residuals it gives about half), its constant is ``1/Phi^-1(3/4)`` to all digits (the
thresholds would move in the 7th digit), and ``scipy.stats`` takes seconds to import on the
way to the rim.
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
