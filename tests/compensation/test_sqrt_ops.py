"""Cholesky rank-1 update/downdate and QR triangularisation against dense numpy factorisations."""

import numpy as np
import pytest

from companion.compensation.sqrt_ops import DowndateError, cholupdate, tria, tril_inverse


def random_spd(n, rng):
    A = rng.standard_normal((n, n + 3))
    return A @ A.T + 0.1 * np.eye(n)


@pytest.mark.parametrize("n", [1, 2, 5, 7])
def test_cholupdate_update_and_downdate(n):
    rng = np.random.default_rng(n)
    for _ in range(20):
        P = random_spd(n, rng)
        S = np.linalg.cholesky(P)
        v = rng.standard_normal(n)
        Su = cholupdate(S, v, +1.0)
        assert np.allclose(Su, np.tril(Su)) and np.all(np.diag(Su) > 0)
        assert np.allclose(Su @ Su.T, P + np.outer(v, v), rtol=1e-10, atol=1e-10)
        assert np.allclose(Su, np.linalg.cholesky(P + np.outer(v, v)), rtol=1e-9, atol=1e-10)
        # a downdate that keeps P positive definite: v scaled so that v^T P^-1 v = 0.5
        w = v / np.sqrt(2.0 * v @ np.linalg.solve(P, v))
        Sd = cholupdate(S, w, -1.0)
        assert np.allclose(Sd @ Sd.T, P - np.outer(w, w), rtol=1e-9, atol=1e-10)
        assert np.allclose(cholupdate(Su, v, -1.0), S, rtol=1e-8, atol=1e-9)


def test_downdate_to_indefinite_raises():
    S = np.linalg.cholesky(np.array([[2.0, 0.5], [0.5, 1.0]]))
    with pytest.raises(DowndateError):
        cholupdate(S, np.array([2.0, 0.0]), -1.0)


def test_tria_and_inverse():
    rng = np.random.default_rng(0)
    for m in (7, 14, 15):
        A = rng.standard_normal((7, m))
        S = tria(A)
        assert np.allclose(S, np.tril(S)) and np.all(np.diag(S) > 0)
        assert np.allclose(S @ S.T, A @ A.T)
        assert np.allclose(tril_inverse(S) @ S, np.eye(7))
