"""The unified (single-integrator) reference of a scenario: ``cosim run <scenario> --method unified``.

A scenario names its reference in ``[unified] function = "package.module:function"`` (optional
``[unified] params = {...}`` are passed on as keyword arguments). The function is called as

    fn(params, stop=..., dt=..., start=..., couplings=[{"to", "from", "transform", "params"}, ...], **params)

with ``params`` = ``{subsim: its [subsims.<name>.params]}`` and ``dt`` = interval / (samples - 1) of
the scenario's default method, and returns ``{"t": (n,), subsim: {output port: (n, size)}}`` sampled
every ``dt``. The samples are written in the SAME columns as a coupled run (``ResultWriter``, one
interval per convergence interval, ``stages`` = 1 in the diagnostics), so results compare column by
column. The run covers whole intervals past ``stop``, as the coupler does.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from cosim import interrupt
from cosim.coupler.relaxation import Interval, RunSummary, interval_end, sample_times
from cosim.importing import import_object
from cosim.outputs import OutputLock, reserve_output
from cosim.results import ResultWriter, diag_path, output_units
from cosim.runner import RunReport, default_output, open_session, output_signals
from cosim.scenario import Scenario, ScenarioError


def resolve_function(scenario: Scenario) -> Any:
    name = scenario.unified.function if scenario.unified else None
    if not name:
        raise ScenarioError(f"{scenario.path}: no [unified] function: this scenario has no unified reference")
    try:
        fn = import_object(name, "unified function", scenario.search_path)
    except ValueError as exc:
        raise ScenarioError(f"{scenario.path}: [unified.function] {exc}") from None
    if not callable(fn):
        raise ScenarioError(f"{scenario.path}: [unified.function] {name!r} is not callable")
    return fn


def run_unified(scenario: Scenario, stop: float | None = None, output: Path | None = None,
                overwrite: bool = True, on_interval: Callable[[Interval], None] | None = None) -> RunReport:
    """Run the scenario's unified reference and write it like a coupled run. Raises ScenarioError, and
    OutputError before computing anything if ``output`` cannot be written (or exists and not ``overwrite``)."""
    resolve_function(scenario)
    output = Path(output) if output is not None else default_output(scenario, "unified")
    lock = reserve_output(output, overwrite)
    try:
        return _run_unified(scenario, stop, output, lock, on_interval)
    finally:
        lock.release()


def _run_unified(scenario: Scenario, stop: float | None, output: Path, lock: OutputLock,
                 on_interval: Callable[[Interval], None] | None) -> RunReport:
    fn = resolve_function(scenario)
    extra = dict(scenario.unified.params)
    settings = scenario.settings_for()
    stop = scenario.stop if stop is None else float(stop)
    H, m = settings.interval, settings.samples
    dt = H / (m - 1)
    start = scenario.start
    n_int = max(1, math.ceil((stop - start) / H - 1e-9))  # whole intervals past stop, as Coordinator.run
    n_steps = n_int * (m - 1)
    couplings = [c.as_table() for c in scenario.couplings]
    params = {name: dict(spec.params) for name, spec in scenario.subsims.items()}

    session = open_session(scenario, inprocess=True)  # the coupled run's output ports and sizes
    try:
        signals = output_signals(scenario, session.descriptions)
        units = output_units(session.descriptions)
    finally:
        session.close()

    started = time.perf_counter()
    try:
        # stop half a step short of the last sample: the function rounds up to whole steps
        result = fn(params, stop=start + (n_steps - 0.5) * dt, dt=dt, start=start, couplings=couplings, **extra)
    except (ValueError, TypeError, KeyError) as exc:
        raise ScenarioError(f"{scenario.path}: [unified.function] {scenario.unified.function}: {exc}") from None
    wall = time.perf_counter() - started

    columns: dict[str, np.ndarray] = {}
    for ref, size in signals:
        try:
            v = np.asarray(result[ref.subsim][ref.port], dtype=np.float64)
        except (KeyError, TypeError):
            raise ScenarioError(f"{scenario.path}: [unified.function] {scenario.unified.function} returned no "
                                f"{ref} (the coupled run writes it)") from None
        v = v.reshape(v.shape[0], -1) if v.ndim else v
        if v.shape != (n_steps + 1, size):
            raise ScenarioError(f"{scenario.path}: [unified.function] {ref} has shape {v.shape}, "
                                f"expected ({n_steps + 1}, {size})")
        columns[str(ref)] = v

    summary = RunSummary(start)
    writer = ResultWriter(output, signals, units, lock=lock)
    try:
        for k in range(n_int):
            t = sample_times(start + k * H, interval_end(start, start + k * H, H), m)  # the coupler's own grid
            rows = slice(k * (m - 1), (k + 1) * (m - 1) + 1)
            outputs: dict[str, dict[str, np.ndarray]] = {}
            for ref, _ in signals:
                outputs.setdefault(ref.subsim, {})[ref.port] = columns[str(ref)][rows]
            interval = Interval(t, outputs, {}, 1, {}, wall_time=wall / n_int)
            try:
                writer.write(interval)
            except interrupt.Interrupted:  # a signal held back while the interval was written: it is in the files
                if on_interval is not None and writer.holds(interval):
                    on_interval(interval)
                raise
            summary.add(interval)
            if on_interval is not None:
                on_interval(interval)
        interrupt.finished()  # every interval is in: a signal now would only cut the files' closing short
    finally:
        writer.close()
    summary.wall_time = wall
    return RunReport("unified", summary, output, diag_path(output), list(scenario.subsims), [],
                     {"dt": dt, "function": scenario.unified.function})
