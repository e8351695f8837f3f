"""Double integrator y'' = u; outputs y and its rate v."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from cosim.subsim import InputFunction, Param, Port, Subsim
from subsims.integrator.model import integrate_twice
from subsims.integrator.subsim import _vector


class DoubleIntegrator(Subsim):
    """y'' = u. Parameters in ``params``. State: (y, v)."""

    name = "double_integrator"
    inputs = {"u": Port(1, "", "second derivative of y")}
    outputs = {"y": Port(1), "v": Port(1)}
    params = {
        "size": Param(1, "", "width of u, y and v"),
        "y0": Param(0.0, "", "y at the start time: a list of size numbers, or one number for all"),
        "v0": Param(0.0, "", "v = y' at the start time: a list of size numbers, or one number for all"),
    }

    def initial_state(self, params: Mapping[str, Any]) -> np.ndarray:
        self.size = size = int(params["size"])
        self.inputs = {"u": Port(size, "", "second derivative of y")}
        self.outputs = {"y": Port(size), "v": Port(size)}
        return np.concatenate([_vector(params, "y0", size), _vector(params, "v0", size)])

    def advance(self, state: np.ndarray, times: np.ndarray, u: InputFunction):
        y, v = integrate_twice(lambda t: u(t)["u"], times, state[: self.size], state[self.size :])
        return {"y": y, "v": v}, np.concatenate([y[-1], v[-1]])
