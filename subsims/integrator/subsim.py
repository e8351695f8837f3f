"""Single integrator y' = u (the paper's §2.3 building block)."""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from cosim.subsim import InputFunction, Port, Subsim
from subsims.integrator.model import integrate_once


def _vector(params: Mapping[str, Any], key: str, size: int) -> np.ndarray:
    v = np.atleast_1d(np.asarray(params.get(key, np.zeros(size)), dtype=float))
    if v.shape != (size,):
        raise ValueError(f"{key} must have {size} entries, got {v.size}")
    return v


class Integrator(Subsim):
    """y' = u. Parameters: ``size`` (default 1), ``y0`` (default zeros), and ``compute_delay``:
    seconds each ``advance`` sleeps, to stand in for an expensive model in benchmarks and fault tests."""

    name = "integrator"
    inputs = {"u": Port(1, "", "rate of y")}
    outputs = {"y": Port(1)}

    def initial_state(self, params: Mapping[str, Any]) -> np.ndarray:
        size = int(params.get("size", 1))
        if not 1 <= size <= 100_000:
            raise ValueError(f"size must be between 1 and 100000, got {size}")
        self.inputs = {"u": Port(size, "", "rate of y")}
        self.outputs = {"y": Port(size)}
        self.compute_delay = float(params.get("compute_delay", 0.0))
        return _vector(params, "y0", size)

    def advance(self, state: np.ndarray, times: np.ndarray, u: InputFunction):
        if self.compute_delay > 0:
            time.sleep(self.compute_delay)
        y = integrate_once(lambda t: u(t)["u"], times, state)
        return {"y": y}, y[-1]
