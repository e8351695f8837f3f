"""Plots of lagrange_pair results: trajectories, attitude, joint force (and loads, and the built-in comparison).

    python -m subsims.lagrange_pair.plots RESULTS... --out DIR [--reference]

RESULTS are result files of ``cosim run`` (.csv or .npz) from a scenario with a ``LagrangePair``
subsim (any subsim name: it is found by its ``pos_B`` column). Several files are overlaid. It writes:

- ``trajectory.png``: side view (altitude over north) of both CMs with the tether drawn every 5 s,
  altitude, speed and east drift over time;
- ``attitude.png``: 3-2-1 Euler angles (unwrapped) and body rates of both bodies;
- ``joint_force.png``: the swivel force (Lagrange multiplier, C axes) and the joint violation;
- ``loads.png``: the aero loads that crossed the coupling, if the file has an aero subsim's
  ``force_B`` ... ``moment_C`` columns;
- ``coupled_vs_builtin.png`` with ``--reference``: the difference from the pair with built-in aero
  (``model.run_reference`` with the default deck, sampled as the file), on a log scale.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from cosim.outputs import atomic_write
from cosim.results import read_results

DEG = 180.0 / np.pi


class Result:
    """One result file, with the pair's (and the aero subsim's) signals by port name."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.label = path.stem
        columns, data = read_results(path)
        self.t = data[:, 0]
        pair = [c[: -len(".pos_B[0]")] for c in columns if c.endswith(".pos_B[0]")]
        if not pair:
            raise ValueError(f"{path}: no '<subsim>.pos_B[0]' column: not a lagrange_pair result")
        self.pair = pair[0]
        loads = [c[: -len(".force_C[0]")] for c in columns if c.endswith(".force_C[0]") and not c.startswith(self.pair)]
        self.aero = loads[0] if loads else None
        self._cols = {c: i for i, c in enumerate(columns)}
        self._data = data

    def get(self, port: str, subsim: str | None = None) -> np.ndarray:
        prefix = f"{subsim or self.pair}.{port}["
        idx = [i for c, i in self._cols.items() if c.startswith(prefix)]
        if not idx:
            raise KeyError(f"{self.path}: no column {prefix}...]")
        return self._data[:, idx]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


STYLES = ["-", "--", ":", "-."]


def _grid_and_legend(ax, which: str = "major") -> None:
    for a in ax.flat:
        a.grid(True, which=which, alpha=0.3)
        a.legend(fontsize=7)


def _save(plt, fig, title: str, path: Path) -> Path:
    """The figure's title, and the PNG written to ``path``."""
    fig.suptitle(title)
    fig.tight_layout()
    atomic_write(path, lambda f: fig.savefig(f, dpi=110, format="png"))  # whole or not at all
    plt.close(fig)
    return path


def _min_span(ax, span: float) -> None:
    """Keep an axis from zooming into round-off: show at least +-span/2 around the data."""
    lo, hi = ax.get_ylim()
    if hi - lo < span:
        mid = 0.5 * (lo + hi) if abs(0.5 * (lo + hi)) > span else 0.0
        ax.set_ylim(mid - span / 2, mid + span / 2)


