"""The paper's satellite figures for ``cosim plot`` (registered as the ``cosim.figures`` entry point).

For result files that have ``attitude.phi``, ``attitude.omega`` and ``orbit.R`` (3 components each):
``satellite-euler.png`` (Euler angles, deg, range-limited as the listings print them; figs. 8-10),
``satellite-rates.png`` (body rates, deg/s; figs. 11-13) and ``satellite-altitude.png``
(|R|/1000 - 6367.65 km; figs. 14-19: pass the RF-D and RK-U files of all cases for the case-method
overlay of figs. 17-19). Every file is one line on each axis.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from cosim.plot import Result, figure
from subsims.satellite.transforms import altitude_km, limit_angles

SIGNALS = ("attitude.phi", "attitude.omega", "orbit.R")


def is_satellite(result: Result) -> bool:
    return all(s in result.signals and result.signals[s].shape[1] == 3 for s in SIGNALS)


def figures(results: Sequence[Result], out: Path) -> list[Path]:
    """The three figures over every satellite file among ``results``; none if there is none."""
    sat = [r for r in results if is_satellite(r)]
    if not sat:
        return []
    return [
        figure(sat, [np.degrees(limit_angles(r.signals["attitude.phi"])) for r in sat],
               "Euler angles (range-limited output)", ["phi_x (deg)", "phi_y (deg)", "phi_z (deg)"],
               out / "satellite-euler.png", wrap=180.0),
        figure(sat, [np.degrees(r.signals["attitude.omega"]) for r in sat], "Body rates",
               ["omega_x (deg/s)", "omega_y (deg/s)", "omega_z (deg/s)"], out / "satellite-rates.png"),
        figure(sat, [altitude_km(r.signals["orbit.R"]) for r in sat], "Altitude", ["altitude (km)"],
               out / "satellite-altitude.png"),
    ]
