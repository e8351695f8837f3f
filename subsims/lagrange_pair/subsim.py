"""Thin subsim adapter of the SRB + parachute pair (physics in :mod:`subsims.lagrange_pair.model`).

State: the model's state vector; with the default ``formulation="stabilized"`` this is the
listing's minimal 30-vector (both attitude matrices, V_B, W_B, W_C, R_B), so a committed or
restored state can never violate the joint. Inputs are extra loads on each body (body axes,
about the CM), read inside every Runge-Kutta stage by calling ``u(t)``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from cosim.subsim import InputFunction, ModelError, Param, Port, Subsim
from subsims.lagrange_pair import model
from subsims.numerics import as_table

INPUT_PORTS: dict[str, Port] = {
    "force_B": Port(3, "lbf", "extra force on the SRB at its CM, B axes"),
    "moment_B": Port(3, "lbf*ft", "extra moment on the SRB about its CM, B axes"),
    "force_C": Port(3, "lbf", "extra force on the parachute at its CM, C axes"),
    "moment_C": Port(3, "lbf*ft", "extra moment on the parachute about its CM, C axes"),
}

OUTPUT_PORTS: dict[str, Port] = {
    "pos_B": Port(3, "ft", "SRB CM position, I frame (north, east, down)"),
    "pos_C": Port(3, "ft", "parachute CM position, I frame"),
    "vel_B": Port(3, "ft/s", "SRB CM velocity, B axes"),
    "vel_C": Port(3, "ft/s", "parachute CM velocity, C axes"),
    "vel_B_I": Port(3, "ft/s", "SRB CM velocity, I frame"),
    "vel_C_I": Port(3, "ft/s", "parachute CM velocity, I frame"),
    "euler_B": Port(3, "rad", "SRB 3-2-1 Euler angles (psi, theta, phi) relative to I"),
    "euler_C": Port(3, "rad", "parachute 3-2-1 Euler angles (psi, theta, phi) relative to I"),
    "dcm_B": Port(9, "", "I->B direction cosine matrix ABI, row-major"),
    "dcm_C": Port(9, "", "I->C direction cosine matrix ACI, row-major"),
    "omega_B": Port(3, "rad/s", "SRB angular velocity, B axes"),
    "omega_C": Port(3, "rad/s", "parachute angular velocity, C axes"),
    "multiplier": Port(3, "lbf", "Lagrange multiplier = swivel force on the SRB, C axes (force on C is its negative)"),
    "violation_pos": Port(3, "ft", "swivel separation: B's attach point minus C's, I frame"),
    "violation_vel": Port(3, "ft/s", "velocity constraint residual A*Omega (eq. 12), C axes"),
}

assert tuple(OUTPUT_PORTS) == model.OUTPUT_NAMES

_UNIT_AND_DOC: dict[str, tuple[str, str]] = {  # the keys of model.DEFAULT_PARAMS (the CHOSEN configuration)
    "formulation": ("", '"stabilized" (the minimal 30-state form), "velocity_only" (33) or "unstabilized" (36)'),
    "aero": ("", "built-in aerodynamics of the listing (false when a separate aero subsim supplies the loads)"),
    "gravity": ("", "flat-Earth gravity (aero and gravity both false: the listing's IFE = 0)"),
    "integrator": ("", '"rk4" (fixed-step classical Runge-Kutta, RUNGF) or "euler" (for comparisons only)'),
    "dt": ("s", "largest integration sub-step (DELT), > 0"),
    "g": ("ft/s^2", "gravity; also converts the weights to masses (MASS = WGHT/g), > 0"),
    "weight_B": ("lbf", "SRB weight, > 0"),
    "inertia_B": ("slug*ft^2", "SRB inertia about its CM, B axes: Ixx, Iyy, Izz, Ixy, Ixz, Iyz (positive definite)"),
    "weight_C": ("lbf", "parachute weight, > 0"),
    "inertia_C": ("slug*ft^2", "parachute inertia about its CM, C axes: Ixx, Iyy, Izz, Ixy, Ixz, Iyz"),
    "attach_B": ("ft", "SRB CM -> swivel, B axes (XATTB, YATTB, ZATTB)"),
    "attach_C": ("ft", "parachute (canopy) CM -> swivel, C axes (XATTC, YATTC, ZATTC)"),
    "speed_B": ("ft/s", "initial SRB speed (VIBS)"),
    "azimuth_B_deg": ("deg", "initial SRB flight-path azimuth, from north toward east (AZIIBS)"),
    "flight_path_B_deg": ("deg", "initial SRB flight-path angle, positive up (GAMIBS)"),
    "altitude_B": ("ft", "initial SRB altitude (ALTBS): R_B(0) = [0, 0, -altitude_B]"),
    "rates_B_deg": ("deg/s", "initial SRB body rates p, q, r (PDEGBS, QDEGBS, RDEGBS)"),
    "alpha_B_deg": ("deg", "initial SRB total angle of attack (ALPHBS)"),
    "phia_B_deg": ("deg", "initial SRB aerodynamic roll angle (PHIABS)"),
    "bank_B_deg": ("deg", "initial SRB bank angle (BANKBS)"),
    "rates_C_deg": ("deg/s", "initial parachute body rates p, q, r"),
    "euler_C_deg": ("deg", "initial parachute 3-2-1 Euler angles psi, theta, phi (PSICS, ...)"),
    "x0": ("", "the initial state vector itself (30, 33 or 36 numbers by formulation), instead of the initial "
           "conditions above; not set: from them"),
}
assert tuple(_UNIT_AND_DOC) == tuple(model.DEFAULT_PARAMS)


def _plain(value: Any) -> Any:
    """A default as a scenario would give it: tuples as lists."""
    return list(value) if isinstance(value, tuple) else value


PARAMS: dict[str, Param] = {k: Param(_plain(model.DEFAULT_PARAMS[k]), *ud) for k, ud in _UNIT_AND_DOC.items()}


class LagrangePair(Subsim):
    """Two rigid bodies (SRB and drogue) on a frictionless swivel, Watts' drift-free Lagrange-multiplier form.

    Parameters (all optional; defaults are the CHOSEN configuration in ``model.DEFAULT_PARAMS``):
    ``formulation`` ("stabilized" | "velocity_only" | "unstabilized"), ``aero``, ``gravity``,
    ``integrator`` ("rk4" | "euler"), ``dt`` (max sub-step, s), ``g``, ``weight_B``/``weight_C`` (lbf),
    ``inertia_B``/``inertia_C`` (Ixx, Iyy, Izz, Ixy, Ixz, Iyz), ``attach_B``/``attach_C`` (ft, body axes),
    the SRB's ``speed_B``, ``azimuth_B_deg``, ``flight_path_B_deg``, ``altitude_B``, ``rates_B_deg``,
    ``alpha_B_deg``, ``phia_B_deg``, ``bank_B_deg``, the parachute's ``rates_C_deg``, ``euler_C_deg``,
    and ``x0`` (an explicit initial state vector).
    """

    name = "lagrange_pair"
    inputs = INPUT_PORTS
    outputs = OUTPUT_PORTS
    params = PARAMS

    def initial_state(self, params: Mapping[str, Any]) -> np.ndarray:
        self.model, self.dt, self.integrator, x0 = model.setup(params)
        return x0

    def advance(
        self, state: np.ndarray, times: np.ndarray, u: InputFunction
    ) -> tuple[Mapping[str, np.ndarray], np.ndarray]:
        x0 = np.array(state, dtype=np.float64)  # private copy: the caller's state is never touched
        if x0.shape != (self.model.state_size,):
            raise ValueError(f"state must have shape ({self.model.state_size},), got {x0.shape}")

        def loads(ts: np.ndarray) -> np.ndarray:
            """The extra loads (k, 12) at all the RK times ``ts``, from one call of ``u``."""
            values = u(ts)
            fx = np.hstack([as_table(values[k], ts.size, 3, k) for k in INPUT_PORTS])
            if not np.all(np.isfinite(fx)):
                i = int(np.argmin(np.isfinite(fx).all(axis=1)))
                raise FloatingPointError(f"extra loads at t={float(ts[i])!r} are not finite: {fx[i].tolist()}")
            return fx

        try:
            samples, x1 = model.integrate(self.model, x0, np.asarray(times, dtype=np.float64), None, self.dt,
                                          self.integrator, inputs=loads)
        except FloatingPointError as exc:
            raise ModelError(f"lagrange_pair: {exc}") from exc
        return model.stack_outputs(self.model, samples), x1
