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
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..asphere import MAX_ALPHA, AsphericMirror
from .adjustment import AdjustmentModel, BundleAdjustment, robust_residuals
from .fit_steps import AdjustmentStep, ResidualGroups, Rounds

__all__ = ["MAX_TERMS", "TERM_ADD_CHI2", "family_step"]

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


def family_step(rounds: Rounds, options) -> tuple[Rounds, str]:
    """The terms of an aspheric fit's mirror chosen by the likelihood-ratio test (module
    docstring): ``(rounds with the chosen fit, the report's sentence on the family)``."""
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
        sol2 = adj2.solve(short.x, f_scale=f_scale, max_nfev=400)
        r = adj2.corner_residuals(sol2.x).reshape(len(fit.used), -1)
        vr = {i: float(np.sqrt(np.mean(r[k] ** 2) * 2)) for k, i in enumerate(fit.used)}
        fit = dataclasses.replace(fit, adj=adj2, sol=sol2, view_rms=vr)
    n = len(fit.adj.mirror.alpha)
    what = "a conic" if n == 0 else f"a conic with {n} polynomial term(s)"
    note = (
        f"the mirror's family: {what} (the start's terms those that fit the Taylor model's "
        f"profile best; one more tested by a likelihood-ratio test on the adjustment's cost, "
        f"chi-square with 1 degree of freedom above {TERM_ADD_CHI2:g} times the residual "
        f"variance, p = 0.001: " + "; ".join(said) + ")"
    )
    fit = dataclasses.replace(fit, warnings=(*fit.warnings, note))
    return dataclasses.replace(rounds, fit=fit), note
