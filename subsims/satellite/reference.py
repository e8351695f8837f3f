"""The satellite's unified reference (RK-U, spec §6) as a scenario's ``[unified] function``.

``cosim run <scenario> --method unified`` (``cosim.unified.run_unified``) calls
``unified_scenario(params, stop=..., dt=..., start=..., couplings=...)`` with the scenario's
per-subsim parameters; the result has the coupled subsims' output ports, sample by sample.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from subsims.satellite.constants import R_CM
from subsims.satellite.unified import run_unified

SUBSIMS = ("orbit", "attitude", "aero")
TORQUE_TRANSFORM = "subsims.satellite.transforms:torque_to_cm"


def transfer_params(couplings: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """r_cm and sign of the aero torque transfer, read from the scenario's ``torque_to_cm`` coupling,
    so the reference uses exactly what the coupled runs use (paper defaults if there is none)."""
    for c in couplings:
        if c.get("transform") == TORQUE_TRANSFORM:
            p = dict(c.get("params", {}))
            return {"r_cm": p.get("r_cm", R_CM), "physical": bool(p.get("physical", False))}
    return {"r_cm": R_CM, "physical": False}


def unified_scenario(params: Mapping[str, Mapping[str, Any]], *, stop: float, dt: float, start: float = 0.0,
                     couplings: Sequence[Mapping[str, Any]] = (), substeps: int = 1) -> dict[str, Any]:
    """RK-U from ``start`` to ``stop`` with RK4 step ``dt / substeps``, one sample per ``dt``.

    ``params``: ``{"orbit": {...}, "attitude": {...}, "aero": {...}}`` (the subsims' parameters;
    their ``idiv`` is ignored). Returns ``{"t": (n,), "orbit": {"R", "V"}, "attitude": {"phi",
    "omega", "omega_dot"}, "aero": {"force", "torque"}}``.
    """
    missing = [s for s in SUBSIMS if s not in params]
    if missing:
        raise ValueError(f"the satellite reference needs subsims {list(SUBSIMS)}; missing {missing}")
    strip = {s: {k: v for k, v in params[s].items() if k != "idiv"} for s in ("orbit", "attitude")}
    tr = transfer_params(couplings)
    if start != 0.0:
        raise ValueError("the satellite reference starts at t = 0 (the orbit's initial conditions)")
    return run_unified(strip["orbit"], strip["attitude"], params["aero"], stop, dt, substeps=substeps,
                       r_cm=tuple(float(x) for x in np.asarray(tr["r_cm"], dtype=float)),
                       physical_torque=tr["physical"])
