"""The mirror's shape as the bundle adjustment estimates it, for either mirror family.

The adjustment (:class:`.adjustment.BundleAdjustment`) holds the shape as a few numbers
``v``; this module is the one place that knows what they are:

- :class:`~omnicam.mirror.HyperbolicMirror`: ``(ln a, ln b)``, names ``a, b`` (logarithms, so
  that ``a, b`` stay positive wherever a step goes);
- :class:`~omnicam.asphere.AsphericMirror`: ``(ln R, k, alpha_4, alpha_6, ...)``, names
  ``R, k, alpha4, alpha6, ...`` (the vertex radius as a logarithm, the conic constant and the
  polynomial coefficients as they are, mirror units).

In both the rim radius is held (it fixes the scale, :data:`.central.NOMINAL_RIM_RADIUS` when
unknown), and so are the asphere's ``rho_n`` and ``vertex_z`` (a shift of the vertex along the
axis is the camera's ``t_z``). A vector no mirror has (``k`` past the rim's conic, a profile
not convex) makes :func:`with_shape` raise ``ValueError``, which the adjustment turns into
large residuals.
"""

from __future__ import annotations

import math

from ..asphere import AsphericMirror
from ..mirror import HyperbolicMirror

__all__ = ["LOG_NAMES", "family", "shape_names", "shape_steps", "shape_vector", "with_shape"]

#: The shape parameters held as logarithms (their standard deviations are scaled back).
LOG_NAMES = frozenset(("a", "b", "R"))


def family(mirror) -> str:
    """``"hyperboloid"`` or ``"asphere"`` (``"conic"`` for an asphere with no polynomial
    terms)."""
    if isinstance(mirror, HyperbolicMirror):
        return "hyperboloid"
    return "conic" if not mirror.alpha else "asphere"


def shape_names(mirror) -> list[str]:
    """The names of the shape parameters of ``mirror`` (module docstring)."""
    if isinstance(mirror, HyperbolicMirror):
        return ["a", "b"]
    return ["R", "k"] + [f"alpha{2 * j + 4}" for j in range(len(mirror.alpha))]


def shape_vector(mirror) -> list[float]:
    """The shape parameters of ``mirror``, in the order of :func:`shape_names`."""
    if isinstance(mirror, HyperbolicMirror):
        return [math.log(mirror.a), math.log(mirror.b)]
    return [math.log(mirror.R), float(mirror.k), *(float(a) for a in mirror.alpha)]


def with_shape(mirror, v):
    """A mirror of ``mirror``'s family, rim radius (and, for an asphere, ``rho_n`` and
    ``vertex_z``) with the shape parameters ``v``; ``ValueError`` when ``v`` makes none."""
    if isinstance(mirror, HyperbolicMirror):
        return HyperbolicMirror(math.exp(v[0]), math.exp(v[1]), mirror.rim_radius)
    return AsphericMirror(
        math.exp(v[0]),
        float(v[1]),
        mirror.rim_radius,
        alpha=tuple(float(a) for a in v[2:]),
        rho_n=mirror.rho_n,
        vertex_z=mirror.vertex_z,
    )


def shape_steps(mirror) -> list[float]:
    """Central-difference steps of the shape parameters: ``1e-6`` for the logarithms and
    ``k``, ``1e-6`` rim radii for the polynomial coefficients (a length)."""
    if isinstance(mirror, HyperbolicMirror):
        return [1e-6, 1e-6]
    return [1e-6, 1e-6] + [1e-6 * mirror.rim_radius] * len(mirror.alpha)
