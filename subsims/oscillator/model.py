"""m u'' = -k u + F(t): the shared RK4 (``subsims.numerics.rk4``), ``idiv`` steps per sample, F read at RK stages."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from subsims.numerics import as_table, rk4


def derivative(x: Sequence[float], force: float, m: float, k: float) -> tuple[float, float]:
    """(u', v') = (v, (F - k u) / m), on Python floats: a numpy array per RK stage would cost more than the sum."""
    u, v = x
    return v, (force - k * u) / m


def integrate(
    x0: np.ndarray, times: np.ndarray, force: Callable[[np.ndarray], np.ndarray], m: float, k: float, idiv: int
) -> np.ndarray:
    """States (n, 2) = (u, v) at every sample time; ``force(ts)``: F at all the RK times (k,) in one call."""
    states, _, _ = rk4(lambda t, x, f: derivative(x, f, m, k), [float(v) for v in x0], times, idiv,
                       lambda ts: as_table(force(ts), ts.size, 1, "F")[:, 0].tolist())
    return np.array(states, dtype=np.float64)


def energy(u1: np.ndarray, v1: np.ndarray, u2: np.ndarray, v2: np.ndarray, m=1.0, k1=4 * np.pi**2,
           k2=4 * np.pi**2, k12=16 * np.pi**2) -> np.ndarray:
    """Total energy of the two-mass three-spring chain (10 pi^2 for the benchmark's start)."""
    return 0.5 * m * (v1**2 + v2**2) + 0.5 * (k1 * u1**2 + k2 * u2**2 + k12 * (u1 - u2) ** 2)
