"""``cosim plot``: result files (.csv/.npz) to PNG, several files (methods, cases) overlaid on one axis.

* Every output signal ``<subsim>.<port>`` gets ``<out>/<subsim>.<port>.png``: one panel per component
  against time, one line per file that has it (``--signals`` selects columns or prefixes).
* Unless ``--signals`` is given, every installed figure provider adds its own figures: a function
  ``figures(results, out) -> list[Path]`` registered in the ``cosim.figures`` entry-point group, which
  draws with :func:`figure` and returns nothing for files that are not its own. This project registers
  the paper's satellite figures (``subsims/satellite/plots.py``).

Lines are labelled with the file names; every axis with its unit (the subsims' port declarations,
stored with the results: an NPZ's ``units``, a CSV's ``<name>.meta.json``). PNGs appear atomically
(written under a temporary name, then renamed). Long runs are drawn through a min/max envelope per pixel
column, so 600,000 samples plot fast and oscillations do not alias away. matplotlib is an optional
dependency (``pip install 'cosim[plot]'``).
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from collections.abc import Callable, Sequence
from importlib.metadata import entry_points
from pathlib import Path

import numpy as np

from cosim.outputs import OutputError, atomic_write
from cosim.results import read_results, read_units

FIGURES_GROUP = "cosim.figures"
SIDECARS = (".diag.csv", ".meta.json", ".lock", ".partial")  # files a run writes beside its results
MAX_POINTS = 4000  # envelope buckets per line
_COLUMN = re.compile(r"^(?P<signal>[^\[]+)\[(?P<index>\d+)\]$")


class PlotError(RuntimeError):
    pass


def _pyplot():
    try:
        import matplotlib
    except ImportError:
        raise PlotError("cosim plot needs matplotlib, an optional dependency: pip install 'cosim[plot]'") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


class Result:
    """One result file: its label, time column and signals {"subsim.port": (n, size)}."""

    def __init__(self, path: Path) -> None:
        if not path.exists():
            raise PlotError(f"result file {path} not found")
        if path.suffix.lower() in {".toml", ".ssp", ".fmu", ".json"}:  # (NumPy's parse error said nothing useful)
            raise PlotError(f"{path}: a {path.suffix} file, not results: plot the .csv or .npz a run wrote (cosim run "
                            "prints where, after 'results:')")
        try:
            columns, data = read_results(path)
        except (ValueError, OSError, KeyError, StopIteration) as exc:
            raise PlotError(f"{path}: not a cosim result file ({exc})") from None
        if not columns or columns[0] != "time":
            raise PlotError(f"{path}: not a cosim result file (first column must be 'time')")
        if data.ndim != 2 or data.shape[0] == 0 or data.shape[1] != len(columns):
            raise PlotError(f"{path}: no samples (the run stopped before its first interval was committed)")
        if data.shape[0] == 1:
            raise PlotError(f"{path}: only one sample (t = {data[0, 0]:g}): nothing to plot against time")
        self.path, self.label = path, path.stem
        self.t = data[:, 0]
        parts: dict[str, list[tuple[int, int]]] = {}
        for j, name in enumerate(columns[1:], start=1):
            m = _COLUMN.match(name)
            signal, index = (m["signal"], int(m["index"])) if m else (name, 0)
            parts.setdefault(signal, []).append((index, j))
        self.signals = {s: data[:, [j for _, j in sorted(cols)]] for s, cols in parts.items()}
        units = read_units(path)
        # unit of each signal (None: the file does not say; "" dimensionless)
        self.units: dict[str, str | None] = {s: units.get(columns[cols[0][1]]) for s, cols in parts.items()}

    def window(self, t0: float | None, t1: float | None) -> None:
        """Keep the samples with t0 <= t <= t1 (None: open end)."""
        keep = np.ones(self.t.size, dtype=bool)
        if t0 is not None:
            keep &= self.t >= t0
        if t1 is not None:
            keep &= self.t <= t1
        self.t = self.t[keep]
        self.signals = {s: v[keep] for s, v in self.signals.items()}


def envelope(t: np.ndarray, y: np.ndarray, points: int = MAX_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """(t, y) reduced to the min and max of each of ``points`` buckets, in time order."""
    n = t.size
    if n <= 2 * points:
        return t, y
    size = math.ceil(n / points)
    pad = (-n) % size
    tb = np.concatenate([t, np.full(pad, t[-1])]).reshape(-1, size)
    yb = np.concatenate([y, np.full(pad, y[-1])]).reshape(-1, size)
    lo, hi = yb.argmin(axis=1), yb.argmax(axis=1)
    first, second = np.minimum(lo, hi), np.maximum(lo, hi)
    rows = np.arange(tb.shape[0])
    tt = np.column_stack([tb[rows, first], tb[rows, second]]).ravel()
    yy = np.column_stack([yb[rows, first], yb[rows, second]]).ravel()
    return tt, yy


def break_wraps(t: np.ndarray, y: np.ndarray, jump: float) -> tuple[np.ndarray, np.ndarray]:
    """Insert a gap where y jumps by more than ``jump`` (angles wrapping at +-180 deg)."""
    at = np.flatnonzero(np.abs(np.diff(y)) > jump) + 1
    return np.insert(t, at, np.nan), np.insert(y, at, np.nan)


def figure(results: Sequence[Result], series: list[np.ndarray], title: str, ylabels: Sequence[str],
           path: Path, wrap: float | None = None) -> Path:
    """Write one PNG: a panel per column of the series (``ylabels``), a line per result, gaps where a
    line jumps by more than ``wrap``; ``series[i]`` is (samples of ``results[i]``, columns)."""
    plt = _pyplot()
    rows = len(ylabels)
    fig, axes = plt.subplots(rows, 1, sharex=True, figsize=(10, 2.4 * rows + 0.8), squeeze=False)
    for k, ax in enumerate(axes[:, 0]):
        for r, y in zip(results, series):
            t, v = envelope(r.t, y[:, k])
            if wrap is not None:
                t, v = break_wraps(t, v, wrap)
            ax.plot(t, v, label=r.label, linewidth=0.8)
        ax.set_ylabel(ylabels[k])
        ax.grid(True, alpha=0.3)
        ax.ticklabel_format(axis="y", useOffset=False)
    axes[0, 0].set_title(title)
    axes[0, 0].legend(fontsize="small", loc="best")
    axes[-1, 0].set_xlabel("time (s)")
    fig.tight_layout()
    try:
        atomic_write(path, lambda f: fig.savefig(f, dpi=110, format="png"))
    except OutputError as exc:
        raise PlotError(str(exc)) from None
    finally:
        plt.close(fig)
    return path


def unit_label(results: Sequence[Result], signal: str) -> str:
    """`` (m)`` for the signal's unit in the files that state one, `` (-)`` if dimensionless, ``""`` if
    none does (files from an older cosim)."""
    units = list(dict.fromkeys(u for r in results if (u := r.units.get(signal)) is not None))
    if not units:
        return ""
    return " (" + " | ".join(u or "-" for u in units) + ")"


def figure_providers() -> list[tuple[str, Callable[[Sequence[Result], Path], list[Path]]]]:
    """(name, figures function) of every installed ``cosim.figures`` entry point that loads, by name."""
    providers = []
    for entry in sorted(entry_points(group=FIGURES_GROUP), key=lambda e: e.name):
        try:
            providers.append((entry.name, entry.load()))
        except Exception as exc:  # a broken provider must not hide the generic plots: say so, go on
            print(f"cosim plot: skipping figure provider {entry.name!r} ({entry.value}), which failed to load: "
                  f"{exc}", file=sys.stderr)
    return providers


def _selected(signal: str, size: int, wanted: Sequence[str] | None) -> list[int]:
    """Components of ``signal`` picked by ``--signals`` (a column like ``x[1]`` or a prefix like ``x``)."""
    if not wanted:
        return list(range(size))
    picked = []
    for i in range(size):
        column = f"{signal}[{i}]"
        if any(column == w or column.startswith(w) for w in wanted):
            picked.append(i)
    return picked


def plot_signals(results: Sequence[Result], out: Path, wanted: Sequence[str] | None = None) -> list[Path]:
    """Generic: one PNG per output signal, one panel per (selected) component, every file overlaid."""
    order: dict[str, int] = {}
    for r in results:
        for s, v in r.signals.items():
            order[s] = max(order.get(s, 0), v.shape[1])
    written = []
    for signal, size in order.items():
        comps = _selected(signal, size, wanted)
        if not comps:
            continue
        having = [r for r in results if signal in r.signals and r.signals[signal].shape[1] == size]
        name = re.sub(r"[^A-Za-z0-9_.-]", "_", signal)
        unit = unit_label(having, signal)
        written.append(figure(having, [r.signals[signal][:, comps] for r in having], signal,
                              [f"{signal}[{i}]{unit}" for i in comps], out / f"{name}.png"))
    return written


def plot_files(paths: Sequence[Path], out: Path, signals: Sequence[str] | None = None,
               window: Sequence[float | None] | None = None) -> list[Path]:
    """Plot result files into ``out``; returns the PNGs written. Raises PlotError.

    ``window`` = (t0, t1) restricts the time axis (e.g. (40000, 60000) for the paper's figs. 8-16).
    """
    if window is not None:
        t0 = float("-inf") if window[0] is None else window[0]
        t1 = float("inf") if window[1] is None else window[1]
        if not t0 < t1:  # also false with a NaN
            raise PlotError(f"--window {window[0]} {window[1]}: give a time span T0 < T1")
    _pyplot()
    results = [Result(Path(p)) for p in paths]
    if window is not None:
        for r in results:
            r.window(*window)
    empty = [r.label for r in results if r.t.size == 0]
    if empty:
        raise PlotError(f"no samples in {', '.join(empty)}{' inside the window' if window is not None else ''}")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise PlotError(f"cannot create the plot directory {out} ({exc.strerror}): choose another --out") from None
    written = []
    if not signals:
        for _, figures in figure_providers():
            written += figures(results, out)
    written += plot_signals(results, out, signals)
    if not written:
        raise PlotError(f"nothing matches --signals {' '.join(signals or [])}")
    return written


DIAGNOSTICS = (("stages", "stages"), ("length_s", "interval length (s)"), ("error", "error / interval_tol"),
               ("halvings", "tries rolled back"), ("largest_residual", "largest residual"),
               ("wall_time_s", "wall time (s)"))  # columns drawn (the rolled-back tries: where the wall time went)


class _Diagnostics:
    """A diagnostics file (``x.csv.diag.csv``) as :func:`figure` takes a result: each interval at its end time."""

    def __init__(self, path: Path) -> None:
        try:
            header, values = read_results(path)  # (a CSV of numbers under a header, as the results are)
        except (OSError, ValueError, StopIteration) as exc:
            raise PlotError(f"{path} is not a diagnostics file cosim wrote ({exc})") from None
        self.label, self.columns = path.name, dict(zip(header, values.T))
        if "t1" not in self.columns:
            raise PlotError(f"{path} is not a diagnostics file cosim wrote (no t1 column)")
        self.t = self.columns["t1"]


def plot_diagnostics(paths: Sequence[Path], out: Path) -> list[Path]:
    """``<out>/diagnostics.png``: each interval's stages, length, error estimate, residual and wall time against
    its end time, a line per file (what an automatic interval did, or where a run took more stages)."""
    diags = [_Diagnostics(Path(p)) for p in paths]
    shown = [(key, label) for key, label in DIAGNOSTICS if all(key in d.columns for d in diags)]
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise PlotError(f"cannot create the plot directory {out} ({exc.strerror}): choose another --out") from None
    series = [np.column_stack([d.columns[key] for key, _ in shown]) for d in diags]
    return [figure(diags, series, "diagnostics per interval", [label for _, label in shown],  # type: ignore[arg-type]
                   out / "diagnostics.png")]


def plot_command(args: argparse.Namespace) -> int:
    """``cosim plot RESULTS... [--out DIR] [--signals ...]`` (and ``args.window`` = (t0, t1) if present). Given
    diagnostics files only, their columns."""
    if args.results and all(p.name.endswith(".diag.csv") for p in args.results):
        try:
            written = plot_diagnostics(args.results, args.out)
        except PlotError as exc:
            print(f"cosim plot: {exc}", file=sys.stderr)
            return 2
        print("\n".join(map(str, written)))
        return 0
    paths = [p for p in args.results if not p.name.endswith(SIDECARS)]  # `cosim plot results/*` works
    beside = [p for p in args.results if p not in paths]
    owners = [p.with_name(p.name[:-len(next(s for s in SIDECARS if p.name.endswith(s)))]) for p in beside]
    for p, owner in zip(beside, owners):
        print(f"cosim plot: skipping {p}, which belongs to the results {owner} (a diagnostics file given alone is "
              "plotted as such)", file=sys.stderr)
    try:
        if not paths:
            raise PlotError(f"no result files given (only files beside them): cosim plot {' '.join(map(str, owners))}")
        written = plot_files(paths, args.out, args.signals, getattr(args, "window", None))
    except (PlotError, OutputError) as exc:
        print(f"cosim plot: {exc}", file=sys.stderr)
        return 2
    for path in written:
        print(path)
    return 0
