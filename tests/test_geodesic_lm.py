"""Levenberg-Marquardt with geodesic acceleration (chessboard.geodesic_lm) on curved valleys."""

import numpy as np
from scipy.optimize import least_squares

from omnicam.chessboard.geodesic_lm import geodesic_lm


def _banana(scale):
    """Rosenbrock's valley as least squares, bent ``scale`` times: ``(scale (y - x^2), 1 - x)``,
    minimum 0 at (1, 1)."""

    def fun(p):
        return np.array([scale * (p[1] - p[0] ** 2), 1.0 - p[0]])

    def jac(p):
        return np.array([[-2.0 * scale * p[0], scale], [-1.0, 0.0]])

    return fun, jac


def test_reaches_the_end_of_a_curved_valley_in_fewer_jacobians_than_minpack():
    fun, jac = _banana(1000.0)
    x0 = np.array([-1.2, 1.0])
    sol = geodesic_lm(fun, jac, x0, max_nfev=2000, tol=1e-12)
    ref = least_squares(fun, x0, jac=jac, method="lm", x_scale="jac", xtol=1e-12, ftol=1e-12)
    assert sol.success and sol.status in (1, 2, 3)
    np.testing.assert_allclose(sol.x, [1.0, 1.0], atol=1e-6)
    assert sol.cost < 1e-12 and np.isclose(sol.cost, 0.5 * sol.fun @ sol.fun)
    assert sol.njev < ref.njev  # the acceleration follows the bend


def test_stops_at_max_nfev_and_says_so():
    fun, jac = _banana(1000.0)
    sol = geodesic_lm(fun, jac, np.array([-1.2, 1.0]), max_nfev=9)
    assert sol.nfev <= 9 and sol.status == 0 and not sol.success
    assert "maximum number" in sol.message


def test_a_start_at_the_minimum_stops_at_once():
    fun, jac = _banana(10.0)
    sol = geodesic_lm(fun, jac, np.array([1.0, 1.0]), max_nfev=100)
    assert sol.success and sol.nfev == 1
    np.testing.assert_array_equal(sol.x, [1.0, 1.0])


def test_a_linear_problem_is_solved_exactly():
    rng = np.random.default_rng(0)
    A, b = rng.normal(size=(30, 4)), rng.normal(size=30)
    sol = geodesic_lm(lambda x: A @ x - b, lambda x: A, np.zeros(4), max_nfev=100)
    np.testing.assert_allclose(sol.x, np.linalg.lstsq(A, b, rcond=None)[0], atol=1e-8)