def _window_max(t: np.ndarray, v: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Largest value in each window of ``width`` seconds (envelope of round-off-level signals)."""
    edges = np.arange(t[0], t[-1] + width, width)
    k = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, len(edges) - 1)
    out = np.zeros(len(edges))
    np.maximum.at(out, k, v)
    return np.append(edges, edges[-1] + width)[: len(edges) + 1], np.append(out, out[-1])


def _positive(v: np.ndarray) -> np.ndarray:
    """Zeros as NaN so a log axis is not stretched down to them."""
    return np.where(v > 0.0, v, np.nan)


def plot_trajectory(results: Sequence[Result], out: Path) -> Path:
    plt = _plt()
    fig, ax = plt.subplots(2, 2, figsize=(12, 9))
    for k, r in enumerate(results):
        ls = STYLES[k % len(STYLES)]
        pb, pc = r.get("pos_B"), r.get("pos_C")
        ax[0, 0].plot(pb[:, 0], -pb[:, 2], "C0" + ls, label=f"SRB CM ({r.label})")
        ax[0, 0].plot(pc[:, 0], -pc[:, 2], "C1" + ls, label=f"drogue CM ({r.label})")
        if k == 0:
            for i in np.flatnonzero(np.isclose(np.mod(r.t + 1e-9, 5.0), 0.0, atol=1e-6)):
                ax[0, 0].plot([pb[i, 0], pc[i, 0]], [-pb[i, 2], -pc[i, 2]], "k-", lw=0.8, alpha=0.6)
                ax[0, 0].annotate(f"{r.t[i]:g} s", (pb[i, 0], -pb[i, 2]), fontsize=7, xytext=(4, -8),
                                  textcoords="offset points")
        ax[0, 1].plot(r.t, -pb[:, 2], "C0" + ls, label=f"SRB ({r.label})")
        ax[0, 1].plot(r.t, -pc[:, 2], "C1" + ls, label=f"drogue ({r.label})")
        ax[1, 0].plot(r.t, np.linalg.norm(r.get("vel_B_I"), axis=1), "C0" + ls, label=f"SRB ({r.label})")
        ax[1, 0].plot(r.t, np.linalg.norm(r.get("vel_C_I"), axis=1), "C1" + ls, label=f"drogue ({r.label})")
        ax[1, 1].plot(r.t, pb[:, 1], "C0" + ls, label=f"SRB ({r.label})")
        ax[1, 1].plot(r.t, pc[:, 1], "C1" + ls, label=f"drogue ({r.label})")
    ax[0, 0].set(xlabel="north [ft]", ylabel="altitude [ft]", title="side view (swivel line every 5 s)")
    ax[0, 1].set(xlabel="t [s]", ylabel="altitude [ft]", title="altitude")
    ax[1, 0].set(xlabel="t [s]", ylabel="speed [ft/s]", title="inertial speed")
    ax[1, 1].set(xlabel="t [s]", ylabel="east [ft]", title="east drift")
    _grid_and_legend(ax)
    return _save(plt, fig, "SRB + drogue: trajectories (I frame: north, east, down)", out / "trajectory.png")


def plot_attitude(results: Sequence[Result], out: Path) -> Path:
    plt = _plt()
    fig, ax = plt.subplots(3, 2, figsize=(12, 9), sharex=True)
    names = ("psi (yaw)", "theta (pitch)", "phi (roll)")
    rates = ("p (roll rate)", "q (pitch rate)", "r (yaw rate)")
    for k, r in enumerate(results):
        ls = STYLES[k % len(STYLES)]
        for body, color in (("B", "C0"), ("C", "C1")):
            e = np.unwrap(r.get(f"euler_{body}"), axis=0) * DEG
            w = r.get(f"omega_{body}") * DEG
            who = "SRB" if body == "B" else "drogue"
            for j in range(3):
                ax[j, 0].plot(r.t, e[:, j], color + ls, label=f"{who} ({r.label})")
                ax[j, 1].plot(r.t, w[:, j], color + ls, label=f"{who} ({r.label})")
    for j in range(3):
        ax[j, 0].set(ylabel=f"{names[j]} [deg]")
        ax[j, 1].set(ylabel=f"{rates[j]} [deg/s]")
        _min_span(ax[j, 0], 2.0)
        _min_span(ax[j, 1], 2.0)
        for a in ax[j]:
            a.grid(True, alpha=0.3)
    ax[0, 0].legend(fontsize=7)
    ax[0, 1].legend(fontsize=7)
    ax[2, 0].set(xlabel="t [s]")
    ax[2, 1].set(xlabel="t [s]")
    ax[0, 0].set_title("3-2-1 Euler angles relative to I (unwrapped)")
    ax[0, 1].set_title("angular velocity, body axes")
    title = "SRB + drogue: attitude (psi and phi are ill-conditioned as theta nears +-90 deg)"
    return _save(plt, fig, title, out / "attitude.png")


def plot_joint_force(results: Sequence[Result], out: Path) -> Path:
    plt = _plt()
    fig, ax = plt.subplots(2, 2, figsize=(12, 8), sharex=True)
    for k, r in enumerate(results):
        ls = STYLES[k % len(STYLES)]
        lam = r.get("multiplier")
        ax[0, 0].plot(r.t, np.linalg.norm(lam, axis=1) / 1e3, "k" + ls, label=f"|lambda| ({r.label})")
        ax[0, 0].plot(r.t, -lam[:, 0] / 1e3, "C0" + ls, label=f"-lambda_x ({r.label})")
        ax[0, 1].plot(r.t, lam[:, 1], "C2" + ls, label=f"lambda_y ({r.label})")
        ax[0, 1].plot(r.t, lam[:, 2], "C3" + ls, label=f"lambda_z ({r.label})")
        for a, port, color in ((ax[1, 0], "violation_pos", "C0"), (ax[1, 1], "violation_vel", "C1")):
            te, env = _window_max(r.t, np.linalg.norm(r.get(port), axis=1), 0.5)
            a.step(te, _positive(env), color + ls, where="post", label=f"{r.label}: max {env.max():.1e}")
    for a in ax[1]:
        a.set_yscale("log")
        a.axhline(1e-9, color="k", lw=0.8, ls=":", label="1e-9 (spec P5)")
    ax[0, 0].set(ylabel="[kip]", title="swivel force on the SRB (C axes): magnitude and axial")
    ax[0, 1].set(ylabel="[lbf]", title="swivel force, lateral components (C axes)")
    ax[1, 0].set(xlabel="t [s]", ylabel="[ft]", title="joint violation |attach B - attach C|, max per 0.5 s")
    ax[1, 1].set(xlabel="t [s]", ylabel="[ft/s]", title="joint velocity violation |A Omega| (eq. 12), max per 0.5 s")
    _grid_and_legend(ax)
    return _save(plt, fig, "SRB + drogue: joint force (Lagrange multiplier) and constraint", out / "joint_force.png")


def plot_loads(results: Sequence[Result], out: Path) -> Path | None:
    with_aero = [r for r in results if r.aero is not None]
    if not with_aero:
        return None
    plt = _plt()
    fig, ax = plt.subplots(2, 2, figsize=(12, 8), sharex=True)
    for k, r in enumerate(with_aero):
        ls = STYLES[k % len(STYLES)]
        for a, port, unit in ((ax[0, 0], "force_B", "lbf"), (ax[0, 1], "moment_B", "lbf*ft"),
                              (ax[1, 0], "force_C", "lbf"), (ax[1, 1], "moment_C", "lbf*ft")):
            v = r.get(port, r.aero)
            for j, comp in enumerate("xyz"):
                a.plot(r.t, v[:, j], f"C{j}" + ls, label=f"{comp} ({r.label})")
            a.set(title=f"{r.aero}.{port} (body axes)", ylabel=f"[{unit}]")
    _grid_and_legend(ax)
    ax[1, 0].set(xlabel="t [s]")
    ax[1, 1].set(xlabel="t [s]")
    return _save(plt, fig, "aerodynamic loads passed over the coupling", out / "loads.png")


def plot_reference(results: Sequence[Result], out: Path) -> Path:
    from subsims.lagrange_pair.model import run_reference

    plt = _plt()
    fig, ax = plt.subplots(1, 3, figsize=(14, 4.5))
    for k, r in enumerate(results):
        ls = STYLES[k % len(STYLES)]
        spacing = float(np.median(np.diff(r.t)))
        times, ref = run_reference(float(r.t[-1]), sample_interval=spacing, t_start=float(r.t[0]))
        if times.shape != r.t.shape or not np.allclose(times, r.t, rtol=0, atol=1e-9):
            print(f"{r.path}: samples are not evenly spaced; skipped in the comparison", file=sys.stderr)
            continue
        for a, port in ((ax[0], "pos_B"), (ax[0], "pos_C"), (ax[1], "dcm_B"), (ax[1], "dcm_C"),
                        (ax[2], "multiplier")):
            d = np.abs(r.get(port) - ref[port]).max(axis=1)
            a.semilogy(r.t, _positive(d), ls, label=f"{port} ({r.label}), max {d.max():.1e}")
    ax[0].set(title="position difference, max over components", ylabel="[ft]")
    ax[1].set(title="DCM difference, max over elements", ylabel="[-]")
    ax[2].set(title="multiplier difference, max over components", ylabel="[lbf]")
    for a in ax:
        a.set(xlabel="t [s]")
    _grid_and_legend(ax, which="both")
    title = "coupled run minus the pair with built-in aerodynamics (model.run_reference, default deck)"
    return _save(plt, fig, title, out / "coupled_vs_builtin.png")


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m subsims.lagrange_pair.plots", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("results", nargs="+", type=Path, help="result files (.csv/.npz) of a lagrange_pair scenario")
    p.add_argument("--out", type=Path, default=Path("plots/lagrange_pair"), help="directory for the PNGs")
    p.add_argument("--reference", action="store_true",
                   help="also plot the difference from the pair with built-in aero (default deck)")
    args = p.parse_args(argv)
    try:
        results = [Result(path) for path in args.results]
    except (OSError, ValueError) as exc:
        print(f"plots: {exc}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    written = [plot_trajectory(results, args.out), plot_attitude(results, args.out),
               plot_joint_force(results, args.out), plot_loads(results, args.out)]
    if args.reference:
        written.append(plot_reference(results, args.out))
    for path in written:
        if path is not None:
            print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
