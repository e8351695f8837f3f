"""Read and validate flexbody parameters (defaults: ``vehicle.SAMPLE_VEHICLE``) into a model and initial state."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import eigh

from subsims.flexbody import modal
from subsims.flexbody.kinematics import dcm_to_quat, euler123_to_dcm
from subsims.flexbody.model import FlexModel, coefficient_matrix, join_state, make_modal_model
from subsims.flexbody.vehicle import SAMPLE_VEHICLE

MODES = ("free", "attitude", "base")
UNIT_SYSTEMS = {
    "slug-ft-lbf-s": {"length": "ft", "mass": "slug", "force": "lbf"},
    "kg-m-N-s": {"length": "m", "mass": "kg", "force": "N"},
}
OPTIONAL_KEYS = {"K", "omega2", "Phi", "q0", "q_dot0", "eta0", "eta_dot0"}


@dataclass(frozen=True, eq=False)
class FlexSetup:
    """Everything ``initial_state`` derives from the parameters."""

    mode: str
    units: dict[str, str]
    model: FlexModel
    omega2_all: np.ndarray  # all 3n constrained w^2 (or the supplied t)
    Y0: np.ndarray  # mode "free": the (8-4) + quaternion state
    eta0: np.ndarray
    eta_dot0: np.ndarray
    h: float


def _vec(p: Mapping[str, Any], key: str, shape: tuple[int, ...]) -> np.ndarray:
    a = np.asarray(p[key], dtype=np.float64)
    if a.size == 1 and shape != (1,) and np.ndim(p[key]) == 0 and a.item() == 0.0:
        a = np.zeros(shape)  # allow a scalar 0 for "all zero"
    try:
        a = a.reshape(shape)
    except ValueError:
        raise ValueError(f"parameter {key!r} must have shape {shape}, got {np.shape(p[key])}") from None
    if not np.all(np.isfinite(a)):
        raise ValueError(f"parameter {key!r} must be finite")
    return a


def merged_params(params: Mapping[str, Any]) -> dict[str, Any]:
    """Defaults overlaid with ``params``; unknown keys are an error (they are usually typos)."""
    unknown = set(params) - set(SAMPLE_VEHICLE) - OPTIONAL_KEYS
    if unknown:
        raise ValueError(f"unknown flexbody parameter(s): {sorted(unknown)}")
    return {**SAMPLE_VEHICLE, **params}


def modes_from_params(p: Mapping[str, Any], masses: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(omega2_all, omega2_t, Phi_t): from K, or supplied modes, or the boom builder (spec §2.4)."""
    n = masses.size
    t = int(p["n_modes"])
    if "K" in p:
        K = modal.check_stiffness(p["K"], n)
    elif "omega2" in p or "Phi" in p:
        omega2 = np.asarray(p["omega2"], dtype=np.float64).ravel()
        Phi = np.asarray(p["Phi"], dtype=np.float64).reshape(3 * n, omega2.size)
        modal.check_modes(Phi, omega2, masses)
        if not 0 <= t <= omega2.size:
            raise ValueError(f"n_modes must be between 0 and {omega2.size} (supplied modes), got {t}")
        return omega2, omega2[:t].copy(), Phi[:, :t].copy()
    else:
        K = modal.boom_stiffness(n, p["booms"], float(p["boom_L"]), float(p["EI_x"]), float(p["EI_z"]), float(p["EA"]))
    if not 0 <= t <= 3 * n:
        raise ValueError(f"n_modes must be between 0 and 3n = {3 * n}, got {t}")
    omega2_all, Phi_all = modal.constrained_modes(K, masses)
    omega2, Phi = modal.truncate(omega2_all, Phi_all, t)
    return omega2_all, omega2, Phi


