"""SRB + drogue parachute joined by a frictionless swivel: Lagrange multiplier and Watts' drift elimination.

Physics of G. Watts, *Technique To Eliminate Computational Instability in Multibody Simulations
Employing the Lagrange Multiplier*, NASA TP-3220 (1992): eqs. 1-19 (12-DOF Newton-Euler equations of
both bodies, 3x3 multiplier solve) and eq. 20 plus the position constraint (the "programming change").
Equation numbers in comments refer to the paper; "listing" means its FORTRAN appendix.

Bodies: B = solid rocket booster, C = parachute. Frames: I (NED, flat Earth, at the ground below the
SRB's initial position), B and C body frames at each CM, x = roll axis. ``A_XY`` maps Y components to
X components (``ABI``: I->B, ``ACI``: I->C, ``ACB = ACI*AIB``). All nine elements of ABI and ACI are
integrated directly (Poisson's equation), never re-orthonormalized, as in the listing.

Formulations (parameter ``formulation``):

- ``"stabilized"`` (the listing): state = the listing's 30-vector XX
  ``[ABI (9, row-major), ACI (9), V_B (3, B axes), W_B (3), W_C (3), R_B (3, I frame)]``; only
  DOmega cells 1, 2, 4 are integrated; V_C (eq. 20) and R_C (position constraint) are recomputed from
  it at every derivative evaluation, so no state can violate the joint.
- ``"velocity_only"`` (the paper's "sufficient" step): as above plus R_C integrated (33 states).
- ``"unstabilized"`` (the textbook / pre-1992 form): all 12 accelerations integrated and R_C integrated
  from V_C (36 states: the 30 above, then V_C (3, C axes), R_C (3)). Drifts.

Units: English (ft, s, lbf, slug, slug*ft^2), angles in radians internally.

The paper prints no input deck. The default configuration in ``DEFAULT_PARAMS`` is CHOSEN for this
project (it is the stand-in deck of the spec, docs/lagrange_pair.md): 165,000 lbf SRB, 1,000 lbf
54-ft drogue, swivel 70 ft ahead of the SRB CM on its roll axis and 150 ft ahead of the canopy CM,
released at 15,000 ft, 300 ft/s, flight path -60 deg, SRB flying tail first (alpha 160 deg).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from subsims.lagrange_pair import aero
from subsims.numerics import cross, dcm321, rk4, substeps

GZERO = 32.1740485  # ft/s^2, listing constant
DEG = 1.0 / aero.RAD2DEG  # rad per deg (1/CNV)

FORMULATIONS: dict[str, int] = {"stabilized": 30, "velocity_only": 33, "unstabilized": 36}
INTEGRATORS = ("rk4", "euler")

# CHOSEN configuration (not from the paper; the paper reads all of these from an unlisted input deck).
DEFAULT_PARAMS: dict[str, Any] = {
    "formulation": "stabilized",  # or "velocity_only", "unstabilized"
    "aero": True,  # built-in aerodynamics of the listing; False when a separate aero subsim supplies loads
    "gravity": True,  # flat-Earth gravity; aero=False and gravity=False together is the listing's IFE=0
    "integrator": "rk4",  # fixed-step classical Runge-Kutta (RUNGF); "euler" for comparisons only
    "dt": 0.01,  # s, largest integration sub-step (DELT)
    "g": GZERO,  # ft/s^2; also converts weights to masses (MASS = WGHT/GZERO)
    "weight_B": 165000.0,  # lbf -> m_B = 5128.357 slug
    "inertia_B": (9.5e4, 9.5e6, 9.5e6, 0.0, 0.0, 0.0),  # slug*ft^2: Ixx, Iyy, Izz, Ixy, Ixz, Iyz
    "weight_C": 1000.0,  # lbf -> m_C = 31.08095 slug
    "inertia_C": (2.0e4, 1.5e4, 1.5e4, 0.0, 0.0, 0.0),
    "attach_B": (70.0, 0.0, 0.0),  # ft, B axes, SRB CM -> swivel (XATTB, YATTB, ZATTB)
    "attach_C": (150.0, 0.0, 0.0),  # ft, C axes, canopy CM -> swivel (XATTC, YATTC, ZATTC)
    "speed_B": 300.0,  # ft/s (VIBS)
    "azimuth_B_deg": 0.0,  # from north toward east (AZIIBS)
    "flight_path_B_deg": -60.0,  # positive up (GAMIBS)
    "altitude_B": 15000.0,  # ft (ALTBS); R_B(0) = [0, 0, -altitude_B]
    "rates_B_deg": (0.0, 5.0, 0.0),  # deg/s, p q r of the SRB (PDEGBS, QDEGBS, RDEGBS)
    "alpha_B_deg": 160.0,  # total angle of attack (ALPHBS)
    "phia_B_deg": 0.0,  # aero roll angle (PHIABS)
    "bank_B_deg": 0.0,  # bank angle (BANKBS)
    "rates_C_deg": (0.0, -10.0, 5.0),  # deg/s, p q r of the parachute
    "euler_C_deg": (0.0, -60.0, 0.0),  # 3-2-1 Euler angles psi, theta, phi of the parachute (PSICS, ...)
    "x0": None,  # optional: the initial state vector itself (overrides the initial-condition parameters)
}


# ----------------------------------------------------------------------------------------------------
# Small matrix helpers


def tilde(a: np.ndarray) -> np.ndarray:
    """Skew-symmetric cross-product matrix: ``tilde(a) @ b == cross(a, b)``."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def inertia_matrix(
    ixx: float, iyy: float, izz: float, ixy: float = 0.0, ixz: float = 0.0, iyz: float = 0.0
) -> np.ndarray:
    """IMATRX (not listed): products of inertia entered as positive integrals, appearing with minus signs."""
    return np.array([[ixx, -ixy, -ixz], [-ixy, iyy, -iyz], [-ixz, -iyz, izz]], dtype=np.float64)


