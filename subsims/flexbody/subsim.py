"""Subsim adapter of the flexible spacecraft (physics in model.py, appendage.py; parameters in vehicle.py).

Ports depend on ``mode`` and on n (particles) and t (retained modes), so ``initial_state`` sets them.
All vectors are body axes unless marked inertial; unit labels follow ``units`` (default slug-ft-lbf-s).

mode "free" (the report's vehicle, spec mode F). State: the report's Y (8-4) + attitude quaternion.
  inputs   f0 (3) force at O_g; tau0 (3) torque about O_g; fp (3n) force on each particle (particle-major).
  outputs  R (3, inertial), euler123 (3, rad, the report's 1-2-3 angles, continuous), euler_zyx (3, rad, Nixon's
           z-y-x angles of the same attitude), quat (4, body->inertial, scalar first), V (3), omega (3), Vdot (3),
           omega_dot (3), eta, eta_dot (t; absent when t = 0), q, q_dot (3n), cm (3), kinetic_energy (1),
           elastic_energy (1), p_I (3, inertial linear momentum), H_O (3, inertial angular momentum about O).
mode "attitude" (appendage under a rigid attitude simulator, spec mode C). State: (eta, eta_dot).
  inputs   omega (3), omega_dot (3): the base's angular motion from the attitude simulator; F_bus (3) external
           force on the base (moves a_O only, default 0); fp (3n).
  outputs  tau_flex (3) about c0, tau_flex_split (3) = tau_flex - D wdot - w x D w (for an attitude simulator using
           J - D), F_int, T_int (3, loads of the appendage on the base, torque about O_g), a_O (3), cm_shift (3),
           eta, eta_dot, q, q_dot, elastic_energy.
mode "base" (prescribed base motion, spec mode B). State: (eta, eta_dot).
  inputs   a_O (3, inertial acceleration of O_g in body axes), omega (3), omega_dot (3), fp (3n).
  outputs  F_int, T_int, F_rig, T_rig, F_flex, T_flex (3), eta, eta_dot, q, q_dot, elastic_energy.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from cosim.subsim import InputFunction, ModelError, Param, Port, Subsim
from subsims.adapters import Unset, unset_by_default
from subsims.flexbody.appendage import appendage_accelerations, inertia_split
from subsims.flexbody.config import RK4_ACCURATE, FlexSetup, build, fastest_frequency
from subsims.flexbody.model import Loads, integrate, integrate_samples
from subsims.flexbody.outputs import appendage_outputs, free_outputs
from subsims.flexbody.vehicle import SAMPLE_VEHICLE
from subsims.numerics import as_table

_V = SAMPLE_VEHICLE

# Every name config.build reads: the keys of SAMPLE_VEHICLE (with its values as defaults) but the report's &RUN
# values t_end, print_dt, plot_dt, which the model does not read, and config.OPTIONAL_KEYS (default None: not set).
# Units are those of the default units = "slug-ft-lbf-s" (the model itself is unit-agnostic).
PARAMS: dict[str, Param] = {
    "mode": Param(_V["mode"], "", '"free" (the whole vehicle, spec mode F), "attitude" (the appendage driven by the '
                  'base\'s angular motion, mode C) or "base" (prescribed base motion, mode B)'),
    "units": Param(_V["units"], "", 'unit system of the port labels only: "slug-ft-lbf-s" or "kg-m-N-s"'),
    "m_b": Param(_V["m_b"], "slug", "base mass, > 0"),
    "I_b": Param(_V["I_b"], "slug*ft^2", "base inertia about the base mass centre, body axes, 3x3 symmetric "
                 "positive definite"),
    "s": Param(_V["s"], "ft", "base mass centre from O_g, body axes"),
    "masses": Param(_V["masses"], "slug", "the n particle masses, > 0"),
    "r": Param(_V["r"], "ft", "undeformed particle positions from O_g, body axes, n x 3"),
    "n_modes": Param(_V["n_modes"], "", "t, the retained constrained modes, 0 <= t <= 3n (0: rigid vehicle, "
                     "mode free only)"),
    "booms": Param(_V["booms"], "", "boom builder (when K, omega2/Phi are not set): each boom's particle numbers "
                   "1..n, root to tip"),
    "boom_L": Param(_V["boom_L"], "ft", "boom builder: the k-th particle of a boom sits k boom_L from its clamp"),
    "EI_x": Param(_V["EI_x"], "lbf*ft^2", "boom builder: bending stiffness, deflection along x"),
    "EI_z": Param(_V["EI_z"], "lbf*ft^2", "boom builder: bending stiffness, deflection along z"),
    "EA": Param(_V["EA"], "lbf", "boom builder: axial stiffness, along y"),
    "mass_order": Param(_V["mass_order"], "", "the report's categories (chapter 4) kept in A: 1, 2 or 3"),
    "kin_order": Param(_V["kin_order"], "", "the report's categories (chapter 4) kept in U: 1, 2 or 3"),
    "modal_damping": Param(_V["modal_damping"], "", "modal damping ratio zeta_k, one for all or t values, >= 0"),
    "R0": Param(_V["R0"], "ft", "initial position of O_g, inertial"),
    "euler123_deg": Param(_V["euler123_deg"], "deg", "initial 1-2-3 Euler angles (the report's THETA)"),
    "V0": Param(_V["V0"], "ft/s", "initial velocity of O_g, body axes (the report's UVW)"),
    "omega_deg_s": Param(_V["omega_deg_s"], "deg/s", "initial body angular velocity (the report's OMEGA)"),
    "h": Param(_V["h"], "s", "fixed RK4 step, > 0"),
    "K": Param(None, "lbf/ft", "stiffness matrix, 3n x 3n (first match wins: K, then omega2 with Phi, then the "
               "boom builder); not set: the next"),
    "omega2": Param(None, "rad^2/s^2", "supplied constrained modes: squared frequencies (with Phi)"),
    "Phi": Param(None, "slug^-0.5", "supplied constrained modes: mass-normalized shapes, 3n x len(omega2) (with "
                 "omega2)"),
    "q0": Param(None, "ft", "initial particle deflections, n x 3, projected as eta = Phi^T M q; not set: zero"),
    "q_dot0": Param(None, "ft/s", "initial particle deflection rates, n x 3, projected; not set: zero"),
    "eta0": Param(None, "slug^0.5*ft", "initial modal coordinates (t), instead of q0; not set: from q0"),
    "eta_dot0": Param(None, "slug^0.5*ft/s", "initial modal rates (t), instead of q_dot0; not set: from q_dot0"),
}


def _ports(setup: FlexSetup) -> tuple[dict[str, Port], dict[str, Port]]:
    u = setup.units
    L, F = u["length"], u["force"]
    TQ, E = f"{F}*{L}", f"{F}*{L}"
    n3, t = 3 * setup.model.n, setup.model.t
    sq = f"{u['mass']}^0.5*{L}"  # eta: q = Phi eta with Phi^T M Phi = E
    modal = {}
    if t:  # no modal ports for the rigid vehicle (t = 0)
        modal = {
            "eta": Port(t, sq, "modal coordinates (basis-dependent)"),
            "eta_dot": Port(t, f"{sq}/s", "modal rates"),
        }
    defl = {
        "q": Port(n3, L, "particle deflections q_i, body axes, particle-major"),
        "q_dot": Port(n3, f"{L}/s", "particle deflection rates"),
        "elastic_energy": Port(1, E, "1/2 eta^T Omega^2 eta"),
    }
    fp = {"fp": Port(n3, F, "external force on each particle, body axes, particle-major")}
    w_in = {
        "omega": Port(3, "rad/s", "base angular velocity, body axes"),
        "omega_dot": Port(3, "rad/s^2", "base angular acceleration, body axes"),
    }
    if setup.mode == "free":
        inputs = {
            "f0": Port(3, F, "force on the base at O_g, body axes"),
            "tau0": Port(3, TQ, "torque on the base about O_g, body axes"),
            **fp,
        }
        outputs = {
            "R": Port(3, L, "position of O_g, inertial"),
            "euler123": Port(3, "rad", "report 1-2-3 Euler angles (7-1), continuous branch"),
            "euler_zyx": Port(3, "rad", "Nixon z-y-x angles (phi_x, phi_y, phi_z) of the same attitude"),
            "quat": Port(4, "", "attitude quaternion body->inertial (w, x, y, z)"),
            "V": Port(3, f"{L}/s", "inertial velocity of O_g, body axes"),
            "omega": Port(3, "rad/s", "body angular velocity, body axes"),
            "Vdot": Port(3, f"{L}/s^2", "body-frame rate of V (inertial acceleration of O_g is Vdot + omega x V)"),
            "omega_dot": Port(3, "rad/s^2", "body angular acceleration"),
            **modal,
            **defl,
            "cm": Port(3, L, "system mass centre from O_g, body axes, mc/m (3-4)"),
            "kinetic_energy": Port(1, E, "T = 1/2 U^T A U"),
            "p_I": Port(3, f"{u['mass']}*{L}/s", "linear momentum, inertial"),
            "H_O": Port(3, f"{u['mass']}*{L}^2/s", "angular momentum about the inertial origin, inertial"),
        }
    elif setup.mode == "attitude":
        inputs = {**w_in, "F_bus": Port(3, F, "external force on the base, body axes"), **fp}
        outputs = {
            "tau_flex": Port(3, TQ, "flexible torque about the composite mass centre c0"),
            "tau_flex_split": Port(3, TQ, "tau_flex - D omega_dot - omega x D omega (attitude inertia J - D)"),
            "F_int": Port(3, F, "force of the appendage on the base"),
            "T_int": Port(3, TQ, "torque of the appendage on the base about O_g"),
            "a_O": Port(3, f"{L}/s^2", "inertial acceleration of O_g, body axes"),
            "cm_shift": Port(3, L, "mass-centre offset from c0, mc_1 / m"),
            **modal,
            **defl,
        }
    else:
        inputs = {"a_O": Port(3, f"{L}/s^2", "inertial acceleration of O_g, body axes"), **w_in, **fp}
        outputs = {
            name: Port(3, F if name.startswith("F") else TQ, doc)
            for name, doc in (
                ("F_int", "force of the appendage on the base"),
                ("T_int", "torque of the appendage on the base about O_g"),
                ("F_rig", "F_int of the rigid undeformed appendage"),
                ("T_rig", "T_int of the rigid undeformed appendage"),
                ("F_flex", "F_int - F_rig"),
                ("T_flex", "T_int - T_rig"),
            )
        }
        outputs.update(modal)
        outputs.update(defl)
    return inputs, outputs


MAX_STEPS = 100_000  # RK4 steps one run_interval may take (about a minute and 50 MB)

def _down(x: float, digits: int = 3) -> float:
    """``x`` rounded down to ``digits`` significant digits (a bound that, shown, still holds)."""
    scale = 10.0 ** (math.floor(math.log10(x)) - digits + 1)
    return math.floor(x / scale) * scale


class FlexBody(Subsim):
    """Flexible spacecraft of Storch & Gates (CSDL-R-1582): rigid base + particle appendage, t modes.

    Parameters: see ``subsims.flexbody.vehicle`` (defaults: the report's appendix-B vehicle, spec §2.4 K).
    """

    name = "flexbody"
    inputs, outputs = _ports(build({}))
    params = PARAMS

    def initial_state(self, params: Mapping[str, Any]) -> np.ndarray:
        setup = build(Unset(params, unset_by_default(self.params)))
        if setup.mode != "free" and setup.model.t == 0:
            raise ValueError(f"parameter 'n_modes' must be >= 1 in mode {setup.mode!r}")
        omega_max = fastest_frequency(setup)
        if omega_max * setup.h > RK4_ACCURATE:  # RK4 is then off by far more than the modes matter (spec §4.1 R5)
            kind = "free-free" if setup.mode == "free" else "constrained"
            raise ValueError(f"parameter 'h' = {setup.h:g} s is too long for the fastest retained mode ({kind}, "
                             f"{omega_max:.4g} rad/s): omega_max h = {omega_max * setup.h:.4g} > {RK4_ACCURATE} (RK4's "
                             f"accuracy bound, spec R5); take h <= {_down(RK4_ACCURATE / omega_max):g} s or fewer "
                             "n_modes")
        self.setup = setup
        self.model = setup.model
        self.split = inertia_split(setup.model)
        self.inputs, self.outputs = _ports(setup)
        if setup.mode == "free":
            return setup.Y0.copy()
        return np.concatenate([setup.eta0, setup.eta_dot0])

    # -- input access -------------------------------------------------------------------------------

    def _inputs(self, u: InputFunction, ts: np.ndarray) -> list[dict[str, np.ndarray]]:
        """The inputs at all the times ``ts`` from ONE call of ``u``, per time a dict (missing inputs: zero)."""
        values = u(ts)
        tables = {name: as_table(values.get(name, np.zeros(port.size)), ts.size, port.size, name)
                  for name, port in self.inputs.items()}
        tables["fp"] = tables["fp"].reshape(ts.size, self.model.n, 3)
        names = tuple(tables)
        return [dict(zip(names, row)) for row in zip(*tables.values())]

    # -- advance --------------------------------------------------------------------------------------

    def advance(
        self, state: np.ndarray, times: np.ndarray, u: InputFunction
    ) -> tuple[Mapping[str, np.ndarray], np.ndarray]:
        times = np.asarray(times, dtype=np.float64)
        steps = (times[-1] - times[0]) / self.setup.h
        if steps > MAX_STEPS:  # one short request must not keep the process busy for minutes or ask for gigabytes
            raise ModelError(f"flexbody: the interval [{times[0]!r}, {times[-1]!r}] needs {steps:.0f} RK4 steps of "
                             f"h = {self.setup.h:g} s; at most {MAX_STEPS} in one request: use shorter intervals")
        y0 = np.array(state, dtype=np.float64)
        advance = self._advance_free if self.setup.mode == "free" else self._advance_appendage
        try:
            with np.errstate(over="ignore", invalid="ignore"):  # a blow-up is reported as a ModelError
                return advance(y0, times, u)
        except np.linalg.LinAlgError as exc:
            raise ModelError(f"flexbody: {exc}") from exc

    def _advance_free(self, y0: np.ndarray, times: np.ndarray, u: InputFunction) -> tuple[dict, np.ndarray]:
        model = self.model

        def loads(ts: np.ndarray) -> list[Loads]:
            return [(d["f0"], d["tau0"], d["fp"]) for d in self._inputs(u, ts)]

        ys = integrate(model, y0, times, None, self.setup.h, inputs=loads)
        if not np.all(np.isfinite(ys)):
            raise ModelError("flexbody: state became non-finite")
        out = free_outputs(model, times, ys, loads(times))
        return {name: out[name] for name in self.outputs}, ys[-1].copy()

    def _advance_appendage(self, y0: np.ndarray, times: np.ndarray, u: InputFunction) -> tuple[dict, np.ndarray]:
        model, t = self.model, self.model.t
        mode_c = self.setup.mode == "attitude"

        def solve(d: Mapping[str, np.ndarray], y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return appendage_accelerations(
                model, y[:t], y[t:], d["omega"], d["omega_dot"], d["fp"],
                F_bus=d["F_bus"] if mode_c else None, a_O=None if mode_c else d["a_O"],
            )

        ys = integrate_samples(lambda tt, y, d: np.concatenate([y[t:], solve(d, y)[1]]), y0, times, self.setup.h,
                               inputs=lambda ts: self._inputs(u, ts))
        if not np.all(np.isfinite(ys)):
            raise ModelError("flexbody: state became non-finite")
        out = appendage_outputs(model, times, ys, solve, self._inputs(u, times), self.split["D"])
        return {name: out[name] for name in self.outputs}, ys[-1].copy()