def build(params: Mapping[str, Any]) -> FlexSetup:
    """Validate the parameters and compute the modes, the constant matrices and the initial state."""
    p = merged_params(params)
    mode = str(p["mode"])
    if mode not in MODES:
        raise ValueError(f"parameter 'mode' must be one of {MODES}, got {mode!r}")
    if p["units"] not in UNIT_SYSTEMS:
        raise ValueError(f"parameter 'units' must be one of {list(UNIT_SYSTEMS)}, got {p['units']!r}")
    masses = np.asarray(p["masses"], dtype=np.float64).ravel()
    n = masses.size
    if n < 1 or np.any(~np.isfinite(masses)) or np.any(masses <= 0):
        raise ValueError("parameter 'masses' must be a non-empty list of positive particle masses")
    m_b = float(p["m_b"])
    if not m_b > 0:
        raise ValueError("parameter 'm_b' must be positive")
    I_b = _vec(p, "I_b", (3, 3))
    if np.max(np.abs(I_b - I_b.T)) > 1e-12 * np.max(np.abs(I_b)) or np.any(np.linalg.eigvalsh(I_b) <= 0):
        raise ValueError("parameter 'I_b' must be symmetric positive definite (report chapter 6: else A is singular)")
    s = _vec(p, "s", (3,))
    r = _vec(p, "r", (n, 3))
    for key in ("mass_order", "kin_order"):
        if p[key] not in (1, 2, 3):
            raise ValueError(f"parameter {key!r} must be 1, 2 or 3, got {p[key]!r}")
    h = float(p["h"])
    if not h > 0:
        raise ValueError("parameter 'h' (RK4 step) must be positive")
    omega2_all, omega2, Phi = modes_from_params(p, masses)
    t = omega2.size
    zeta = np.broadcast_to(np.asarray(p["modal_damping"], dtype=np.float64), (t,)).copy()
    if not np.all(zeta >= 0):  # (not all >= 0: NaN too)
        raise ValueError("parameter 'modal_damping' must be >= 0")
    model = make_modal_model(m_b, I_b, s, masses, r, omega2, Phi, zeta, int(p["mass_order"]), int(p["kin_order"]))

    m_dof = np.repeat(masses, 3)
    if "eta0" in p:
        eta0 = _vec(p, "eta0", (t,))
    else:
        eta0 = Phi.T @ (m_dof * _vec(p, "q0", (n, 3)).ravel()) if "q0" in p else np.zeros(t)
    if "eta_dot0" in p:
        eta_dot0 = _vec(p, "eta_dot0", (t,))
    else:
        eta_dot0 = Phi.T @ (m_dof * _vec(p, "q_dot0", (n, 3)).ravel()) if "q_dot0" in p else np.zeros(t)
    theta0 = np.radians(_vec(p, "euler123_deg", (3,)))
    Y0 = join_state(
        _vec(p, "R0", (3,)), theta0, eta0, _vec(p, "V0", (3,)), np.radians(_vec(p, "omega_deg_s", (3,))), eta_dot0,
        dcm_to_quat(euler123_to_dcm(theta0)),
    )
    return FlexSetup(mode, UNIT_SYSTEMS[p["units"]], model, omega2_all, Y0, eta0, eta_dot0, h)


RK4_ACCURATE = 0.3  # omega_max h at most this for accuracy (spec §4.1 R5; <= 2.8 for stability alone)


def fastest_frequency(setup: FlexSetup) -> float:
    """omega_max of spec §4.1 R5, rad/s: in mode "free" the highest free-free frequency of the retained model (the
    modes' stiffness against the undeformed vehicle's whole mass matrix, rigid motion condensed out), in modes
    "attitude" and "base" the highest retained constrained frequency; 0 without modes."""
    model = setup.model
    if model.t == 0:
        return 0.0
    if setup.mode != "free":
        return float(np.sqrt(np.max(model.K_eta.diagonal())))
    A = coefficient_matrix(model, np.zeros((model.n, 3)), mass_order=1)
    rigid, flexible = slice(0, 6), slice(6, None)
    condensed = A[flexible, flexible] - A[flexible, rigid] @ np.linalg.solve(A[rigid, rigid], A[rigid, flexible])
    return float(np.sqrt(np.max(eigh(model.K_eta, condensed, eigvals_only=True))))
