"""Control laws as plain functions (no state): torque at O_g in body axes."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

LAWS = ("pd", "bang_bang")

# Defaults sized for the report's vehicle (composite inertia about its mass centre J = diag(642.8, 2.083, 641.6)
# slug ft^2): per axis w_n = 0.2 rad/s and zeta = 0.7 for the rigid composite, kp = J w_n^2, kd = 2 zeta w_n J,
# well below the first free-free elastic frequency (0.47 Hz = 2.9 rad/s).
DEFAULT_CONTROL: dict[str, Any] = {
    "law": "pd",
    "kp": [25.7, 0.0833, 25.7],  # ft lbf / rad
    "kd": [180.0, 0.583, 180.0],  # ft lbf s / rad
    "theta_cmd_deg": [0.0, 0.0, 0.0],  # commanded 1-2-3 Euler angles
    "torque": [0.0, 0.0, 10.0],  # bang_bang: torque for t_on <= t < t_switch, minus it for t_switch <= t < t_off
    "t_on": 0.0,
    "t_switch": 5.0,
    "t_off": 10.0,
}


def merged_params(params: Mapping[str, Any]) -> dict[str, Any]:
    """``DEFAULT_CONTROL`` overlaid with ``params``; unknown names raise ValueError."""
    unknown = sorted(set(params) - set(DEFAULT_CONTROL))
    if unknown:
        raise ValueError(f"unknown flexbody_control parameter(s) {unknown}; known: {', '.join(DEFAULT_CONTROL)}")
    return {**DEFAULT_CONTROL, **params}


@dataclass(frozen=True, eq=False)
class ControlParams:
    law: str
    kp: np.ndarray
    kd: np.ndarray
    theta_cmd: np.ndarray  # rad
    torque: np.ndarray
    t_on: float
    t_switch: float
    t_off: float

    @classmethod
    def from_mapping(cls, params: Mapping[str, Any]) -> ControlParams:
        """Defaults ``DEFAULT_CONTROL``; unknown names and bad shapes raise ValueError naming the parameter."""
        p = merged_params(params)
        if p["law"] not in LAWS:
            raise ValueError(f"parameter 'law' must be one of {LAWS}, got {p['law']!r}")

        def vec(key: str) -> np.ndarray:
            a = np.asarray(p[key], dtype=np.float64)
            if a.shape != (3,) or not np.all(np.isfinite(a)):
                raise ValueError(f"parameter {key!r} must be 3 finite numbers, got {p[key]!r}")
            return a

        times = [float(p[k]) for k in ("t_on", "t_switch", "t_off")]
        if not times[0] <= times[1] <= times[2]:
            raise ValueError("parameters must satisfy t_on <= t_switch <= t_off")
        return cls(p["law"], vec("kp"), vec("kd"), np.radians(vec("theta_cmd_deg")), vec("torque"), *times)


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles to (-pi, pi]."""
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


def pd_torque(p: ControlParams, euler123: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """tau0 = -(kp (theta - theta_cmd) + kd omega), per body axis, angle error wrapped to (-pi, pi]."""
    return -(p.kp * wrap_angle(euler123 - p.theta_cmd) + p.kd * omega)


def bang_bang_torque(p: ControlParams, t: float, left: bool = False) -> np.ndarray:
    """+torque on [t_on, t_switch), -torque on [t_switch, t_off), else 0; ``left``: the left limit at a switch."""
    def inside(a: float, b: float) -> bool:
        return (a < t <= b) if left else (a <= t < b)

    if inside(p.t_on, p.t_switch):
        return p.torque.copy()
    if inside(p.t_switch, p.t_off):
        return -p.torque
    return np.zeros(3)


def control_torque(
    p: ControlParams, t: float, euler123: np.ndarray, omega: np.ndarray, left: bool = False
) -> np.ndarray:
    """The torque of the configured law."""
    if p.law == "pd":
        return pd_torque(p, euler123, omega)
    return bang_bang_torque(p, t, left)
