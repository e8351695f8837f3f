"""m u'' = -k u + F(t), classical RK4 with ``idiv`` steps per sample, F interpolated at RK stages."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


def derivative(x: np.ndarray, force: float, m: float, k: float) -> np.ndarray:
    u, v = x
    return np.array([v, (force - k * u) / m])


def rk4_step(f: Callable[[float, np.ndarray], np.ndarray], t: float, x: np.ndarray, h: float) -> np.ndarray:
    k1 = f(t, x)
    k2 = f(t + h / 2, x + h / 2 * k1)
    k3 = f(t + h / 2, x + h / 2 * k2)
    k4 = f(t + h, x + h * k3)
    return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def integrate(
    x0: np.ndarray, times: np.ndarray, force: Callable[[float], float], m: float, k: float, idiv: int
) -> np.ndarray:
    """States (n, 2) = (u, v) at every sample time."""
    out = np.empty((times.size, 2))
    out[0] = x = x0
    f = lambda t, x: derivative(x, force(t), m, k)  # noqa: E731
    for i in range(times.size - 1):
        h = (times[i + 1] - times[i]) / idiv
        for j in range(idiv):
            x = rk4_step(f, times[i] + j * h, x, h)
        out[i + 1] = x
    return out


def energy(u1: np.ndarray, v1: np.ndarray, u2: np.ndarray, v2: np.ndarray, m=1.0, k1=4 * np.pi**2,
           k2=4 * np.pi**2, k12=16 * np.pi**2) -> np.ndarray:
    """Total energy of the two-mass three-spring chain (10 pi^2 for the benchmark's start)."""
    return 0.5 * m * (v1**2 + v2**2) + 0.5 * (k1 * u1**2 + k2 * u2**2 + k12 * (u1 - u2) ** 2)
