"""The paper's three control cases and run settings as plain dicts (spec §9.1, §7.5, §3.5, §7.8).

Every case uses the same orbit, aero and transfer; only the attitude gains differ (spec §7.5 table;
text §7.1: "For case 2, the Z-axis control gains were set to zero; and for case 3, all control gains
were set to zero"). Parameter names are those of ``Orbit``, ``Attitude`` and ``Aero``; omitted ones take
the paper's defaults (spec §7). ``transfer`` are the params of ``transforms.torque_to_cm``.
"""

from __future__ import annotations

import copy
from typing import Any

from subsims.satellite import constants as C

# spec §7.8: circular 300 km orbit, 30 deg inclination, start at the northernmost point; spec §7.2 mass
ORBIT: dict[str, Any] = {"altitude_km": C.ALTITUDE_KM, "inclination_deg": C.INCLINATION_DEG, "mass": C.MASS, "idiv": 1}

# spec §7.6: rho 1.95e-11 kg/m^3 constant, Cd 2.25, 15 x 4 x 3 m box
AERO: dict[str, Any] = {"rho": C.RHO, "cd": C.CD, "length": C.BOX_LENGTH, "width": C.BOX_WIDTH, "height": C.BOX_HEIGHT}

# spec §7.4: inertia diag(11250, 193125, 0.9*193125) kg m^2; spec §7.8: phi0 = omega0 = 0; spec §3.2: idiv 1
_ATTITUDE: dict[str, Any] = {"inertia": [C.IXX, C.IYY, C.IZZ], "phi0": [0.0, 0.0, 0.0], "omega0": [0.0, 0.0, 0.0],
                             "idiv": 1}

# spec §7.4 r_cm (1.0, 0.1, 0.1) m; spec §7.6/§12.1 item 2: the listings' sign T + r_cm x F
TRANSFER: dict[str, Any] = {"r_cm": list(C.R_CM), "physical": False}

_FULL = dict(C.GAINS_FULL)


def _case(**attitude_gains: float) -> dict[str, dict[str, Any]]:
    return copy.deepcopy({"orbit": ORBIT, "attitude": {**_ATTITUDE, **attitude_gains}, "aero": AERO,
                          "transfer": TRANSFER})


CASES: dict[str, dict[str, dict[str, Any]]] = {
    "case1": _case(**_FULL),  # full inertial three-axis control (attitude.f as listed)
    "case2": _case(**{**_FULL, "c0": 0.0, "c1": 0.0}),  # two-axis control: z gains zero
    "case3": _case(**{g: 0.0 for g in _FULL}),  # no control, tumble (rku.f as listed: control=0)
}

# spec §9.1 / §3.1: ndp 5 samples per interval incl. both ends, dtmaj 0.4 s -> delt 0.1 s; 60,000 s runs
RUN: dict[str, Any] = {"ndp": 5, "dtmaj": 0.4, "delt": 0.1, "t_stop": 60000.0, "itmax": 100}

# spec §3.5: span-relative tol and absolute res, per scalar signal, max-abs stage difference
METHODS: dict[str, dict[str, Any]] = {
    "rfc": {"tol": 1e-12, "res": 1e-12, "check": "all 18 subsystem outputs"},
    "rfd": {"tol": 1e-14, "res": 1e-14, "check": "the 6 feedback signals (aero force inertial, torque at c.m.)",
            "order": ["orbit", "attitude", "aero"]},
    "rku": {"dt": 0.1},
}

# spec §7.9: the REAL*4-promoted literals (constants.FORTRAN_LITERALS), for bit-level experiments only (merge
# into the dicts above)
FORTRAN_LITERALS: dict[str, dict[str, Any]] = {
    "orbit": {"mu": C.FORTRAN_LITERALS["gme"]},
    "attitude": {"mu": C.FORTRAN_LITERALS["gme"], "inertia": [C.IXX, C.IYY, C.FORTRAN_LITERALS["izz"]]},
    "aero": {"rho": C.FORTRAN_LITERALS["rho"]},
}
