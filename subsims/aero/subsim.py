"""Subsim adapter of the box aerodynamics (subsystem 3 of the paper; aerodyn.f mode 3)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from cosim.subsim import InputFunction, Param, Port, Subsim
from subsims.aero.model import AeroParams, aero_loads, aero_loads_batch
from subsims.numerics import as_table
from subsims.satellite import constants as C

# samples from which one NumPy pass over all of them beats a loop of the scalar form (about 50 us against 2.5 us a
# sample, measured on the 2-core machine: 17 samples 53 vs 46 us, 33 samples 60 vs 87 us)
BATCH_FROM = 20


class Aero(Subsim):
    """Six-facet box in free-molecular drag, constant density. Algebraic: evaluated at the sample times only.

    Parameters (``params``; all optional, the paper's values by default).
    """

    name = "aero"
    algebraic = True
    inputs = {
        "R_body": Port(3, "m", "orbit radius in body axes (unused: density is constant)"),
        "V_body": Port(3, "m/s", "flow-relative (= inertial) velocity in body axes"),
    }
    outputs = {
        "force": Port(3, "N", "aerodynamic force, body (= geometric) axes, acting at the geometric origin"),
        "torque": Port(3, "N m", "aerodynamic torque about the geometric origin, body axes"),
    }

    params = {  # the names of model.PARAM_NAMES; defaults those of AeroParams.from_mapping (spec §7.6)
        "rho": Param(C.RHO, "kg/m^3", "atmospheric density, constant, >= 0"),
        "cd": Param(C.CD, "", "drag coefficient, the same for all facets, >= 0"),
        "length": Param(C.BOX_LENGTH, "m", "box along body x, > 0"),
        "width": Param(C.BOX_WIDTH, "m", "box along body y, > 0"),
        "height": Param(C.BOX_HEIGHT, "m", "box along body z, > 0"),
    }

    def initial_state(self, params: Mapping[str, Any]) -> np.ndarray:
        self.p = AeroParams.from_mapping(params)
        self.facets = self.p.facets
        return np.empty(0, dtype=np.float64)

    def advance(
        self, state: np.ndarray, times: np.ndarray, u: InputFunction
    ) -> tuple[dict[str, np.ndarray], np.ndarray]:
        times = np.asarray(times, dtype=np.float64)
        velocity = as_table(u(times)["V_body"], times.size, 3, "V_body")
        if times.size >= BATCH_FROM:  # one NumPy pass; both forms give the same bits
            force, torque = aero_loads_batch(velocity, self.p, self.facets)
        else:
            loads = [aero_loads(v, self.p, self.facets) for v in velocity.tolist()]
            force, torque = (np.array(x, dtype=np.float64).reshape(-1, 3) for x in zip(*loads))
        return {"force": force, "torque": torque}, np.empty(0, dtype=np.float64)
