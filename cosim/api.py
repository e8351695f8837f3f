"""Run scenarios from scripts and notebooks: ``cosim.run(...)`` returns the time series as numpy arrays.

    import cosim
    r = cosim.run("scenarios/satellite/case1.toml", method="distributed", stop=400)
    r.t                      # (n,) sample times
    r["orbit.r"]             # (n, 3): an output, "subsim.port"
    r.diagnostics["stages"]  # (intervals,) stages each interval took

It is the run ``cosim run`` makes (same processes, same coupler, same bits), without the
command line: the result file is written only when ``output`` is given. See docs/api.md.
"""

from __future__ import annotations

import copyreg
import io
import os
import pickle
import signal
import tempfile
import types
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from cosim import interrupt
from cosim.console import say
from cosim.coupler.relaxation import Interval, RunSummary
from cosim.outputs import OutputError
from cosim.preflight import UsageError, check_run_arguments
from cosim.protocol.keys import check_name
from cosim.results import DIAG_COLUMNS, read_results
from cosim.runner import run_scenario
from cosim.scenario import Scenario, ScenarioError, load, parse
from cosim.unified import run_unified


def _read_only(table: dict) -> types.MappingProxyType:
    return types.MappingProxyType(table)


def _result(pickled: bytes) -> Result:
    return Result(**pickle.loads(pickled))


@dataclass(repr=False)
class Result:
    """The time series of one run and its per-interval diagnostics. ``r["subsim.port"]`` is a signal; ``in``,
    ``len`` and iteration go over the signals' names."""

    scenario: Scenario
    method: str
    t: np.ndarray  # (n,) every sample time, each interval's last sample being the next one's first
    signals: dict[str, np.ndarray]  # "subsim.port" -> (n, size)
    diagnostics: dict[str, np.ndarray]  # DIAG_COLUMNS -> (intervals,)
    summary: RunSummary
    order: list[str] = field(default_factory=list)
    feedback: list[str] = field(default_factory=list)
    output: Path | None = None  # the result file, when one was asked for

    def __getitem__(self, signal: str) -> np.ndarray:
        try:
            return self.signals[signal]
        except KeyError:
            raise KeyError(f"no signal {signal!r}; signals: {', '.join(self.signals)}") from None

    def __contains__(self, signal: object) -> bool:
        return signal in self.signals

    def __iter__(self) -> Iterator[str]:  # (without it, `in` and a for loop asked for r[0], r[1], ...)
        return iter(self.signals)

    def __len__(self) -> int:
        return len(self.signals)

    def __reduce__(self) -> tuple[Any, tuple[bytes]]:
        """Its scenario's tables are read-only views (MappingProxyType), which pickle cannot copy: a Result could not
        come back from a multiprocessing worker (an API probe). They are pickled as the dicts they show, by a pickler
        of its own (copyreg's table, for every pickle in the process, is left as it is)."""
        buffer = io.BytesIO()
        pickler = pickle.Pickler(buffer, pickle.HIGHEST_PROTOCOL)
        pickler.dispatch_table = {**copyreg.dispatch_table,
                                  types.MappingProxyType: lambda view: (_read_only, (dict(view),))}
        pickler.dump({f.name: getattr(self, f.name) for f in fields(self)})
        return _result, (buffer.getvalue(),)

    def __repr__(self) -> str:  # (the dataclass's printed every array: 10,000 characters)
        span = f"t = {self.t[0]:g} to {self.t[-1]:g} s, {self.t.size} samples" if self.t.size else "no samples"
        signals = ", ".join(f"{k} {v.shape[1:] or ''}".rstrip() for k, v in self.signals.items())
        return (f"<Result of {self.scenario.name!r}, {self.method}: {span}, {len(self.diagnostics.get('stages', ()))} "
                f"intervals; signals {signals or 'none'}>")

    def column(self, name: str) -> np.ndarray:
        """One column as the result file names it: ``"time"`` or ``"subsim.port[i]"``."""
        if name == "time":
            return self.t
        signal_name, bracket, index = name.rpartition("[")
        if not bracket or not index.endswith("]") or not (index[:-1].isascii() and index[:-1].isdigit()):
            raise KeyError(f"column {name!r}: name one as 'subsim.port[i]' (or 'time'); r[{name!r}] is the whole "
                           "signal")
        signal, i = self[signal_name], int(index[:-1])
        if i >= signal.shape[1]:  # (a bare numpy IndexError named no column)
            raise KeyError(f"column {name!r}: {signal_name} has {signal.shape[1]} columns, [0] to "
                           f"[{signal.shape[1] - 1}]")
        return signal[:, i]


