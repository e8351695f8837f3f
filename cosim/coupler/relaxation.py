"""Recursive feedback (waveform relaxation) over one convergence interval, sans-IO.

Centralized (RF-C, Jacobi, spec §4): every stage runs all subsims concurrently on inputs made
from the previous stage's outputs; the check compares all outputs of successive stages.
Distributed (RF-D, Gauss-Seidel, spec §5): subsims run in order; forward couplings use the
current stage's outputs at once; only the feedback couplings (sources at or after the target
in the order) are iterated, and only they are checked.

Both check from stage 1 on, as the paper's listings do (stage 0 runs on the first guess).
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from cosim.coupler.convergence import Check, Tolerance, check
from cosim.coupler.couplings import Coupling, SignalRef, check_couplings, derive_order, feedback_weight, is_feedback
from cosim.coupler.first_guess import POLICIES, first_guess
from cosim.handles import Description, IntervalResult, SubsimHandle
from cosim.signals import SCHEMES

METHODS = ("centralized", "distributed")


@dataclass(frozen=True)
class Settings:
    method: str = "centralized"
    interval: float = 1.0  # H
    samples: int = 5  # ndp, both ends included
    first_guess: str = "extrapolate"
    interp: str = "linear"
    tol: Tolerance = Tolerance(1e-12, 1e-12)
    tolerances: Mapping[str, Tolerance] = field(default_factory=dict)  # per signal "subsim.port"
    max_stages: int = 100
    order: Sequence[str] | None = None  # distributed only; derived when None
    max_halvings: int = 0

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {', '.join(METHODS)}, got {self.method!r}")
        if not (isinstance(self.interval, (int, float)) and np.isfinite(self.interval) and self.interval > 0):
            raise ValueError(f"interval must be a positive number, got {self.interval!r}")
        if not isinstance(self.samples, int) or self.samples < 2:
            raise ValueError(f"samples must be an integer >= 2, got {self.samples!r}")
        if self.first_guess not in POLICIES:
            raise ValueError(f"first_guess must be one of {', '.join(POLICIES)}, got {self.first_guess!r}")
        if self.interp not in SCHEMES:
            raise ValueError(f"interp must be one of {', '.join(SCHEMES)}, got {self.interp!r}")
        if not isinstance(self.max_stages, int) or self.max_stages < 2:
            raise ValueError(f"max_stages must be an integer >= 2, got {self.max_stages!r}")
        if not isinstance(self.max_halvings, int) or self.max_halvings < 0:
            raise ValueError(f"max_halvings must be an integer >= 0, got {self.max_halvings!r}")


@dataclass
class Interval:
    """One converged (committed) interval, as handed to the output writer."""

    t: np.ndarray
    outputs: dict[str, dict[str, np.ndarray]]  # subsim -> port -> (n, size)
    inputs: dict[str, np.ndarray]  # "subsim.port" -> (n, size), as used by the last stage
    stages: int
    residuals: dict[str, list[float]]  # checked signal -> largest residual per checked stage
    wall_time: float = 0.0
    halvings: int = 0

    @property
    def largest_residual(self) -> float:
        return max((r[-1] for r in self.residuals.values() if r), default=0.0)


@dataclass
class RunSummary:
    t_start: float
    t_end: float = 0.0
    intervals: int = 0
    stages: Counter = field(default_factory=Counter)  # stages per interval -> count
    halved: int = 0
    wall_time: float = 0.0

    def add(self, interval: Interval) -> None:
        self.t_end = float(interval.t[-1])
        self.intervals += 1
        self.stages[interval.stages] += 1
        self.halved += interval.halvings > 0
        self.wall_time += interval.wall_time


class NotConverged(RuntimeError):
    def __init__(self, t0: float, t1: float, stages: int, failing: list[str], residuals: dict[str, list[float]]):
        lines = [f"interval [{t0!r}, {t1!r}] did not converge in {stages} stages; failing signals:"]
        for name in failing:
            hist = ", ".join(f"{r:.3e}" for r in residuals[name][-8:])
            lines.append(f"  {name}: residual by stage (last 8) [{hist}]")
        super().__init__("\n".join(lines))
        self.t0, self.t1, self.stages, self.failing, self.residuals = t0, t1, stages, failing, residuals


class Coordinator:
    """Couples subsims through handles only; the same object drives in-process and remote runs."""

    def __init__(
        self,
        handles: Mapping[str, SubsimHandle],
        couplings: Sequence[Coupling],
        settings: Settings,
        descriptions: Mapping[str, Description] | None = None,
        on_stage: Callable[[int, dict[str, dict[str, np.ndarray]]], None] | None = None,
    ) -> None:
        """``on_stage(stage, outputs)`` sees every stage's outputs (diagnostics, the exact tests)."""
        self.on_stage = on_stage
        self.handles = dict(handles)
        self.couplings = list(couplings)
        self.settings = settings
        desc = dict(descriptions) if descriptions else {n: h.describe() for n, h in self.handles.items()}
        self.inputs = {n: d.inputs for n, d in desc.items()}
        self.outputs = {n: d.outputs for n, d in desc.items()}
        check_couplings(self.couplings, self.inputs, self.outputs)
        self.sizes = {SignalRef(s, p): port.size for s, ports in self.inputs.items() for p, port in ports.items()}
        names = list(self.handles)
        if settings.order is not None:
            if sorted(settings.order) != sorted(names):
                raise ValueError(f"order {list(settings.order)} must name every subsim exactly once: {names}")
            self.order = list(settings.order)
        else:
            self.order = derive_order(names, self.couplings, self.sizes) if settings.method == "distributed" else names
        rank = {n: i for i, n in enumerate(self.order)}
        self.feedback = [c for c in self.couplings if is_feedback(c, rank)]
        self.forward = [c for c in self.couplings if not is_feedback(c, rank)]
        self.feedback_signals = feedback_weight(self.order, self.couplings, self.sizes)
        self._previous: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        # converged subsims whose commit has not been sent: it rides on their next run_interval
        self._uncommitted: set[str] = set()

    # --- a run --------------------------------------------------------------------------------

    def run(
        self, t_start: float, t_stop: float, on_interval: Callable[[Interval], None] | None = None
    ) -> RunSummary:
        """Advance whole intervals from ``t_start`` (every subsim's committed time) past ``t_stop``.

        Interval ends sit on the grid ``t_start + k H`` (no drift over long runs) unless a
        halving moved the start off it.
        """
        H = self.settings.interval
        summary = RunSummary(t_start)
        t = t_start
        while t < t_stop - 1e-9 * H:
            k = round((t - t_start) / H)
            t1 = t_start + (k + 1) * H if t_start + k * H == t else t + H
            interval = self._advance(t, t1)
            summary.add(interval)
            if on_interval is not None:
                on_interval(interval)
            t = float(interval.t[-1])
        self.commit_pending()
        return summary

    # --- one interval -------------------------------------------------------------------------

    def sample_times(self, t0: float, t1: float) -> np.ndarray:
        n = self.settings.samples
        t = t0 + (t1 - t0) * (np.arange(n) / (n - 1))
        t[0], t[-1] = t0, t1
        return t

    def advance(self, t0: float, t1: float) -> Interval:
        """Converge the interval [t0, t1], commit every subsim, and return what converged.

        With ``max_halvings`` > 0 a non-converging interval is retried on its first half, then
        its first quarter, ...; the returned interval then ends before ``t1``.
        """
        interval = self._advance(t0, t1)
        self.commit_pending()
        return interval

    def commit_pending(self) -> None:
        """Commit, in one concurrent round trip, the converged trials still waiting for a next interval."""
        names = [n for n in self.handles if n in self._uncommitted]
        for wait in [self.handles[n].start_commit() for n in names]:
            wait()
        self._uncommitted.clear()

    def _advance(self, t0: float, t1: float) -> Interval:
        """:meth:`advance`, but each subsim's commit rides on its first request of the next interval."""
        started = time.perf_counter()
        for halvings in range(self.settings.max_halvings + 1):
            times = self.sample_times(t0, t0 + (t1 - t0) / 2**halvings)
            try:
                interval = self._converge(times)
                break
            except NotConverged:
                for h in self.handles.values():
                    h.rollback()
                if halvings == self.settings.max_halvings:
                    raise
        self._uncommitted = set(self.handles)
        self._previous = {k: (interval.t, v) for k, v in interval.inputs.items()}
        interval.wall_time, interval.halvings = time.perf_counter() - started, halvings
        return interval

    def _converge(self, times: np.ndarray) -> Interval:
        if self.settings.method == "centralized":
            return self._centralized(times)
        return self._distributed(times)

    def _collect(self, pending: Mapping[str, Callable[[], IntervalResult]]) -> dict[str, dict[str, np.ndarray]]:
        """Wait for every pending run (none is left in flight); a subsim that answered has committed
        its previous interval if asked to. Raises the first error after all have answered."""
        outputs, error = {}, None
        for name, wait in pending.items():
            try:
                outputs[name] = wait().outputs
            except Exception as exc:
                error = error or exc
                continue
            self._uncommitted.discard(name)
        if error is not None:
            raise error
        return outputs

    def _guess(self, times: np.ndarray, couplings: Sequence[Coupling]) -> dict[str, np.ndarray]:
        sizes = {str(c.target): self.sizes[c.target] for c in couplings}
        return first_guess(self.settings.first_guess, times, sizes, self._previous, self.settings.interp)

    def _subsim_inputs(self, name: str, signals: Mapping[str, np.ndarray], n: int) -> dict[str, np.ndarray]:
        """Inputs of ``name`` from coupled ``signals``; uncoupled inputs are zero."""
        return {p: signals[k] if (k := f"{name}.{p}") in signals else np.zeros((n, port.size))
                for p, port in self.inputs[name].items()}

    def _evaluate(self, c: Coupling, outputs: Mapping, n: int) -> np.ndarray:
        return c.evaluate(outputs, self.sizes[c.target], n)

    def _check(self, new: dict, old: dict, history: dict[str, list[float]]) -> Check:
        """The convergence check of one stage; appends each signal's largest residual to ``history``."""
        result = check(new, old, self.settings.tol, self.settings.tolerances)
        for k, r in result.residuals.items():
            history.setdefault(k, []).append(float(r.max(initial=0.0)))
        return result

    def _centralized(self, times: np.ndarray) -> Interval:
        n, s = times.size, self.settings
        inputs = self._guess(times, self.couplings)
        history: dict[str, list[float]] = {}
        previous: dict[str, np.ndarray] | None = None
        for stage in range(s.max_stages):
            pending = {
                name: h.start_run_interval(times, self._subsim_inputs(name, inputs, n), s.interp,
                                           commit=name in self._uncommitted)
                for name, h in self.handles.items()
            }
            outputs = self._collect(pending)
            if self.on_stage is not None:
                self.on_stage(stage, outputs)
            flat = {f"{name}.{p}": v for name, ports in outputs.items() for p, v in ports.items()}
            if previous is not None:
                result = self._check(flat, previous, history)
                if result.converged:
                    return Interval(times, outputs, inputs, stage + 1, history)
            previous = flat
            inputs = {str(c.target): self._evaluate(c, outputs, n) for c in self.couplings}
        raise NotConverged(float(times[0]), float(times[-1]), s.max_stages, result.failing, history)

    def _distributed(self, times: np.ndarray) -> Interval:
        n, s = times.size, self.settings
        fed_back = self._guess(times, self.feedback)
        history: dict[str, list[float]] = {}
        for stage in range(s.max_stages):
            inputs = dict(fed_back)
            outputs: dict[str, dict[str, np.ndarray]] = {}
            for name in self.order:
                for c in self.forward:
                    if c.target.subsim == name:
                        inputs[str(c.target)] = self._evaluate(c, outputs, n)
                outputs.update(self._collect({name: self.handles[name].start_run_interval(
                    times, self._subsim_inputs(name, inputs, n), s.interp, commit=name in self._uncommitted)}))
            if self.on_stage is not None:
                self.on_stage(stage, outputs)
            new = {str(c.target): self._evaluate(c, outputs, n) for c in self.feedback}
            if not self.feedback:  # nothing to iterate: feed-forward chain is exact in one stage
                return Interval(times, outputs, inputs, stage + 1, history)
            if stage > 0:
                result = self._check(new, fed_back, history)
                if result.converged:
                    return Interval(times, outputs, inputs, stage + 1, history)
            fed_back = new
        raise NotConverged(float(times[0]), float(times[-1]), s.max_stages, result.failing, history)
