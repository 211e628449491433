"""The aspheric mirror's family checked by the data: one more polynomial term while a
likelihood-ratio test on the adjustment's cost asks for it.

The families are nested: a conic (``R, k``; the hyperboloid is the conic with ``k < -1``), a
conic with ``alpha_4``, with ``alpha_4, alpha_6``... Adding a term that the corners do not need
lowers the cost by the residual variance times a chi-square variable of 1 degree of freedom;
a term is kept when a short refinement with it free (:data:`_TERM_CHECK_NFEV` evaluations, a
lower bound of the fit's gain) lowers the corners' and the rim's robust cost by more than
:data:`TERM_ADD_CHI2` times the residual variance (``p = 0.001``), and the fit then carried on
to convergence. The generic start (:mod:`.any_start`) begins with the terms that fit the
Taylor model's profile best (at most :data:`.any_start.START_TERMS`); the short refinement is
a weak bound in the adjustment's flat valley, so the test only adds, it does not build the
family from the conic up (a conic start runs off along that valley on KaidanOmni).
The central start's hyperboloid is tested the same way against the conic with ``alpha_4``
(:func:`hyperboloid_term_check`), the test's degrees of freedom the parameters it frees. The
sentence each returns is the report's ``family``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..asphere import MAX_ALPHA, AsphericMirror
from ..mirror import HyperbolicMirror
from .adjustment import AdjustmentModel, BundleAdjustment, robust_residuals
from .fit_steps import AdjustmentStep, ResidualGroups, Rounds, carried_on

__all__ = ["MAX_TERMS", "TERM_ADD_CHI2", "chi2_limit", "family_step", "hyperboloid_term_check"]

#: A term is added when it lowers the cost by more than this times the residual variance:
#: chi-square with 1 degree of freedom exceeds it with probability 0.001.
TERM_ADD_CHI2 = 10.83
#: Most polynomial terms tried: the outer profile beyond the boards' reach is not seen, and
#: every term is one more parameter of the adjustment's slowest valley.
MAX_TERMS = 3
#: Evaluations of the short refinement that tests a term.
_TERM_CHECK_NFEV = 10


def _with_term(fit: AdjustmentStep, image_size):
    """The adjustment of ``fit`` again with one more polynomial term (0) in the mirror:
    ``(adj2, x2)`` at the same solution."""
    adj, sol = fit.adj, fit.sol
    camera, gauged = adj.to_gauge(sol.x, image_size)
    m = camera.mirror
    if isinstance(m, HyperbolicMirror):  # the same surface, the conic of the asphere family
        m = m.as_asphere()
    mirror = AsphericMirror(
        m.R, m.k, m.rim_radius, alpha=(*m.alpha, 0.0), rho_n=m.rho_n, vertex_z=m.vertex_z
    )
    camera = camera.replace(mirror=mirror)
    model = AdjustmentModel(
        adj.free_d, adj.n_d, adj.fit_skew, True, adj.lens_px, None if adj.fit_lens_z else adj.lens_z
    )
    adj2 = BundleAdjustment(camera, mirror, adj.obj, adj.views, adj.rim_px, model)
    boards = [np.concatenate([np.ravel(r), np.ravel(t)]) for r, t in gauged]
    return adj2, np.concatenate([adj2.x0_global, *boards])


def _term_chi2(adj2, x2, n_params, f_scale):
    """How much a short refinement of ``adj2`` from ``x2`` lowers the corners' and the rim's
    robust cost, in units of the residual variance: ``(chi2, short solution)``."""
    rows = slice(0, ResidualGroups.of(adj2).rim.stop)

    def cost(x):
        z = robust_residuals(adj2.residuals(x), f_scale)[0][rows]
        return float(z @ z)

    c0 = cost(x2)
    sigma2 = c0 / max(rows.stop - n_params, 1)
    # (MINPACK's steps, as the shape check's: :func:`.fit_steps._held_shape_chi2`)
    short = adj2.solve(x2, f_scale=f_scale, max_nfev=_TERM_CHECK_NFEV, accelerate=False)
    return (c0 - cost(short.x)) / sigma2, short


def hyperboloid_term_check(rounds: Rounds, options) -> tuple[Rounds, str]:
    """A hyperboloid's fit (the central start's family) tested against the conic with one
    polynomial term by the likelihood-ratio test of :func:`family_step`, its degrees of
    freedom the parameters freed (``alpha4``, and ``R, k`` where the hyperboloid's ``a, b``
    were held): ``(rounds, the report's sentence on the family)``, the hyperboloid's fit where
    it stands, else the asphere's (more terms tested as in :func:`family_step`)."""
    fit, f_scale = rounds.fit, options.f_scale
    dof = 1 if fit.adj.fit_shape else 3
    try:
        adj2, x2 = _with_term(fit, options.image_size)
        chi2, short = _term_chi2(adj2, x2, len(x2), f_scale)
    except ValueError:  # (no conic with a term near it: the hyperboloid stands untested)
        return rounds, ""
    test = (
        f"a conic with alpha4 {{}} the cost by {chi2:.2f} times the residual variance "
        f"({'above' if chi2 > chi2_limit(dof) else 'not above'} {chi2_limit(dof):.2f}, "
        f"chi-square with {dof} degree(s) of freedom at p = 0.001)"
    )
    if not chi2 > chi2_limit(dof):
        held = test.format("would lower")
        return rounds, f"the mirror's family: a hyperboloid, as the central fit's ({held})"
    fit = carried_on(fit, adj2, short.x, f_scale)
    origin = f"the central fit's hyperboloid does not hold: {test.format('lowers')}; alpha4 added"
    return family_step(dataclasses.replace(rounds, fit=fit), options, origin)


def chi2_limit(dof: int) -> float:
    """The chi-square quantile at ``1 - 0.001`` of ``dof`` degrees of freedom."""
    from scipy.stats import chi2

    return float(chi2.ppf(0.999, dof))


def family_step(rounds: Rounds, options, origin: str = "") -> tuple[Rounds, str]:
    """The terms of an aspheric fit's mirror chosen by the likelihood-ratio test (module
    docstring): ``(rounds with the chosen fit, the report's sentence on the family)``;
    ``origin`` says where the fit's terms came from (default: the generic start's)."""
    fit, f_scale = rounds.fit, options.f_scale
    said = []
    while len(fit.adj.mirror.alpha) < min(MAX_TERMS, MAX_ALPHA):
        try:  # (a fit that ran off to a rig that cannot be: the report step says so)
            adj2, x2 = _with_term(fit, options.image_size)
            chi2, short = _term_chi2(adj2, x2, len(x2), f_scale)
        except ValueError:
            break
        name = adj2.shape_names[-1]
        if not chi2 > TERM_ADD_CHI2:
            said.append(f"{name} would lower the cost by {chi2:.2f} times it: not added")
            break
        said.append(f"{name} lowers the cost by {chi2:.0f} times it: added")
        fit = carried_on(fit, adj2, short.x, f_scale)
    n = len(fit.adj.mirror.alpha)
    what = "a conic" if n == 0 else f"a conic with {n} polynomial term(s)"
    note = (
        f"the mirror's family: {what} ("
        + (origin or "the start's terms those that fit the Taylor model's profile best")
        + "; one more tested by a likelihood-ratio test on the adjustment's cost, "
        f"chi-square with 1 degree of freedom above {TERM_ADD_CHI2:g} times the residual "
        f"variance, p = 0.001: " + "; ".join(said) + ")"
    )
    return dataclasses.replace(rounds, fit=fit), note