DIAG_KINDS = (int, float, float, int, float, float, int, int, float, float)  # of DIAG_COLUMNS: counts are integers


class _Collect:
    """Gathers the committed intervals as the result writer does: each interval but its last sample."""

    def __init__(self) -> None:
        self.t: list[np.ndarray] = []
        self.signals: dict[str, list[np.ndarray]] = {}
        self.diag: list[tuple] = []
        self.last: Interval | None = None

    def __call__(self, interval: Interval) -> None:
        self.t.append(interval.t[:-1])
        for name, ports in interval.outputs.items():
            for port, v in ports.items():
                self.signals.setdefault(f"{name}.{port}", []).append(v[:-1])
        t0, t1 = float(interval.t[0]), float(interval.t[-1])
        self.diag.append((len(self.diag) + 1, t0, t1, interval.stages, interval.largest_residual, interval.wall_time,
                          interval.halvings, interval.restarts, t1 - t0, interval.error))
        self.last = interval

    def arrays(self) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]]:
        if self.last is None:
            return np.empty(0), {}, {c: np.empty(0) for c in DIAG_COLUMNS}
        last = self.last
        t = np.concatenate([*self.t, last.t[-1:]])
        signals = {k: np.concatenate([*v, last.outputs[k.split(".", 1)[0]][k.split(".", 1)[1]][-1:]])
                   for k, v in self.signals.items()}
        columns = list(zip(*self.diag))
        diag = {c: np.array(col, dtype=kind) for c, col, kind in zip(DIAG_COLUMNS, columns, DIAG_KINDS, strict=True)}
        return t, signals, diag


def run(
    scenario: str | Path | Scenario,
    method: str | None = None,
    stop: float | None = None,
    *,
    params: Mapping[str, Mapping[str, Any]] | None = None,
    output: str | Path | None = None,
    inprocess: bool = False,
    listen: str | None = None,
    run_id: str | None = None,
    attach_wait: float = 300.0,
    progress: bool = False,
    restarts: int | None = None,
    timeout: float | None = None,
    resume: bool = False,
    on_interval: Callable[[Interval], None] | None = None,
    log: Callable[[str], None] = say,
) -> Result:
    """Run a scenario as ``cosim run`` does and return its time series.

    ``scenario``: a file or a loaded :class:`~cosim.scenario.Scenario`. ``method``: ``"centralized"``,
    ``"distributed"`` or ``"unified"`` (default: the scenario's). ``stop``: overrides the scenario's.
    ``params``: ``{subsim: {parameter: value}}`` merged over the scenario's (a variant without a new
    file). ``output``: also write the result file (.csv or .npz) and its diagnostics. The other
    arguments are those of ``cosim run``. ``resume``: go on with the interrupted run that wrote ``output``
    (required then) from its latest resume point; the result is then the whole run, read back from its
    file. ``on_interval``: called with each committed :class:`~cosim.coupler.relaxation.Interval` as the
    run goes (an exception it raises stops the run). ``log``: where the run's lines go (default: stderr).
    Raises ``ScenarioError``, ``SubsimError``, ``NotConverged``, ``TransformError``, ``OutputError``.
    A Ctrl-C (SIGINT) stops the run as the command's does, raising ``KeyboardInterrupt`` once every subsim is
    stopped and every result file finished; a second one does not cut that short.
    """
    if not isinstance(scenario, (str, os.PathLike, Scenario)):  # (a dict met pathlib's TypeError)
        raise ScenarioError(f"scenario must be a file path or a loaded Scenario, got {type(scenario).__name__}: "
                            "write the tables to a .toml file, or build one with cosim.scenario.parse(tables, path)")
    sc = scenario if isinstance(scenario, Scenario) else load(scenario)
    if params is not None:
        sc = _with_params(sc, params)
    method = method or sc.default_method
    try:  # the command's checks of its options
        check_run_arguments(sc.start, stop, timeout, attach_wait, restarts, output, options=False)
    except UsageError as exc:
        raise ScenarioError(str(exc)) from None
    if run_id is not None:
        try:
            check_name(run_id, "run id")
        except ValueError as exc:  # refused over the bus anyway; in-process too, as the command refuses it
            raise ScenarioError(str(exc)) from None
    if resume and output is None:
        raise ScenarioError("resume=True goes on with the results of an interrupted run: give its output= file")
    if resume and method == "unified":
        raise ScenarioError("resume=True continues coupled runs (centralized, distributed), not unified ones")
    if method == "unified":
        with tempfile.TemporaryDirectory(prefix="cosim-run-") as scratch:  # it reads back what it wrote
            path = Path(output) if output is not None else Path(scratch) / "results.csv"
            return _from_file(sc, run_unified(sc, stop=stop, output=path, on_interval=on_interval), output)
    collect = _Collect()

    def each(interval: Interval) -> None:
        collect(interval)
        if on_interval is not None:
            on_interval(interval)

    try:
        with interrupt.handling((signal.SIGINT,)):  # the script keeps its own SIGTERM and SIGHUP
            report = run_scenario(sc, method=method, stop=stop, output=None if output is None else Path(output),
                                  inprocess=inprocess, listen=listen, progress=progress, log=log, on_interval=each,
                                  run_id=run_id, attach_wait=attach_wait, restarts=restarts, timeout=timeout,
                                  resume=resume, record=output is not None)
    except (ScenarioError, OutputError) as exc:  # the command's words, for its options: this caller's arguments
        if len(exc.args) == 1 and isinstance(exc.args[0], str):
            said = in_api_words(exc.args[0])
            if any(f"[subsims.{name}.params]" in said for name in params or ()):  # (it blamed the file: a probe)
                said += " (the params= of this call are merged over the file's)"
            exc.args = (said,)
        raise
    if resume:  # the intervals before the resume point are in the file only
        return _from_file(sc, report, output)
    t, signals, diag = collect.arrays()
    # in the scenario's order of subsims, as the result file's columns (in the run's order, which depends on the
    # method, two runs' signals misaligned when stacked: a probe)
    declared = list(sc.subsims)
    signals = dict(sorted(signals.items(), key=lambda item: declared.index(item[0].partition(".")[0])))
    return Result(sc, report.method, t, signals, diag, report.summary, report.order, report.feedback,
                  Path(output) if output is not None else None)


