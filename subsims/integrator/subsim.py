"""Single integrator y' = u (the paper's §2.3 building block)."""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from cosim.subsim import InputFunction, Param, Port, Subsim
from subsims.integrator.model import integrate_once


def _vector(params: Mapping[str, Any], key: str, size: int) -> np.ndarray:
    """``params[key]``: a list of ``size`` numbers, or one number for all of them."""
    v = np.asarray(params[key], dtype=float)
    v = np.full(size, v) if v.ndim == 0 else v
    if v.shape != (size,):
        raise ValueError(f"{key} must have {size} entries, got {v.size}")
    return v


class Integrator(Subsim):
    """y' = u. Parameters in ``params``; ``compute_delay`` is the
    seconds each ``advance`` sleeps, to stand in for an expensive model in benchmarks and fault tests."""

    name = "integrator"
    inputs = {"u": Port(1, "", "rate of y")}
    outputs = {"y": Port(1)}
    params = {
        "size": Param(1, "", "width of u and y, 1 to 100000"),
        "y0": Param(0.0, "", "y at the start time: a list of size numbers, or one number for all"),
        "compute_delay": Param(0.0, "s", "wall-clock seconds each advance sleeps (benchmarks, fault tests)"),
    }

    def initial_state(self, params: Mapping[str, Any]) -> np.ndarray:
        size = int(params["size"])
        if not 1 <= size <= 100_000:
            raise ValueError(f"size must be between 1 and 100000, got {size}")
        self.inputs = {"u": Port(size, "", "rate of y")}
        self.outputs = {"y": Port(size)}
        self.compute_delay = float(params["compute_delay"])
        if not 0 <= self.compute_delay < float("inf"):
            raise ValueError(f"compute_delay must be a finite number of seconds >= 0, got {self.compute_delay}")
        return _vector(params, "y0", size)

    def advance(self, state: np.ndarray, times: np.ndarray, u: InputFunction):
        if self.compute_delay > 0:
            time.sleep(self.compute_delay)
        y = integrate_once(lambda t: u(t)["u"], times, state)
        return {"y": y}, y[-1]
