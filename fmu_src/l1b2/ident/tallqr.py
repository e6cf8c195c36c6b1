"""The R factor of a tall matrix by blocks of rows (tall-skinny QR), for the compressed trust-region steps.

One Householder QR of an n x p matrix with n >> p (LAPACK ``geqrf``: for p up to its block width the
factorisation is column by column, every column a pass over all n rows) is bound by memory traffic. The
same R comes from blocks of rows that fit in the cache: ``A = [A_1; ...; A_m]``, ``A_i = Q_i R_i``, then
one QR of the stacked ``[R_1; ...; R_m]`` ((m p) x p). Every step is an orthogonal transformation, so
``R^T R = A^T A`` and the result is backward stable like one QR of ``A``; R is unique up to the signs of
its rows (each row of R and of the compressed residual flips together, which leaves norms, gradients and
Gauss-Newton matrices unchanged).
"""

from __future__ import annotations

import numpy as np

#: rows per block (a block of 1024 rows of a few tens of columns stays in the cache)
BLOCK_ROWS = 1024


def r_factor(A: np.ndarray, block_rows: int = BLOCK_ROWS) -> np.ndarray:
    """The upper-triangular R (min(n, p) x p) of ``A = Q R`` (n x p), computed block by block of rows.

    ``block_rows <= 0`` or ``n <= 2 * block_rows``: one Householder QR (``numpy.linalg.qr(A, mode="r")``).
    """
    A = np.asarray(A, float)
    n, p = A.shape
    if block_rows <= 0 or n <= 2 * max(block_rows, p):
        return np.linalg.qr(A, mode="r")
    b = max(int(block_rows), p)
    stacked = np.vstack([np.linalg.qr(A[i:i + b], mode="r") for i in range(0, n, b)])
    return np.linalg.qr(stacked, mode="r")
