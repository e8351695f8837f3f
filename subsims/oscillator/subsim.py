"""Subsim adapter: one mass with its own spring to ground; the coupling spring's force is an input."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from cosim.subsim import InputFunction, Param, Port, Subsim
from subsims.adapters import reports_physics_errors
from subsims.oscillator.model import integrate


class Mass(Subsim):
    """One mass on a spring to ground, m u'' = -k u + F, classical RK4 with ``idiv`` steps per sample."""

    name = "mass"
    inputs = {"F": Port(1, "N", "force of the coupling spring on this mass")}
    outputs = {"u": Port(1, "m", "displacement"), "v": Port(1, "m/s", "velocity")}
    params = {
        "m": Param(1.0, "kg", "mass, > 0"),
        "k": Param(4 * np.pi**2, "N/m", "stiffness of everything that pulls the mass back to u = 0"),
        "u0": Param(0.0, "m", "displacement at the start time"),
        "v0": Param(0.0, "m/s", "velocity at the start time"),
        "idiv": Param(1, "", "RK4 steps per sample interval, >= 1 (the input F is interpolated at the RK stages)"),
    }

    def initial_state(self, params: Mapping[str, Any]) -> np.ndarray:
        self.m, self.k, self.idiv = float(params["m"]), float(params["k"]), int(params["idiv"])
        if not self.m > 0 or self.idiv < 1:  # (not m > 0: NaN too)
            raise ValueError(f"need m > 0 and idiv >= 1, got m={self.m}, idiv={self.idiv}")
        state = np.array([float(params["u0"]), float(params["v0"])])
        bad = [k for k, v in (("m", self.m), ("k", self.k), ("u0", state[0]), ("v0", state[1])) if not np.isfinite(v)]
        if bad:
            raise ValueError(f"{', '.join(bad)} must be finite numbers")
        return state

    @reports_physics_errors
    def advance(self, state: np.ndarray, times: np.ndarray, u: InputFunction):
        x = integrate(state, times, lambda ts: u(ts)["F"], self.m, self.k, self.idiv)
        return {"u": x[:, :1], "v": x[:, 1:]}, x[-1]
