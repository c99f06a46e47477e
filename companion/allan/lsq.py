"""Small numpy-only solvers for the online estimators, so that `companion run` never loads scipy.

- :func:`nnls`: non-negative least squares, min ||A x - b||_2 subject to x >= 0, by the active-set
  algorithm of Lawson & Hanson, *Solving Least Squares Problems* (1974), ch. 23 (the algorithm
  ``scipy.optimize.nnls`` implements). Meant for the estimators' few columns (<= a dozen).
- :func:`exp_sum`: the final value of the first-order recursion S_k = lam S_{k-1} + x_k, bit for bit
  what ``scipy.signal.lfilter([1], [1, -lam], x, zi=[lam S_0])[0][-1]`` returns.

Importing scipy costs 50-80 MB of resident memory and 0.3-1.4 s of CPU on a small board; these two
(with :mod:`companion.allan.special` for the root finder, bounded minimiser and chi-square quantiles of
the fit) replace the scipy calls the live pipeline would make (tests/cli/test_startup.py and
tests/allan/test_special.py compare them with scipy).
"""

from __future__ import annotations

import math

import numpy as np


def _norm(r: np.ndarray) -> float:
    """||r||_2 of a 1-D float array: the value ``np.linalg.norm`` gives (the same sqrt of r.r), without its
    argument checks (the fits call this thousands of times on a few dozen points)."""
    return math.sqrt(float(r.dot(r)))


def nnls(A, b, max_iter: int | None = None):
    """``(x, rnorm)``: argmin ||A x - b|| with x >= 0 (Lawson-Hanson active set)."""
    A = np.asarray(A, dtype=float)
    b = np.asarray(b, dtype=float)
    m, n = A.shape
    x = np.zeros(n)
    passive = np.zeros(n, dtype=bool)
    max_iter = 3 * n + 30 if max_iter is None else max_iter
    if 0 < n <= m:
        # the unconstrained least-squares solution, when every coefficient is positive, is the solution (the
        # problem is convex and it meets the Kuhn-Tucker conditions with every column free): the model fits
        # select their terms so that this is the common case, and it is one solve instead of one per column
        z, _, rank, _ = np.linalg.lstsq(A, b, rcond=None)
        if rank == n and np.all(z > 0):
            return z, _norm(A @ z - b)
    # the gradient w = A^T (b - A x) is "zero" below rounding of its own size
    tol = 10.0 * np.finfo(float).eps * max(m, n) * max(np.linalg.norm(A, 1), 1e-300) * max(np.linalg.norm(b), 1e-300)
    w = A.T @ b
    it = 0
    while (~passive).any() and it < max_iter:
        cand = np.where(passive, -np.inf, w)
        j = int(np.argmax(cand))
        if not cand[j] > tol:
            break  # Kuhn-Tucker conditions hold: optimal
        passive[j] = True
        first = True
        while True:  # inner loop: keep the passive-set solution feasible
            it += 1
            idx = np.flatnonzero(passive)
            z = np.zeros(n)
            z[idx] = np.linalg.lstsq(A[:, idx], b, rcond=None)[0]
            if np.all(z[idx] > 0):
                x = z
                break
            if first and z[j] <= 0:  # rounding: the column that looked uphill is not; x stays optimal
                passive[j] = False
                return x, _norm(A @ x - b)
            first = False
            if it >= max_iter:
                passive = x > 0
                break
            neg = idx[z[idx] <= 0]
            ratios = x[neg] / (x[neg] - z[neg])
            alpha = np.min(ratios)
            x = x + alpha * (z - x)
            x[neg[ratios <= alpha]] = 0.0  # the blocking variable(s) leave exactly
            passive &= x > 0.0
            x[~passive] = 0.0
        w = A.T @ (b - A @ x)
    return x, _norm(A @ x - b)


def exp_sum(x, lam: float, s0: float) -> float:
    """Final value of S_k = lam S_{k-1} + x_k from S_{-1} = s0 over a 1-D ``x``, summed in order.

    Bit-for-bit what ``scipy.signal.lfilter([1], [1, -lam], x, zi=[lam * s0])[0][-1]`` returns (same
    operations in the same order), so results do not depend on how the samples were split into blocks.
    """
    s = float(s0)
    lam = float(lam)
    for v in np.asarray(x, dtype=float).tolist():
        s = lam * s + v
    return s
