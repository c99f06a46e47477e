"""The fit's least squares remember their designs' solutions and columns: the same numbers as a fresh solve, and a
caller changing what it got back changes nothing remembered."""

from __future__ import annotations

import numpy as np

from companion.allan.fit import gls
from companion.allan.terms import linear_basis


def _problem(seed=3):
    rng = np.random.default_rng(seed)
    tau = 0.01 * 2.0 ** np.arange(12)
    A = linear_basis(tau, ["white_noise", "bias_instability", "random_walk"])
    v = A @ np.array([1.0, 0.02, 0.001]) * (1 + 0.05 * rng.normal(size=tau.shape[0]))
    corr = 0.6 ** np.abs(np.subtract.outer(np.arange(12), np.arange(12)))
    cov = corr * np.outer(0.05 * v, 0.05 * v)
    return tau, v, cov


def test_a_design_solved_again_gives_a_fresh_solve():
    tau, v, cov = _problem()
    linear = ["white_noise", "bias_instability", "random_walk"]
    prob = gls._Problem(tau, v, cov)
    theta, c2 = prob.solve(gls._columns(linear, [], tau))
    theta[:] = -1.0  # the caller's copy: the remembered solution stays
    again, c2_again = prob.solve(gls._columns(linear, [], tau))
    fresh, c2_fresh = gls._Problem(tau, v, cov)._solve(linear_basis(tau, linear))
    assert np.array_equal(again, fresh) and c2_again == c2_fresh == c2
    assert not np.array_equal(again, theta)  # the -1s did not reach it
    # another design on the same problem is its own solve
    other, _ = prob.solve(gls._columns(["white_noise", "random_walk"], [], tau))
    assert other.shape == (2,)


def test_remembered_columns_are_the_basis_and_read_only():
    tau, _, _ = _problem()
    col = gls._linear_column(tau, "bias_instability")
    assert np.array_equal(col, linear_basis(tau, ["bias_instability"])[:, 0])
    assert not col.flags.writeable
    A = gls._columns(["white_noise", "bias_instability"], [], tau)
    A[:, 1] = 0.0  # a design is the caller's own array
    assert np.array_equal(gls._linear_column(tau, "bias_instability"), col) and np.all(col > 0)
