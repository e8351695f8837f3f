"""Plots of flexbody co-simulation results: base attitude, base rate, tip deflection, control torque.

    python -m subsims.flexbody.plots RESULTS [RESULTS ...] --out DIR

RESULTS are ``cosim run`` result files (.csv or .npz) of the scenarios in scenarios/flexbody/; several files are
overlaid (e.g. distributed vs centralized, flexible vs rigid). Signals are found by port name, whatever the subsim
is called: the attitude from ``euler123`` (flexbody, mode F) or ``phi`` (the rigid attitude subsim, z-y-x angles),
the rate from ``omega``, the deflections from ``q`` (particle-major; the boom tips are particles 2 and 4 of the
example vehicle, x components q[3] and q[9]), the torques from ``tau0``, ``tau_flex_split``, ``tau_flex``.
Writes attitude.png, rate.png, tip.png and torque.png (those whose signals are present) and prints their paths.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from functools import partial
from pathlib import Path

import numpy as np

from cosim.outputs import atomic_write
from cosim.results import read_results

AXES = ("x", "y", "z")


def find(columns: Sequence[str], port: str) -> dict[str, list[int]]:
    """{"subsim.port": [column indices]} of every signal whose port is ``port``."""
    out: dict[str, list[int]] = {}
    for i, c in enumerate(columns):
        name, _, _ = c.partition("[")
        if name.partition(".")[2] == port:
            out.setdefault(name, []).append(i)
    return out


def load(path: Path) -> tuple[list[str], np.ndarray]:
    columns, data = read_results(path)
    if data.shape[0] == 0:
        raise ValueError(f"{path}: no samples")
    return columns, data


def _active(data: np.ndarray, idx: list[int]) -> list[int]:
    """The components that move by more than 1e-6 of the largest motion (all of them if none moves)."""
    spans = np.array([np.ptp(data[:, i]) for i in idx])
    moving = [k for k, span in enumerate(spans) if span > 1e-6 * spans.max() > 0.0]
    return moving or list(range(len(idx)))


def plot_files(paths: Sequence[Path], out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [(Path(p), *load(Path(p))) for p in paths]
    out.mkdir(parents=True, exist_ok=True)
    figures = {
        "attitude": ("base attitude", "angle (deg)", (("euler123", "theta_{}", np.degrees), ("phi", "phi_{}",
                                                                                           np.degrees))),
        "rate": ("base angular rate", "omega (deg/s)", (("omega", "omega_{}", np.degrees),)),
        "tip": ("boom tip deflection (particles 2 and 4, body x)", "q (ft)", (("q", None, None),)),
        "torque": ("torques: control at O_g; flexible, about c0", "torque (ft lbf)",
                   (("tau0", "tau0_{}", None), ("tau_flex_split", "tau~_{}", None), ("tau_flex", "tau_flex_{}", None))),
    }
    written = []
    for key, (title, ylabel, ports) in figures.items():
        fig, ax = plt.subplots(figsize=(9, 4.5))
        drawn = 0
        for path, columns, data in runs:
            t = data[:, 0]
            label_run = path.stem
            for port, fmt, conv in ports:
                for name, idx in find(columns, port).items():
                    if port == "q":  # boom tips, x components (particles 2 and 4)
                        picks = [(3, "tip A q_2x"), (9, "tip B q_4x")] if len(idx) >= 12 else []
                        for i, lab in picks:
                            ax.plot(t, data[:, idx[i]], label=f"{label_run}: {lab}")
                            drawn += 1
                        continue
                    for k in _active(data, idx):
                        y = data[:, idx[k]]
                        ax.plot(t, conv(y) if conv else y, label=f"{label_run}: {name} {fmt.format(AXES[k])}")
                        drawn += 1
        if drawn:
            ax.set(title=title, xlabel="t (s)", ylabel=ylabel)
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=8)
            fig.tight_layout()
            path = out / f"{key}.png"
            atomic_write(path, partial(fig.savefig, dpi=110, format="png"))  # whole or not at all
            written.append(path)
        plt.close(fig)
    return written


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m subsims.flexbody.plots", description=__doc__.split("\n")[0])
    p.add_argument("results", nargs="+", type=Path, help="result files (.csv/.npz) of cosim run")
    p.add_argument("--out", type=Path, default=Path("plots"), help="directory for the PNGs (default: plots)")
    args = p.parse_args(argv)
    try:
        written = plot_files(args.results, args.out)
    except (OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for path in written:
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
