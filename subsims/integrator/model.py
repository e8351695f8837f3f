"""Exact quadrature of an input interpolant between sample times.

The interpolants of ``cosim.signals`` are polynomials of degree <= n-1 on each sample step, so
Gauss-Legendre with ceil(n/2)+1 nodes per step integrates them exactly (degree 2p-1 >= n).
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np


@functools.lru_cache(maxsize=64)
def gauss_nodes(n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on [0, 1], exact for degree <= n_samples."""
    p = n_samples // 2 + 2
    x, w = np.polynomial.legendre.leggauss(p)
    return 0.5 * (x + 1.0), 0.5 * w


def _node_values(f: Callable[[np.ndarray], np.ndarray], times: np.ndarray, x: np.ndarray) -> np.ndarray:
    """f at every step's nodes t_i + h_i x_k, in ONE call: (n-1, p, size)."""
    h = times[1:] - times[:-1]
    ts = times[:-1, None] + h[:, None] * x[None, :]
    return np.asarray(f(ts.ravel()), dtype=np.float64).reshape(ts.shape + (-1,))


def integrate_once(f: Callable[[np.ndarray], np.ndarray], times: np.ndarray, y0: np.ndarray) -> np.ndarray:
    """y(t_i) = y0 + integral of f from t_0 to t_i, at every sample time (y' = u); ``f(ts)`` -> (k, size)."""
    x, w = gauss_nodes(times.size)
    fs = _node_values(f, times, x)
    steps = (times[1:] - times[:-1])[:, None] * np.einsum("k,skm->sm", w, fs)
    return np.cumsum(np.concatenate((y0[None, :], steps)), axis=0)  # y[i+1] = y[i] + step i, in order


def integrate_twice(
    f: Callable[[np.ndarray], np.ndarray], times: np.ndarray, y0: np.ndarray, v0: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """y'' = u: v = v0 + int u, y = y0 + v0 (t - t0) + int (t - s) u(s) ds, per step; ``f(ts)`` -> (k, size)."""
    x, w = gauss_nodes(times.size + 1)
    fs = _node_values(f, times, x)
    h = times[1:] - times[:-1]
    dv = h[:, None] * np.einsum("k,skm->sm", w, fs)
    moment = (h * h)[:, None] * np.einsum("k,skm->sm", w * (1.0 - x), fs)
    v = np.cumsum(np.concatenate((v0[None, :], dv)), axis=0)
    y = np.empty_like(v)
    y[0] = y0
    for i in range(h.size):
        y[i + 1] = y[i] + h[i] * v[i] + moment[i]
    return y, v
