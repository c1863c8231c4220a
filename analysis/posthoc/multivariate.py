"""Standard errors of pair contrasts under afex's multivariate model (emmeans on the ``mlm``).

No sphericity: the subjects' cell values have an unstructured covariance Σ, estimated by the pooled
within-group covariance on ``n − groups`` df. For a contrast ``L`` (groups × within cells) of the group
means, ``Var(L) = Σ_g L[g]' Σ L[g] / n_g`` and every contrast has ``df = n − groups`` — emmeans'
``emmeans(afex_fit, …, model = "multivariate")``.
"""

from __future__ import annotations

import numpy as np


def multivariate_weights(L: np.ndarray, n_g: np.ndarray) -> np.ndarray:
    """``B[p] = Σ_g L[p, g] L[p, g]' / n_g``, flattened: pairs × cells², so that Var = B · vec(Σ).

    >>> multivariate_weights(np.array([[[1.0, -1.0]]]), np.array([5])).round(2).tolist()
    [[0.2, -0.2, -0.2, 0.2]]
    """
    B = np.matmul(np.swapaxes(L / n_g[None, :, None], 1, 2), L)
    return B.reshape(len(L), -1)


def multivariate_se(B: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """SE of every pair (…, pairs) from ``B`` (pairs × cells²) and the covariance (…, cells, cells)."""
    flat = cov.reshape(cov.shape[:-2] + (-1,))
    return np.sqrt(np.maximum(flat @ B.T, 0.0))
