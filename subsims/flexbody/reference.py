"""Monolithic references for the flexbody co-simulations: one system, one RK4, no coupling error.

- ``sample_run_exact``: closed-form solution of the report's force-free sample run (spec §2.3).
- ``simulate_free``: the flexbody alone under open-loop loads (mode F).
- ``closed_loop_reference``: flexbody + ``flexbody_control`` integrated as ONE system, the control torque
  evaluated from the state at every RK stage (the reference for the flexbody <-> controller co-simulation).
- ``heavy_bus_slew_reference``: spec AT-13's heavy-bus vehicle under the bang-bang slew, the monolithic
  reference for mode C (appendage + rigid attitude simulator with inertia split).

Step inputs: integration is split at ``breakpoints`` (bang-bang switch times) and within each piece the
loads are evaluated strictly inside it, so every RK stage sees the piece's own value (spec AT-10).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from subsims.flexbody.config import build
from subsims.flexbody.kinematics import euler123_from_dcm, euler123_to_dcm, quat_to_dcm
from subsims.flexbody.model import Loads, integrate
from subsims.flexbody.outputs import free_outputs
from subsims.flexbody.vehicle import BANG_BANG_SLEW, HEAVY_BUS, SAMPLE_VEHICLE
from subsims.flexbody_control.law import ControlParams, control_torque


def _rotation(axis_angle: np.ndarray) -> np.ndarray:
    """exp(a~): rotation by |a| about a (Rodrigues)."""
    angle = float(np.linalg.norm(axis_angle))
    if angle == 0.0:
        return np.eye(3)
    k = axis_angle / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * kx + (1.0 - np.cos(angle)) * kx @ kx


def sample_run_exact(times: Sequence[float], params: Mapping[str, Any] | None = None) -> dict[str, np.ndarray]:
    """Exact solution of the force-free sample run (spec §2.3): steady spin about the boom axis through c0.

    The initial rate (0, 10, 0) deg/s is along body y, a principal axis of the composite inertia, and every
    particle lies on the line through c0 parallel to it, so there is no centripetal load: q = 0 for any K and
    any t, w is constant, the mass centre moves uniformly:
    C(t) = C0 exp(w~ t); R(t) = R0 + C0 c0 + v_cm t - C(t) c0 with v_cm = C0 (V0 + w x c0); V(t) = C^T v_cm - w x c0.
    Returns R (n, 3), V (n, 3), C (n, 3, 3) and the continuous Euler angles euler123 (n, 3) (rad).
    Valid only for initial conditions of that kind (the report's own).
    """
    p = {**SAMPLE_VEHICLE, **(params or {})}
    m = float(p["m_b"]) + float(np.sum(p["masses"]))
    c0 = (float(p["m_b"]) * np.asarray(p["s"], float) + np.asarray(p["masses"], float) @ np.asarray(p["r"], float)) / m
    theta0 = np.radians(np.asarray(p["euler123_deg"], float))
    w = np.radians(np.asarray(p["omega_deg_s"], float))
    C0 = euler123_to_dcm(theta0)
    R0 = np.asarray(p["R0"], float)
    v_cm = C0 @ (np.asarray(p["V0"], float) + np.cross(w, c0))
    out: dict[str, list] = {"R": [], "V": [], "C": [], "euler123": []}
    ref = theta0
    for t in times:
        C = C0 @ _rotation(w * t)
        ref = euler123_from_dcm(C, ref=ref)
        out["R"].append(R0 + C0 @ c0 + v_cm * t - C @ c0)
        out["V"].append(C.T @ v_cm - np.cross(w, c0))
        out["C"].append(C)
        out["euler123"].append(ref)
    return {k: np.array(v) for k, v in out.items()}


def _piecewise_integrate(model, Y0, times, loads, h, breakpoints):  # noqa: ANN001, ANN202 - internal
    """Integrate over ``times``, restarting at each breakpoint (which must be sample times)."""
    times = np.asarray(times, dtype=np.float64)
    cuts = sorted({float(b) for b in breakpoints if times[0] < b < times[-1]})
    for b in cuts:
        if not np.any(times == b):
            raise ValueError(f"breakpoint t = {b} must be one of the sample times")
    edges = [float(times[0]), *cuts, float(times[-1])]
    ys = [Y0[None, :]]
    y = Y0
    for a, b in zip(edges[:-1], edges[1:]):
        seg = times[(times >= a) & (times <= b)]
        inside_lo, inside_hi = np.nextafter(a, b), np.nextafter(b, a)

        def piece_loads(t: float, yy: np.ndarray, lo: float = inside_lo, hi: float = inside_hi) -> Loads:
            return loads(min(max(t, lo), hi), yy)

        seg_ys = integrate(model, y, seg, piece_loads, h)
        ys.append(seg_ys[1:])
        y = seg_ys[-1]
    return np.concatenate(ys)


def simulate_free(
    params: Mapping[str, Any],
    times: Sequence[float],
    loads: Callable[[float, np.ndarray], Loads] | None = None,
    h: float | None = None,
    breakpoints: Sequence[float] = (),
) -> dict[str, np.ndarray]:
    """Mode F alone: outputs of the adapter (same names) at ``times`` under ``loads(t, Y)`` (default none)."""
    setup = build({**params, "mode": "free"})
    model = setup.model
    zero = (np.zeros(3), np.zeros(3), np.zeros((model.n, 3)))
    loads = loads or (lambda t, y: zero)
    times = np.asarray(times, dtype=np.float64)
    ys = _piecewise_integrate(model, setup.Y0, times, loads, h or setup.h, breakpoints)
    out = free_outputs(model, times, ys, [loads(float(tt), y) for tt, y in zip(times, ys)])
    out["t"] = times
    return out


def closed_loop_reference(
    flex_params: Mapping[str, Any],
    control_params: Mapping[str, Any],
    times: Sequence[float],
    h: float | None = None,
) -> dict[str, np.ndarray]:
    """Flexbody + attitude controller integrated as one system (the monolithic closed-loop reference).

    tau0 = control law of (t, Euler angles of the stage state, omega of the stage state) at every RK stage;
    the outputs are the flexbody's (mode "free") plus ``tau0``.
    """
    cp = ControlParams.from_mapping(control_params)
    setup = build({**flex_params, "mode": "free"})
    model, t = setup.model, setup.model.t
    fp0 = np.zeros((model.n, 3))

    def loads(tt: float, y: np.ndarray) -> Loads:
        quat = y[12 + 2 * t:]
        theta = euler123_from_dcm(quat_to_dcm(quat / np.linalg.norm(quat)), ref=y[3:6])
        return np.zeros(3), control_torque(cp, tt, theta, y[9 + t:12 + t]), fp0

    breaks = (cp.t_on, cp.t_switch, cp.t_off) if cp.law == "bang_bang" else ()
    out = simulate_free(flex_params, times, loads, h, breaks)
    samples = zip(out["t"], out["euler123"], out["omega"])
    out["tau0"] = np.array([control_torque(cp, tt, th, w) for tt, th, w in samples])
    return out


def heavy_bus_slew_reference(times: Sequence[float], n_modes: int = 2, h: float = 0.005) -> dict[str, np.ndarray]:
    """Spec AT-13 monolithic reference: heavy bus (m_b = 100 slug, I_b = 2000 E3) + bang-bang slew, from rest.

    Spec values (NT = 2): t = 5, 10, 20 s -> theta_3 = 2.7211734, 5.4221176, 5.4303216 deg; omega_3 = 1.1078985,
    -0.0513986, 0.0487018 deg/s; q_2x = 0.0152806, -0.0034971, 0.0103159 ft. ``times`` must contain 5 and 10.
    """
    return closed_loop_reference({**HEAVY_BUS, "n_modes": n_modes}, BANG_BANG_SLEW, times, h)
