"""Subsim adapter: one mass with its own spring to ground; the coupling spring's force is an input."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from cosim.subsim import InputFunction, Port, Subsim
from subsims.oscillator.model import integrate


class Mass(Subsim):
    """Parameters: ``m`` (1), ``k`` spring to ground (4 pi^2), ``u0``, ``v0`` (0), ``idiv`` RK4 steps per sample (1)."""

    name = "mass"
    inputs = {"F": Port(1, "N", "force of the coupling spring on this mass")}
    outputs = {"u": Port(1, "m", "displacement"), "v": Port(1, "m/s", "velocity")}

    def initial_state(self, params: Mapping[str, Any]) -> np.ndarray:
        self.m = float(params.get("m", 1.0))
        self.k = float(params.get("k", 4 * np.pi**2))
        self.idiv = int(params.get("idiv", 1))
        if self.m <= 0 or self.idiv < 1:
            raise ValueError(f"need m > 0 and idiv >= 1, got m={self.m}, idiv={self.idiv}")
        return np.array([float(params.get("u0", 0.0)), float(params.get("v0", 0.0))])

    def advance(self, state: np.ndarray, times: np.ndarray, u: InputFunction):
        x = integrate(state, times, lambda ts: u(ts)["F"], self.m, self.k, self.idiv)
        return {"u": x[:, :1], "v": x[:, 1:]}, x[-1]