def dcm_321(psi: float, theta: float, phi: float) -> np.ndarray:
    """I -> body matrix of a 3-2-1 Euler sequence (listing, parachute initialization): the one 3-2-1 DCM."""
    return np.array(dcm321((phi, theta, psi)))


def euler_321(a: np.ndarray) -> np.ndarray:
    """3-2-1 Euler angles (psi, theta, phi) in rad of an I -> body matrix (listing output section)."""
    theta = math.asin(min(1.0, max(-1.0, -a[0, 2])))
    return np.array([aero.ztan2(a[0, 1], a[0, 0]), theta, aero.ztan2(a[1, 2], a[2, 2])])


def orthogonality_error(a: np.ndarray) -> float:
    """ORTH (not listed): max |A A^T - I|, the listing's 'error indicator'."""
    return float(np.max(np.abs(a @ a.T - np.eye(3))))


# ----------------------------------------------------------------------------------------------------
# Static model


@dataclass(frozen=True, eq=False)
class PairModel:
    """Mass properties, attach points and load switches of the pair; derived matrices are built once."""

    m_b: float
    i_b: np.ndarray
    m_c: float
    i_c: np.ndarray
    l_b: np.ndarray  # LABB, B axes
    l_c: np.ndarray  # LACC, C axes
    g: float = GZERO
    aero: bool = True
    gravity: bool = True
    formulation: str = "stabilized"
    M: np.ndarray = field(init=False, repr=False)  # derived matrices: built once, too big to print
    MINV: np.ndarray = field(init=False, repr=False)
    lt_b: np.ndarray = field(init=False, repr=False)
    lt_c: np.ndarray = field(init=False, repr=False)
    a_34: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.formulation not in FORMULATIONS:
            raise ValueError(f"formulation must be one of {sorted(FORMULATIONS)}, got {self.formulation!r}")
        for name in ("i_b", "i_c", "l_b", "l_c"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        M, MINV = mass_matrix(self.m_b, self.i_b, self.m_c, self.i_c)
        lt_b, lt_c = tilde(self.l_b), tilde(self.l_c)
        a_34 = np.hstack([-np.eye(3), lt_c])  # cells 3 and 4 of [A] (eq. 12), constant
        for name, arr in (("M", M), ("MINV", MINV), ("lt_b", lt_b), ("lt_c", lt_c), ("a_34", a_34)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def state_size(self) -> int:
        return FORMULATIONS[self.formulation]


def mass_matrix(m_b: float, i_b: np.ndarray, m_c: float, i_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[M] (eq. 2) and its inverse, both 12x12 quasi-diagonal; [MINV] is built cell by cell as in the listing."""
    M = np.zeros((12, 12))
    MINV = np.zeros((12, 12))
    M[0:3, 0:3] = m_b * np.eye(3)
    M[3:6, 3:6] = i_b
    M[6:9, 6:9] = m_c * np.eye(3)
    M[9:12, 9:12] = i_c
    MINV[0:3, 0:3] = np.eye(3) / m_b
    MINV[3:6, 3:6] = np.linalg.inv(i_b)
    MINV[6:9, 6:9] = np.eye(3) / m_c
    MINV[9:12, 9:12] = np.linalg.inv(i_c)
    return M, MINV


# ----------------------------------------------------------------------------------------------------
# One derivative evaluation


@dataclass(frozen=True, eq=False)
class Evaluation:
    """Everything the listing computes in one pass of its derivative section."""

    ABI: np.ndarray
    ACI: np.ndarray
    ACB: np.ndarray
    R_B: np.ndarray  # I frame, ft
    R_C: np.ndarray  # I frame, ft (position constraint, or integrated)
    V_B: np.ndarray  # B axes, ft/s
    V_C: np.ndarray  # C axes, ft/s (eq. 20, or integrated)
    W_B: np.ndarray  # B axes, rad/s
    W_C: np.ndarray  # C axes, rad/s
    FL: np.ndarray  # aero loads (12)
    FG: np.ndarray  # gravity (12)
    FX: np.ndarray  # extra loads from the input ports (12)
    FE: np.ndarray  # FL + FG + FX
    FW: np.ndarray  # -W x H terms
    F: np.ndarray  # FE + FW
    Om: np.ndarray  # [Omega]
    A: np.ndarray  # constraint matrix, 3x12
    ADOT: np.ndarray  # its time derivative, 3x12
    lam: np.ndarray  # Lagrange multiplier: swivel force on B, C axes, lbf
    FA: np.ndarray  # A^T lam
    DOm: np.ndarray  # [DOmega], 12


def split_state(model: PairModel, x: np.ndarray) -> tuple[np.ndarray, ...]:
    """(ABI, ACI, V_B, W_B, W_C, R_B, V_C or None, R_C or None) views of a state vector."""
    ABI = x[0:9].reshape(3, 3)
    ACI = x[9:18].reshape(3, 3)
    V_B, W_B, W_C, R_B = x[18:21], x[21:24], x[24:27], x[27:30]
    V_C = R_C = None
    if model.formulation == "velocity_only":
        R_C = x[30:33]
    elif model.formulation == "unstabilized":
        V_C, R_C = x[30:33], x[33:36]
    return ABI, ACI, V_B, W_B, W_C, R_B, V_C, R_C


def constrained_c(
    model: PairModel, ABI: np.ndarray, ACI: np.ndarray,
    V_B: np.ndarray, W_B: np.ndarray, W_C: np.ndarray, R_B: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """V_C (eq. 20, C axes) and R_C (position constraint, I frame) of the parachute from the independent coordinates."""
    AIB, AIC = ABI.T, ACI.T
    ACB = ACI @ AIB
    R_C = R_B + AIB @ model.l_b - AIC @ model.l_c  # RICI = RIBI + [AIB]*LABB - [AIC]*LACC
    V_C = ACB @ (V_B + cross(W_B, model.l_b)) - cross(W_C, model.l_c)  # eq. 20
    return V_C, R_C


def evaluate(model: PairModel, x: np.ndarray, extra: np.ndarray | None = None) -> Evaluation:
    """The listing's derivative section at state ``x``; ``extra`` = 12 extra loads [F_B, M_B, F_C, M_C], body axes."""
    ABI, ACI, V_B, W_B, W_C, R_B, V_C, R_C = split_state(model, x)
    ACB = ACI @ ABI.T
    if model.formulation != "unstabilized":
        V_C_con, R_C_con = constrained_c(model, ABI, ACI, V_B, W_B, W_C, R_B)
        V_C = V_C_con  # eq. 20 at every evaluation
        if model.formulation == "stabilized":
            R_C = R_C_con  # position constraint at every evaluation

    # external loads [FE] = [FL] + [FG] (+ extra loads from other subsims)
    FL = np.zeros(12)
    if model.aero:
        f_b, m_b, f_c, m_c = aero.pair_aero_loads(-R_B[2], V_B, V_C)
        FL[0:3], FL[3:6], FL[6:9], FL[9:12] = f_b, m_b, f_c, m_c
    FG = np.zeros(12)
    if model.gravity:
        FG[0:3] = model.m_b * model.g * ABI[:, 2]  # MASSB * [ABI] [0, 0, GZERO]
        FG[6:9] = model.m_c * model.g * ACI[:, 2]
    FX = np.zeros(12) if extra is None else np.asarray(extra, dtype=np.float64)
    FE = FL + FG + FX

    Om = np.concatenate([V_B, W_B, V_C, W_C])  # [Omega]
    H = model.M @ Om  # momentum matrix [H]
    FW = np.concatenate(
        [-cross(W_B, H[0:3]), -cross(W_B, H[3:6]), -cross(W_C, H[6:9]), -cross(W_C, H[9:12])]
    )  # (1A), (1B): -W x (m V), -W x H
    F = FE + FW  # [F] = [FE] + [FW]

    A = np.hstack([ACB, -ACB @ model.lt_b, model.a_34])  # eq. 12, cells [ACB | -ACB LTB | -IDENT | LTC]
    ACBD = -tilde(W_C) @ ACB + ACB @ tilde(W_B)  # [ACBDOT] = -[OMTC][ACB] + [ACB][OMTB]
    ADOT = np.zeros((3, 12))
    ADOT[:, 0:3] = ACBD
    ADOT[:, 3:6] = -ACBD @ model.lt_b  # cells 3, 4 of [ADOT] are zero

    AMINV = A @ model.MINV
    try:
        lam = np.linalg.solve(AMINV @ A.T, -AMINV @ F - ADOT @ Om)  # eq. 18
    except np.linalg.LinAlgError as exc:  # only with a degenerate (non-finite) state
        raise FloatingPointError(f"multiplier solve failed: {exc}") from exc
    FA = A.T @ lam  # eq. 16 / 19
    DOm = model.MINV @ (F + FA)  # eq. 3
    return Evaluation(ABI, ACI, ACB, R_B, R_C, V_B, V_C, W_B, W_C, FL, FG, FX, FE, FW, F, Om, A, ADOT, lam, FA, DOm)


def derivative(model: PairModel, ev: Evaluation) -> np.ndarray:
    """Time derivative of the state from an evaluation: Poisson's equation, the integrated accelerations, dR/dt."""
    ABID = -tilde(ev.W_B) @ ev.ABI  # B11D = B21*OMB(3) - B31*OMB(2), ...
    ACID = -tilde(ev.W_C) @ ev.ACI
    parts = [ABID.ravel(), ACID.ravel(), ev.DOm[0:3], ev.DOm[3:6], ev.DOm[9:12], ev.ABI.T @ ev.V_B]  # DOM9, VIBI
    if model.formulation == "velocity_only":
        parts.append(ev.ACI.T @ ev.V_C)  # R_C integrated from the constrained V_C
    elif model.formulation == "unstabilized":
        parts += [ev.DOm[6:9], ev.ACI.T @ ev.V_C]  # all 12 accelerations and both positions integrated
    return np.concatenate(parts)


# ----------------------------------------------------------------------------------------------------
# Diagnostics


def joint_violation(model: PairModel, ev: Evaluation) -> tuple[np.ndarray, np.ndarray]:
    """Position (I frame, ft) and velocity (A*Omega, C axes, ft/s) violation of the swivel."""
    pos = (ev.R_B + ev.ABI.T @ model.l_b) - (ev.R_C + ev.ACI.T @ model.l_c)
    return pos, ev.A @ ev.Om


def invariants(model: PairModel, ev: Evaluation) -> tuple[float, np.ndarray, np.ndarray]:
    """Kinetic energy (ft*lbf), linear momentum (I frame) and angular momentum about the I origin (I frame)."""
    v_b, v_c = ev.ABI.T @ ev.V_B, ev.ACI.T @ ev.V_C
    h_b, h_c = model.i_b @ ev.W_B, model.i_c @ ev.W_C
    ke = 0.5 * (model.m_b * v_b @ v_b + model.m_c * v_c @ v_c + ev.W_B @ h_b + ev.W_C @ h_c)
    p = model.m_b * v_b + model.m_c * v_c
    h = model.m_b * cross(ev.R_B, v_b) + model.m_c * cross(ev.R_C, v_c) + ev.ABI.T @ h_b + ev.ACI.T @ h_c
    return float(ke), p, h


# ----------------------------------------------------------------------------------------------------
# Integration (RUNGF: fixed-step classical RK4; forward Euler for comparison)

LoadFunction = Callable[[float], np.ndarray | None]
EvalHook = Callable[[float, Evaluation], None]


def integrate(
    model: PairModel,
    x0: np.ndarray,
    times: np.ndarray,
    loads: LoadFunction | None = None,
    dt: float = 0.01,
    integrator: str = "rk4",
    hook: EvalHook | None = None,
    inputs: Callable[[np.ndarray], Sequence[np.ndarray]] | None = None,
) -> tuple[list[Evaluation], np.ndarray]:
    """Integrate from ``x0`` at ``times[0]``; return the evaluations at every sample time and the final state.

    Between consecutive samples the interval is cut into equal sub-steps of at most ``dt`` (the shared RK4,
    ``subsims.numerics.rk4``; ``integrator="euler"`` for comparisons). The evaluation at a sample is also the
    first RK stage of the next step (the listing prints the derivative pass that follows each completed step).
    Extra loads (12, body axes): ``loads(t)`` called at every evaluation, or ``inputs(ts)`` giving them at all
    the RK times ``ts`` at once. ``hook(t, ev)`` sees every evaluation.
    """
    if integrator not in INTEGRATORS:
        raise ValueError(f"integrator must be one of {list(INTEGRATORS)}, got {integrator!r}")

    def evaluation(t: float, x: np.ndarray, row: np.ndarray | None) -> Evaluation:
        ev = evaluate(model, x, row if inputs is not None else None if loads is None else loads(t))
        if hook is not None:
            hook(t, ev)
        return ev

    def node(t: float, x: np.ndarray, row: np.ndarray | None) -> tuple[np.ndarray, Evaluation]:
        ev = evaluation(t, x, row)
        return derivative(model, ev), ev

    times = np.asarray(times, dtype=np.float64)
    states, samples, x = rk4(lambda t, x, row: derivative(model, evaluation(t, x, row)), x0, times,
                             substeps(times, dt), inputs, node=node, end_node=True, euler=integrator == "euler")
    bad = [k for k, s in enumerate(states) if not np.all(np.isfinite(s))]
    if bad:
        raise FloatingPointError(f"state became non-finite between t={times[bad[0] - 1]} and t={times[bad[0]]}")
    return samples, x


# ----------------------------------------------------------------------------------------------------
# Parameters, initial state, outputs


def _vector(params: Mapping[str, Any], key: str, n: int) -> np.ndarray:
    v = np.asarray(params[key], dtype=np.float64)
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise ValueError(f"parameter {key!r} must be {n} finite numbers, got {params[key]!r}")
    return v


def _number(params: Mapping[str, Any], key: str, positive: bool = False) -> float:
    try:
        v = float(params[key])
    except (TypeError, ValueError) as exc:
        raise ValueError(f"parameter {key!r} must be a number, got {params[key]!r}") from exc
    if not math.isfinite(v) or (positive and v <= 0.0):
        raise ValueError(f"parameter {key!r} must be finite{' and > 0' if positive else ''}, got {v!r}")
    return v


def merged_params(params: Mapping[str, Any] | None) -> dict[str, Any]:
    """DEFAULT_PARAMS updated with ``params``; unknown names raise KeyError."""
    params = dict(params or {})
    unknown = sorted(set(params) - set(DEFAULT_PARAMS))
    if unknown:
        raise KeyError(f"unknown lagrange_pair parameter(s) {unknown}; known: {sorted(DEFAULT_PARAMS)}")
    return {**DEFAULT_PARAMS, **params}


def build_model(params: Mapping[str, Any]) -> PairModel:
    """PairModel from (merged) parameters."""
    g = _number(params, "g", positive=True)
    i_b, i_c = _vector(params, "inertia_B", 6), _vector(params, "inertia_C", 6)
    for key, ivec in (("inertia_B", i_b), ("inertia_C", i_c)):
        if np.any(np.linalg.eigvalsh(inertia_matrix(*ivec)) <= 0.0):
            raise ValueError(f"parameter {key!r} does not give a positive definite inertia matrix: {ivec.tolist()}")
    for key in ("aero", "gravity"):
        if not isinstance(params[key], bool | np.bool_):
            raise ValueError(f"parameter {key!r} must be a bool, got {params[key]!r}")
    if params["formulation"] not in FORMULATIONS:
        raise ValueError(f"parameter 'formulation' must be one of {list(FORMULATIONS)}, got {params['formulation']!r}")
    return PairModel(
        m_b=_number(params, "weight_B", positive=True) / g,  # MASSB = WGHTB/GZERO
        i_b=inertia_matrix(*i_b),
        m_c=_number(params, "weight_C", positive=True) / g,
        i_c=inertia_matrix(*i_c),
        l_b=_vector(params, "attach_B", 3),
        l_c=_vector(params, "attach_C", 3),
        g=g,
        aero=bool(params["aero"]),
        gravity=bool(params["gravity"]),
        formulation=params["formulation"],
    )


def pack_state(
    model: PairModel, ABI: np.ndarray, ACI: np.ndarray,
    V_B: np.ndarray, W_B: np.ndarray, W_C: np.ndarray, R_B: np.ndarray,
) -> np.ndarray:
    """State vector of ``model.formulation``; C's translation (where it is a state) comes from the constraints."""
    x = np.concatenate([np.ravel(ABI), np.ravel(ACI), V_B, W_B, W_C, R_B]).astype(np.float64)
    V_C, R_C = constrained_c(model, np.reshape(ABI, (3, 3)), np.reshape(ACI, (3, 3)), V_B, W_B, W_C, R_B)
    if model.formulation == "velocity_only":
        x = np.concatenate([x, R_C])
    elif model.formulation == "unstabilized":
        x = np.concatenate([x, V_C, R_C])
    return x


def initial_state(model: PairModel, params: Mapping[str, Any]) -> np.ndarray:
    """The listing's initialization section (records 4-6 of its input deck), or the ``x0`` parameter."""
    if params.get("x0") is not None:
        x0 = np.array(params["x0"], dtype=np.float64)
        if x0.shape != (model.state_size,) or not np.all(np.isfinite(x0)):
            raise ValueError(f"parameter 'x0' must be {model.state_size} finite numbers for {model.formulation!r}")
        return x0
    alpha = _number(params, "alpha_B_deg") * DEG
    phia = _number(params, "phia_B_deg") * DEG
    bank = _number(params, "bank_B_deg") * DEG
    azi = _number(params, "azimuth_B_deg") * DEG
    gam = _number(params, "flight_path_B_deg") * DEG
    sbk, cbk, sal, cal = math.sin(bank), math.cos(bank), math.sin(alpha), math.cos(alpha)
    spa, cpa = math.sin(phia), math.cos(phia)
    ABV = np.array(  # 1-2-1 sequence (BANKB, ALPHAB, PHIAB)
        [
            [cal, sbk * sal, -cbk * sal],
            [spa * sal, cpa * cbk - spa * sbk * cal, cpa * sbk + spa * cbk * cal],
            [cpa * sal, -spa * cbk - cpa * sbk * cal, -spa * sbk + cpa * cbk * cal],
        ]
    )
    saz, caz, sgm, cgm = math.sin(azi), math.cos(azi), math.sin(gam), math.cos(gam)
    AVI = np.array([[caz * cgm, saz * cgm, -sgm], [-saz, caz, 0.0], [caz * sgm, saz * sgm, cgm]])
    ABI = ABV @ AVI
    speed = _number(params, "speed_B")
    VIBI = speed * np.array([cgm * caz, cgm * saz, -sgm])
    R_B = np.array([0.0, 0.0, -_number(params, "altitude_B")])
    W_B = _vector(params, "rates_B_deg", 3) * DEG
    W_C = _vector(params, "rates_C_deg", 3) * DEG
    ACI = dcm_321(*(_vector(params, "euler_C_deg", 3) * DEG))
    return pack_state(model, ABI, ACI, ABI @ VIBI, W_B, W_C, R_B)


def setup(params: Mapping[str, Any] | None) -> tuple[PairModel, float, str, np.ndarray]:
    """Validate parameters; return (model, dt, integrator, initial state)."""
    p = merged_params(params)
    model = build_model(p)
    dt = _number(p, "dt", positive=True)
    if p["integrator"] not in INTEGRATORS:
        raise ValueError(f"parameter 'integrator' must be one of {list(INTEGRATORS)}, got {p['integrator']!r}")
    return model, dt, p["integrator"], initial_state(model, p)


OUTPUT_NAMES = (
    "pos_B", "pos_C", "vel_B", "vel_C", "vel_B_I", "vel_C_I", "euler_B", "euler_C", "dcm_B", "dcm_C",
    "omega_B", "omega_C", "multiplier", "violation_pos", "violation_vel",
)  # fmt: skip


def outputs_of(model: PairModel, ev: Evaluation) -> dict[str, np.ndarray]:
    """The pair's output signals at one evaluation (see the adapter's port table for units and frames)."""
    pos, vel = joint_violation(model, ev)
    return {
        "pos_B": ev.R_B,
        "pos_C": ev.R_C,
        "vel_B": ev.V_B,
        "vel_C": ev.V_C,
        "vel_B_I": ev.ABI.T @ ev.V_B,
        "vel_C_I": ev.ACI.T @ ev.V_C,
        "euler_B": euler_321(ev.ABI),
        "euler_C": euler_321(ev.ACI),
        "dcm_B": ev.ABI.ravel(),
        "dcm_C": ev.ACI.ravel(),
        "omega_B": ev.W_B,
        "omega_C": ev.W_C,
        "multiplier": ev.lam,
        "violation_pos": pos,
        "violation_vel": vel,
    }


def stack_outputs(model: PairModel, samples: list[Evaluation]) -> dict[str, np.ndarray]:
    """Output arrays (n, size) from the evaluations at the sample times."""
    rows = [outputs_of(model, ev) for ev in samples]
    return {name: np.array([r[name] for r in rows], dtype=np.float64) for name in OUTPUT_NAMES}


def run_reference(
    t_stop: float, params: Mapping[str, Any] | None = None, t_start: float = 0.0, sample_interval: float = 0.1
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Monolithic reference: integrate the pair (built-in aerodynamics by default) from t_start to t_stop.

    Returns the sample times (every ``sample_interval``, plus ``t_stop``) and the adapter's outputs
    at them, ``{name: (n, size)}``. No extra loads are applied.
    """
    model, dt, integrator, x0 = setup(params)
    if not t_stop > t_start or sample_interval <= 0.0:
        raise ValueError(f"need t_stop > t_start and sample_interval > 0, got {t_start}, {t_stop}, {sample_interval}")
    n = int(math.floor((t_stop - t_start) / sample_interval + 1e-9))
    times = t_start + sample_interval * np.arange(n + 1)
    if t_stop - times[-1] > 1e-9 * max(1.0, abs(t_stop)):
        times = np.append(times, t_stop)
    else:
        times[-1] = t_stop
    samples, _ = integrate(model, x0, times, None, dt, integrator)
    return times, stack_outputs(model, samples)
