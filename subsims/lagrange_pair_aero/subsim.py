"""Algebraic subsim: the listing's aerodynamics of the SRB and parachute, moved out of the pair.

Wire the pair's ``pos_B``, ``vel_B``, ``vel_C`` outputs to the inputs of the same names, and this
subsim's ``force_B``, ``moment_B``, ``force_C``, ``moment_C`` outputs to the pair's extra-load inputs;
run the pair with ``aero=False``. Both use :func:`subsims.lagrange_pair.aero.pair_aero_loads`, so the
coupled pair equals the pair with built-in aerodynamics up to the coupling error.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from cosim.subsim import InputFunction, Port, Subsim
from subsims.lagrange_pair.aero import pair_aero_loads
from subsims.numerics import input_rows

INPUT_PORTS: dict[str, Port] = {
    "pos_B": Port(3, "ft", "SRB CM position, I frame (north, east, down); gives the altitude for the density"),
    "vel_B": Port(3, "ft/s", "SRB CM velocity, B axes"),
    "vel_C": Port(3, "ft/s", "parachute CM velocity, C axes"),
}

OUTPUT_PORTS: dict[str, Port] = {
    "force_B": Port(3, "lbf", "aero force on the SRB at its CM, B axes"),
    "moment_B": Port(3, "lbf*ft", "aero moment on the SRB about its CM, B axes"),
    "force_C": Port(3, "lbf", "aero force on the parachute at its CM, C axes"),
    "moment_C": Port(3, "lbf*ft", "aero moment on the parachute about its CM, C axes"),
}


class LagrangePairAero(Subsim):
    """Aero loads of both bodies from their kinematics; no state, no parameters."""

    name = "lagrange_pair_aero"
    algebraic = True
    inputs = INPUT_PORTS
    outputs = OUTPUT_PORTS

    def initial_state(self, params: Mapping[str, Any]) -> np.ndarray:
        if params:
            raise KeyError(f"lagrange_pair_aero takes no parameters, got {sorted(params)}")
        return np.zeros(0)

    def advance(
        self, state: np.ndarray, times: np.ndarray, u: InputFunction
    ) -> tuple[Mapping[str, np.ndarray], np.ndarray]:
        out = {name: np.empty((len(times), 3)) for name in OUTPUT_PORTS}
        rows = input_rows(u, np.asarray(times, dtype=np.float64), INPUT_PORTS)
        for k, (pos_b, vel_b, vel_c) in enumerate(rows):  # one call of u for all the samples
            loads = pair_aero_loads(-float(pos_b[2]), vel_b, vel_c)
            for name, value in zip(OUTPUT_PORTS, loads, strict=True):
                out[name][k] = value
        return out, np.array(state, dtype=np.float64)