# what the command's messages say of its options, as cosim.run's arguments (a script was told to pass --overwrite)
API_WORDS = (("(--overwrite instead of --resume)", "(resume=False)"), ("with --overwrite", "with resume=False"),
             ("(--overwrite;", "(resume=False;"), ("pass --overwrite to replace it, or choose another --output",
                                                   "choose another output="),
             ("--resume", "resume=True"), ("--overwrite", "resume=False"), ("--output", "output="),
             ("--timeout", "timeout="), ("--attach-wait", "attach_wait="), ("--listen", "listen="),
             ("--stop", "stop="), ("--inprocess", "inprocess=True"), ("--method", "method="))


def in_api_words(text: str) -> str:
    for command, argument in API_WORDS:
        text = text.replace(command, argument)
    return text


def _with_params(sc: Scenario, params: Mapping[str, Mapping[str, Any]]) -> Scenario:
    raw = {**sc.raw, "subsims": {k: dict(v) for k, v in sc.raw["subsims"].items()}}
    if not isinstance(params, Mapping):
        raise ScenarioError(f"params must be {{subsim: {{parameter: value}}}}, got {type(params).__name__}")
    for name, values in params.items():
        if not isinstance(values, Mapping):
            raise ScenarioError(f"params[{name!r}] must be {{parameter: value}}, got {type(values).__name__}")
        if name not in raw["subsims"]:
            raise ScenarioError(f"{sc.path}: params for unknown subsim {name!r}; subsims: {', '.join(sc.subsims)}")
        raw["subsims"][name]["params"] = {**raw["subsims"][name].get("params", {}), **values}
    return parse(raw, sc.path)


def _from_file(sc: Scenario, report: Any, output: str | Path | None) -> Result:
    """A unified or resumed run's file, read back (CSV floats are written with repr: exact)."""
    columns, data = read_results(report.output)
    signals: dict[str, list[np.ndarray]] = {}
    for i, name in enumerate(columns[1:], start=1):
        signals.setdefault(name.rpartition("[")[0], []).append(data[:, i])
    _, diag_rows = read_results(report.diagnostics)
    diag = {c: diag_rows[:, j].astype(kind) for j, (c, kind) in enumerate(zip(DIAG_COLUMNS, DIAG_KINDS, strict=True))}
    return Result(sc, report.method, data[:, 0], {k: np.column_stack(v) for k, v in signals.items()}, diag,
                  report.summary, report.order, report.feedback, Path(output) if output is not None else None)
