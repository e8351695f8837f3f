"""Output samples of the flexbody from its state samples (shared by the adapter and the monolithic references)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from subsims.flexbody.appendage import appendage_loads
from subsims.flexbody.kinematics import euler_zyx_from_dcm, quat_to_dcm
from subsims.flexbody.model import (
    FlexModel,
    Loads,
    accelerations,
    deflections,
    elastic_energy,
    kinetic_energy,
    momenta,
    split_state,
)

FREE_OUTPUTS = ("R", "euler123", "euler_zyx", "quat", "V", "omega", "Vdot", "omega_dot", "eta", "eta_dot", "q", "q_dot",
                "cm", "kinetic_energy", "elastic_energy", "p_I", "H_O")


def free_outputs(model: FlexModel, times: np.ndarray, ys: np.ndarray, loads: Sequence[Loads]) -> dict[str, np.ndarray]:
    """Mode "free" outputs at each sample (row of ``ys``); Vdot, omega_dot use the sample's ``loads``."""
    out: dict[str, list] = {name: [] for name in FREE_OUTPUTS}
    for y, load in zip(ys, loads, strict=True):
        R, theta, eta, V, w, eta_dot, quat = split_state(y, model.t)
        P, H = momenta(model, y)
        q = deflections(model, eta)
        x = accelerations(model, V, w, eta, eta_dot, load)
        sample = {
            "R": R, "euler123": theta, "euler_zyx": euler_zyx_from_dcm(quat_to_dcm(quat)), "quat": quat,
            "V": V, "omega": w, "Vdot": x[:3], "omega_dot": x[3:6], "eta": eta, "eta_dot": eta_dot,
            "q": q.ravel(), "q_dot": deflections(model, eta_dot).ravel(),
            "cm": (model.mc0 + model.masses @ q) / model.m,
            "kinetic_energy": [kinetic_energy(model, V, w, eta, eta_dot)],
            "elastic_energy": [elastic_energy(model, eta)],
            "p_I": P, "H_O": H,
        }
        for name in out:
            out[name].append(sample[name])
    return {name: np.array(v, dtype=np.float64).reshape(len(times), -1) for name, v in out.items()}


def appendage_outputs(
    model: FlexModel,
    times: np.ndarray,
    ys: np.ndarray,
    solve: Callable[[Any, np.ndarray], tuple[np.ndarray, np.ndarray]],
    inputs: Sequence[Mapping[str, np.ndarray]],
    D: np.ndarray,
) -> dict[str, np.ndarray]:
    """Modes "attitude"/"base" outputs; ``inputs`` per sample, ``solve(inputs, y) -> (a_O, eta_ddot)``."""
    t = model.t
    out: dict[str, list] = {}
    for y, d in zip(ys, inputs, strict=True):
        a_O, eta_dd = solve(d, y)
        eta, eta_dot = y[:t], y[t:]
        sample = appendage_loads(model, eta, eta_dot, eta_dd, a_O, d["omega"], d["omega_dot"], d["fp"], D)
        sample.update(a_O=a_O, eta=eta, eta_dot=eta_dot, q=deflections(model, eta).ravel(),
                      q_dot=deflections(model, eta_dot).ravel(), elastic_energy=[elastic_energy(model, eta)])
        for name, v in sample.items():
            out.setdefault(name, []).append(v)
    return {name: np.array(v, dtype=np.float64).reshape(len(times), -1) for name, v in out.items()}
