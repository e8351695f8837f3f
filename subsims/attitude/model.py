"""Attitude dynamics and control (spec §7.3-7.5; paper eqs. 13-17; listing attitude.f / sub2 / rksys2).

Rigid body about its c.m. State x = [phi_x, phi_y, phi_z (rad), omega_x, omega_y, omega_z (rad/s, body)].
Euler angles: inertial -> body by z (phi_z, 1st), y (phi_y, 2nd), x (phi_x, 3rd) rotations.
Torques (body, about the c.m.): gravity gradient, linear control, external (aerodynamic) input.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from subsims import numerics
from subsims.numerics import Mat, PhysicsError, Vec, cross3, matvec, rk4, rotation321, vecnorm
from subsims.satellite import constants as C
from subsims.satellite.parameters import as_float, as_int, as_vec3

GAIN_NAMES = ("a0", "a1", "b0", "b1", "c0", "c1")
PARAM_NAMES = ("inertia", "mu", "idiv", "phi0", "omega0", "min_cos_phi_y", *GAIN_NAMES)
MIN_COS_PHI_Y = 1e-6  # cos phi_y below this (phi_y within ~6e-5 deg of, or beyond, +-90 deg): EulerSingularityError


dcm321, dcm321_batch = numerics.dcm321, numerics.dcm321_batch  # eq. 15, kept where the attitude's users look


class EulerSingularityError(PhysicsError):
    """The 3-2-1 Euler-rate kinematics (eq. 14) is singular at phi_y = +-90 deg."""


# --- kinematics ---------------------------------------------------------------------------------------


def dcm2ang321(a: Mat) -> tuple[float, float, float]:
    """dcm2ang321 (spec §7.3): angles of A in (-pi, pi] x [-pi/2, pi/2] x (-pi, pi] (output range limiting)."""
    phi_y = math.atan2(-a[0][2], math.hypot(a[0][0], a[0][1]))
    return math.atan2(a[1][2], a[2][2]), phi_y, math.atan2(a[0][1], a[0][0])


def euler_rates(phi: Vec, omega: Vec, min_cos_phi_y: float = MIN_COS_PHI_Y,
                sin_cos: tuple[Vec, Vec] | None = None) -> tuple[float, float, float]:
    """Eq. 14 (sub2 form, tan = sin/cos): Euler-angle rates from body rates.

    ``sin_cos``: (sines, cosines) of ``phi`` if the caller has them already. Raises ``EulerSingularityError``
    unless cos phi_y >= ``min_cos_phi_y``: phi_y (unlimited) can leave (-90, 90) deg only through the
    singularity, so this also catches an RK stage that jumped over it.
    """
    if sin_cos is None:
        sin_1, sin_2, cos_1, cos_2 = math.sin(phi[0]), math.sin(phi[1]), math.cos(phi[0]), math.cos(phi[1])
    else:
        (sin_1, sin_2, _), (cos_1, cos_2, _) = sin_cos
    # phi_y must stay in (-90, 90) deg (+ k 360): a step that jumps over the singularity is caught too
    if not cos_2 >= min_cos_phi_y:  # also catches NaN
        raise EulerSingularityError(
            f"3-2-1 Euler angles singular: phi_y = {math.degrees(phi[1]):.6f} deg reached +-90 deg "
            f"(cos phi_y = {cos_2:.3e} < min_cos_phi_y = {min_cos_phi_y:.1e}); the z-y-x Euler-rate "
            "kinematics (eq. 14) cannot continue through this attitude")
    tan_2 = sin_2 / cos_2
    w1, w2, w3 = omega
    return (w1 + sin_1 * tan_2 * w2 + cos_1 * tan_2 * w3,
            cos_1 * w2 - sin_1 * w3,
            sin_1 / cos_2 * w2 + cos_1 / cos_2 * w3)


# --- torques --------------------------------------------------------------------------------------------


def gravity_gradient_torque(amat: Mat, rad: Vec, inertia: Mat, mu: float) -> tuple[float, float, float]:
    """T_gg = (3 mu / R^3) r_b x (I r_b), r_b = A R/|R| (sub2; the listing's factor 3, not eq. 17's 1).

    Zero when |R| < 1e-6 m (sub2 guard: RF-C stage 0 feeds R = 0).
    """
    rad_norm, rmag = vecnorm(rad)
    if rmag < 1e-6:
        return 0.0, 0.0, 0.0
    rb = matvec(amat, rad_norm)
    rxxir = cross3(rb, matvec(inertia, rb))
    ggmul = 3.0 * mu / rmag**3
    return ggmul * rxxir[0], ggmul * rxxir[1], ggmul * rxxir[2]


def control_torque(phi: Vec, omega: Vec, gains: Mapping[str, float]) -> tuple[float, float, float]:
    """Eq. 16: linear inertial-hold control on raw Euler angles and body rates."""
    return (-(gains["a0"] * phi[0] + gains["a1"] * omega[0]),
            -(gains["b0"] * phi[1] + gains["b1"] * omega[1]),
            -(gains["c0"] * phi[2] + gains["c1"] * omega[2]))


# --- parameters and dynamics -----------------------------------------------------------------------------


def _inertia(value: Any) -> tuple[tuple[float, float, float], ...]:
    a = np.asarray(value, dtype=np.float64)
    if a.shape == (3,):
        a = np.diag(a)
    if a.shape != (3, 3) or not np.all(np.isfinite(a)):
        raise ValueError(f"parameter 'inertia' must be 3 principal moments or a finite 3x3 matrix, got {value!r}")
    if not np.allclose(a, a.T, rtol=1e-12, atol=0.0) or np.any(np.linalg.eigvalsh(0.5 * (a + a.T)) <= 0.0):
        raise ValueError(f"parameter 'inertia' must be symmetric positive definite, got {a.tolist()}")
    return tuple(tuple(row) for row in a.tolist())  # type: ignore[return-value]


@dataclass(frozen=True)
class AttitudeParams:
    """Constants of the attitude subsystem (attitude.f mode 1) and its initial conditions (mode 2)."""

    inertia: tuple[tuple[float, float, float], ...] = C.INERTIA  # xmoi, kg m^2, body axes at the c.m.
    inertia_inv: tuple[tuple[float, float, float], ...] = ()  # filled from inertia
    mu: float = C.GME
    gains: Mapping[str, float] = field(default_factory=lambda: dict(C.GAINS_FULL))  # a0 a1 b0 b1 c0 c1
    idiv: int = 1
    phi0: tuple[float, float, float] = (0.0, 0.0, 0.0)
    omega0: tuple[float, float, float] = (0.0, 0.0, 0.0)
    min_cos_phi_y: float = MIN_COS_PHI_Y

    def __post_init__(self) -> None:
        if not self.inertia_inv:
            inv = np.linalg.inv(np.array(self.inertia, dtype=np.float64))  # inv3
            object.__setattr__(self, "inertia_inv", tuple(tuple(row) for row in inv.tolist()))

    @classmethod
    def from_mapping(cls, params: Mapping[str, Any]) -> AttitudeParams:
        """Build from a parameter dict; defaults are the paper's case 1. Unknown names raise ValueError.

        ``inertia``: 3 principal moments or a 3x3 matrix (kg m^2); gains ``a0 a1 b0 b1 c0 c1`` (N m/rad,
        N m s/rad); ``phi0`` (rad), ``omega0`` (rad/s); ``min_cos_phi_y``: singularity margin.
        """
        unknown = sorted(set(params) - set(PARAM_NAMES))
        if unknown:
            raise ValueError(f"unknown attitude parameter(s) {unknown}; known: {', '.join(PARAM_NAMES)}")
        gains = {g: as_float(params.get(g, C.GAINS_FULL[g]), g) for g in GAIN_NAMES}
        return cls(inertia=_inertia(params.get("inertia", C.INERTIA)),
                   mu=as_float(params.get("mu", C.GME), "mu", nonnegative=True),
                   gains=gains,
                   idiv=as_int(params.get("idiv", 1), "idiv"),
                   phi0=as_vec3(params.get("phi0", (0.0, 0.0, 0.0)), "phi0"),
                   omega0=as_vec3(params.get("omega0", (0.0, 0.0, 0.0)), "omega0"),
                   min_cos_phi_y=as_float(params.get("min_cos_phi_y", MIN_COS_PHI_Y), "min_cos_phi_y",
                                          positive=True))

    def initial_state(self) -> np.ndarray:
        if not math.cos(self.phi0[1]) >= self.min_cos_phi_y:
            raise ValueError(f"parameter 'phi0': phi_y = {self.phi0[1]!r} rad must lie inside (-pi/2, pi/2) "
                             "(mod 2 pi), away from the 3-2-1 Euler singularity")
        return np.array(self.phi0 + self.omega0, dtype=np.float64)


def attitude_derivative(x: Vec, rad: Vec, t_aero: Vec, p: AttitudeParams) -> list[float]:
    """sub2: xdot = [phi_dot (eq. 14), omega_dot (eq. 13)].

    ``rad``: orbit radius, inertial (m). ``t_aero``: external torque about the c.m., body (N m).
    omega_dot = I^-1 (T_gg + T_aero + T_control - omega x I omega).
    """
    phi = x[0:3]
    omega = x[3:6]
    sc = ((math.sin(phi[0]), math.sin(phi[1]), math.sin(phi[2])),
          (math.cos(phi[0]), math.cos(phi[1]), math.cos(phi[2])))
    amat = rotation321(*sc)  # eq. 15
    t_gg = gravity_gradient_torque(amat, rad, p.inertia, p.mu)  # eq. 17 (x 3)
    t_c = control_torque(phi, omega, p.gains)  # eq. 16
    wxh = cross3(omega, matvec(p.inertia, omega))
    t_total = (t_gg[0] + t_aero[0] + t_c[0] - wxh[0],
               t_gg[1] + t_aero[1] + t_c[1] - wxh[1],
               t_gg[2] + t_aero[2] + t_c[2] - wxh[2])
    omegadot = matvec(p.inertia_inv, t_total)
    phidot = euler_rates(phi, omega, p.min_cos_phi_y, sc)
    return [*phidot, *omegadot]


def integrate(p: AttitudeParams, x0: Vec, times: Sequence[float],
              inputs: Callable[[np.ndarray], Sequence[tuple[Vec, Vec]]]) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """attitude mode 3: RK4 over ``times`` with ``p.idiv`` steps per sample.

    ``inputs(ts)``: for all the RK times ``ts`` (k,) in one call, per time a pair (R inertial (m), T_aero body
    at the c.m. (N m)). Returns (samples (n, 6) with row 0 = x0, omega_dot (n, 3) at the samples, state at times[-1]).
    """

    def deriv(t: float, x: Sequence[float], row: tuple[Vec, Vec]) -> list[float]:
        try:
            return attitude_derivative(x, row[0], row[1], p)
        except EulerSingularityError as e:
            raise EulerSingularityError(f"at t = {t:.9g} s: {e}") from None

    states, rates, end = rk4(deriv, [float(v) for v in x0], times, p.idiv, inputs, end_node=True)
    return np.array(states, dtype=np.float64), np.array([r[3:6] for r in rates], dtype=np.float64), end
