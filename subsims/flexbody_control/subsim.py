"""Subsim adapter of the flexbody attitude controller (algebraic: no state).

inputs   euler123 (3, rad): the flexbody's 1-2-3 Euler angles; omega (3, rad/s): its body rates.
outputs  tau0 (3, torque units): torque at O_g, body axes, for the flexbody's ``tau0`` input.

Parameters (``law.DEFAULT_CONTROL``): ``law`` "pd" (tau0 = -(kp (theta - theta_cmd) + kd omega)) with ``kp``,
``kd``, ``theta_cmd_deg``; or "bang_bang" (open loop, spec AT-10) with ``torque``, ``t_on``, ``t_switch``, ``t_off``.
The bang-bang output is piecewise constant inside every interval: at a switch that is the interval's last sample
it reports the left limit, so a linearly interpolated input never ramps across the switch when switches fall on
interval boundaries (spec §4.1 R3).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from cosim.subsim import InputFunction, Param, Port, Subsim
from subsims.flexbody_control.law import DEFAULT_CONTROL, ControlParams, control_torque
from subsims.numerics import input_rows


class AttitudeControl(Subsim):
    """PD attitude control on the report's Euler angles, or a bang-bang slew, for the flexbody."""

    name = "flexbody_control"
    algebraic = True
    inputs = {
        "euler123": Port(3, "rad", "flexbody 1-2-3 Euler angles (report eq. 7-1)"),
        "omega": Port(3, "rad/s", "flexbody body rates"),
    }
    outputs = {"tau0": Port(3, "lbf*ft", "control torque at O_g, body axes")}
    params = {  # the keys of law.DEFAULT_CONTROL, with its values; units of the flexbody's slug-ft-lbf-s
        "law": Param(DEFAULT_CONTROL["law"], "", '"pd": tau0 = -(kp (theta - theta_cmd) + kd omega), or "bang_bang": '
                     "open loop (spec AT-10)"),
        "kp": Param(DEFAULT_CONTROL["kp"], "lbf*ft/rad", "pd: angle gains per body axis"),
        "kd": Param(DEFAULT_CONTROL["kd"], "lbf*ft*s/rad", "pd: rate gains per body axis"),
        "theta_cmd_deg": Param(DEFAULT_CONTROL["theta_cmd_deg"], "deg", "pd: commanded 1-2-3 Euler angles"),
        "torque": Param(DEFAULT_CONTROL["torque"], "lbf*ft", "bang_bang: torque at O_g, body axes, for t_on <= t < "
                        "t_switch; minus it for t_switch <= t < t_off; zero otherwise"),
        "t_on": Param(DEFAULT_CONTROL["t_on"], "s", "bang_bang: start of the torque, t_on <= t_switch"),
        "t_switch": Param(DEFAULT_CONTROL["t_switch"], "s", "bang_bang: the torque reverses, t_switch <= t_off"),
        "t_off": Param(DEFAULT_CONTROL["t_off"], "s", "bang_bang: end of the torque"),
    }

    def initial_state(self, params: Mapping[str, Any]) -> np.ndarray:
        self.p = ControlParams.from_mapping(params)
        return np.empty(0, dtype=np.float64)

    def advance(
        self, state: np.ndarray, times: np.ndarray, u: InputFunction
    ) -> tuple[Mapping[str, np.ndarray], np.ndarray]:
        times = np.asarray(times, dtype=np.float64)
        rows = input_rows(u, times, self.inputs)  # one call for all the samples
        last = times.size - 1
        tau = np.array([control_torque(self.p, tt, euler, omega, left=k == last and k > 0)
                        for k, (tt, (euler, omega)) in enumerate(zip(times.tolist(), rows))]).reshape(-1, 3)
        return {"tau0": tau}, np.array(state, dtype=np.float64)
