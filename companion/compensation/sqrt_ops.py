"""Square-root building blocks for the SR-UKF (Van der Merwe & Wan 2001, section 3).

- :func:`cholupdate`: rank-1 update or downdate of a lower-triangular Cholesky factor,
  S S^T +/- v v^T = S' S'^T (Golub & Van Loan, "Matrix Computations", sec. 6.5.4; the LINPACK
  dchud/dchdd recurrence with plane rotations), O(n^2), never forming S S^T.
- :func:`tria`: the ``qr()`` of Van der Merwe & Wan / Shi et al. eq. (14), (18): for a compound matrix
  A (n x m, m >= n) returns the lower-triangular S with S S^T = A A^T, i.e. the transpose of the upper
  triangle R of the QR decomposition A^T = Q R, with a positive diagonal.

The state dimension here is 7, for which a scalar Python loop beats numpy's per-call overhead.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import lapack


class DowndateError(ArithmeticError):
    """A Cholesky downdate would make the matrix indefinite (S S^T - v v^T not positive definite)."""


def cholupdate(S: np.ndarray, v: np.ndarray, sign: float = 1.0) -> np.ndarray:
    """Return lower-triangular S' with S' S'^T = S S^T + sign * v v^T (sign = +1 update, -1 downdate).

    For k = 0..n-1 (Golub & Van Loan 6.5.4)::

        r = sqrt(S_kk^2 + sign v_k^2),  c = r / S_kk,  s = v_k / S_kk,  S'_kk = r
        S'_ik = (S_ik + sign s v_i) / c,  v_i <- c v_i - s S'_ik      (i > k)

    ``S`` must have a positive diagonal; the result has one too. Raises :class:`DowndateError` when a
    downdate would lose positive definiteness.
    """
    cols = S.T.tolist()  # cols[k][i] = S[i, k]
    v = [float(t) for t in v]
    n = len(v)
    for k in range(n):
        col = cols[k]
        skk = col[k]
        vk = v[k]
        r2 = skk * skk + sign * vk * vk
        if not r2 > 0.0 or not skk > 0.0:
            raise DowndateError(f"cholupdate: pivot {k} would be {r2:.3g} (matrix not positive definite)")
        r = math.sqrt(r2)
        c = r / skk
        s = vk / skk
        col[k] = r
        ss = sign * s
        ic = 1.0 / c
        for i in range(k + 1, n):
            sik = (col[i] + ss * v[i]) * ic
            col[i] = sik
            v[i] = c * v[i] - s * sik
    return np.array(cols).T


def tria(A: np.ndarray) -> np.ndarray:
    """Lower-triangular S (positive diagonal) with S S^T = A A^T, via the QR decomposition of A^T."""
    n = A.shape[0]
    qr, _tau, _work, info = lapack.dgeqrf(A.T)
    if info != 0:  # pragma: no cover - LAPACK argument error
        raise ArithmeticError(f"dgeqrf failed, info={info}")
    mask = _UPPER.get(n)
    if mask is None:
        mask = _UPPER[n] = np.triu(np.ones((n, n)))
    R = qr[:n, :n] * mask
    sign = np.where(R.diagonal() < 0.0, -1.0, 1.0)
    return (R * sign[:, None]).T


_UPPER: dict[int, np.ndarray] = {}


def tril_inverse(S: np.ndarray) -> np.ndarray:
    """Inverse of a lower-triangular matrix (LAPACK dtrtri)."""
    inv, info = lapack.dtrtri(S, lower=1)
    if info != 0:
        raise DowndateError(f"singular triangular factor (dtrtri info={info})")
    return inv
