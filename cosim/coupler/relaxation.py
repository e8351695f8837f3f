"""Recursive feedback (waveform relaxation), sans-IO: a state machine that says what to run next.

Centralized (RF-C, Jacobi, spec §4): every stage runs all subsims concurrently on inputs made
from the previous stage's outputs; the check compares all outputs of successive stages.
Distributed (RF-D, Gauss-Seidel, spec §5): subsims run in order; forward couplings use the
current stage's outputs at once; only the feedback couplings (sources at or after the target
in the order) are iterated, and only they are checked. Consecutive subsims that read nothing of
each other in a stage (a level of the plan) run in one ``Run``, concurrently: the same inputs, so
the same results, in fewer sequential round trips. With ``speculate``, from stage 1 on a level also runs
beside the level before it, on that level's outputs of the previous stage; it is kept when those outputs come
back bit for bit the same (its inputs were then exactly the in-order ones: the same results, one round trip
less), else run again in order.
Both check from stage 1 on, as the paper's listings do (stage 0 runs on the first guess). Neither runs a subsim
again on inputs that are, bit for bit, those of its latest run in the interval: ``advance`` is pure and the
subsim commits its latest trial, so its outputs are reused (RF-C on the paper's satellite: orbit at stage 1, whose
input, aero's force on the zero first guess, is zero again: 14 requests an interval instead of 15).

The machine does no I/O and reads no clock. It emits actions and takes results (the h11 pattern)::

    steps = Relaxation(plan, settings).run(0.0, 10.0)
    action = steps.send(None)
    while not isinstance(action, Done):
        if isinstance(action, Run):       # run these subsims on these inputs; answer their outputs
            action = steps.send({name: run(name, action.times, ins) for name, ins in action.inputs.items()})
        else:                             # Rollback: discard every trial; Commit: commit and record
            action = steps.send(None)

A driver (``cosim.driver``) performs the actions over in-process or remote handles.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from collections.abc import Generator, Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

from cosim.coupler.convergence import Check, Tolerance, check
from cosim.coupler.couplings import Coupling
from cosim.coupler.first_guess import POLICIES, first_guess
from cosim.coupler.interval_control import (
    IntervalControl,
    error_ratio,
    magnitudes,
    next_length,
    order,
    retry_length,
)
from cosim.coupler.plan import Plan
from cosim.signals import SCHEMES, check_scheme

METHODS = ("centralized", "distributed")
RETRY_MISSED = 32  # interval tries after a speculation missed before it is tried again at that level and stage
CEILING_PATIENCE = 16  # interval = "auto": intervals after a try that did not converge that stay below its length
CEILING_MARGIN = 0.75  # ... below it by this factor at least

Outputs = dict[str, dict[str, np.ndarray]]  # subsim -> port -> samples (n, size)
Evaluations = tuple[tuple[str, Coupling, int], ...]  # couplings with their targets' "subsim.port" and width
Latest = dict[str, tuple[dict[str, np.ndarray], dict[str, np.ndarray]]]  # subsim -> inputs, outputs of its latest run


def _whole(value: object, least: int) -> bool:
    """An integer (a bool is not one here, though Python says so) of at least ``least``."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= least


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
    auto: IntervalControl | None = None  # interval = "auto": sized per interval (interval is the first one)
    speculate: bool = False  # distributed only: run a level beside the one before it when that one repeats its outputs

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {', '.join(METHODS)}, got {self.method!r}")
        interval = self.interval
        if isinstance(interval, bool) or not isinstance(interval, (int, float)) or not np.isfinite(interval) \
                or interval <= 0:
            raise ValueError(f"interval must be a positive number, got {self.interval!r}")
        if not _whole(self.samples, 2):
            raise ValueError(f"samples must be an integer >= 2, got {self.samples!r}")
        if self.first_guess not in POLICIES:
            raise ValueError(f"first_guess must be one of {', '.join(POLICIES)}, got {self.first_guess!r}")
        if self.interp not in SCHEMES:
            raise ValueError(f"interp must be one of {', '.join(SCHEMES)}, got {self.interp!r}")
        check_scheme(self.interp, self.samples)
        if not isinstance(self.tol, Tolerance):  # a bare number would fail only at the first check, deep inside
            raise ValueError(f"tol must be a Tolerance(rel, abs), got {self.tol!r}")
        bad = next(((k, v) for k, v in dict(self.tolerances).items() if not isinstance(v, Tolerance)), None)
        if bad is not None:
            raise ValueError(f"tolerances must map signal names to Tolerance(rel, abs); {bad[0]!r} maps to {bad[1]!r}")
        if not _whole(self.max_stages, 2):
            raise ValueError(f"max_stages must be an integer >= 2, got {self.max_stages!r}")
        if not _whole(self.max_halvings, 0):
            raise ValueError(f"max_halvings must be an integer >= 0, got {self.max_halvings!r}")
        if not isinstance(self.speculate, bool):
            raise ValueError(f"speculate must be true or false, got {self.speculate!r}")
        if self.auto is not None:
            if not isinstance(self.auto, IntervalControl):
                raise ValueError(f"auto must be an IntervalControl or None, got {self.auto!r}")
            if self.samples < 3:
                raise ValueError(f"samples must be >= 3 with interval = 'auto', got {self.samples}")


@dataclass
class Interval:
    """One converged (committed) interval, as handed to the output writer."""

    t: np.ndarray
    outputs: Outputs
    inputs: dict[str, np.ndarray]  # "subsim.port" -> (n, size), as used by the last stage
    stages: int
    residuals: dict[str, list[float]]  # checked signal -> largest residual per checked stage
    wall_time: float = 0.0  # set by the driver (the machine reads no clock)
    halvings: int = 0  # times this interval was rolled back and retried shorter
    restarts: int = 0  # subsims the driver replaced during this interval
    error: float = 0.0  # interval = "auto": the error ratio (estimate / interval_tol; <= 1 accepted), else 0
    converged_last: tuple[str, ...] = ()  # the checked signals that failed the check before the last: the slowest

    @property
    def length(self) -> float:
        return float(self.t[-1] - self.t[0])

    @property
    def largest_residual(self) -> float:
        return max((r[-1] for r in self.residuals.values() if r), default=0.0)


@dataclass(frozen=True)
class ResumePoint:
    """What the machine carries from one committed interval to the next: with every subsim's committed state
    there, enough to go on with a run from ``t`` exactly as it would have gone on (``Relaxation.run(...,
    resume=...)``): the last interval's converged inputs (the extrapolating first guess), and with
    ``interval = "auto"`` the next interval's length and the inputs' largest magnitudes so far."""

    t: float
    length: float | None
    previous: dict[str, tuple[np.ndarray, np.ndarray]]
    magnitudes: dict[str, np.ndarray]
    ceiling: float = math.inf  # interval = "auto": lengths below it only, for ``patience`` more intervals
    patience: int = 0


@dataclass
class RunSummary:
    t_start: float
    t_end: float = 0.0
    intervals: int = 0
    stages: Counter = field(default_factory=Counter)  # stages per interval -> count
    halved: int = 0
    wall_time: float = 0.0
    rejected: int = 0  # rolled-back tries of intervals that were then retried shorter
    shortest: float = math.inf  # interval lengths, s
    longest: float = 0.0
    round_trips: int = 0  # Run actions, rejected tries included (the subsims of one Run answer concurrently)
    requests: int = 0  # subsim runs, rejected tries included
    round_trip_median: float | None = None  # s from a Run's requests to its last reply (recent ones; by the driver)
    round_trip_max: float | None = None  # s, the longest of them (a subsim that stalled, not a slow link)
    unconverged: int = 0  # of the rejected tries: not converged (diverged, stalled), not over interval_tol
    rejected_stages: int = 0  # stages the rejected tries ran
    over_tol: int = 0  # interval = "auto": intervals accepted at interval_min above interval_tol
    converged_last: Counter = field(default_factory=Counter)  # checked signal -> intervals it was the last to pass in

    def add(self, interval: Interval) -> None:
        self.t_end = float(interval.t[-1])
        self.intervals += 1
        self.stages[interval.stages] += 1
        self.halved += interval.halvings > 0
        self.rejected += interval.halvings
        self.wall_time += interval.wall_time
        self.shortest = min(self.shortest, interval.length)
        self.longest = max(self.longest, interval.length)
        self.converged_last.update(interval.converged_last)


class NotConverged(RuntimeError):
    def __init__(self, t0: float, t1: float, stages: int, failing: list[str], residuals: dict[str, list[float]],
                 values: Mapping[str, np.ndarray] | None = None, cycled: int = 0):
        """``values``: the failing signals' last samples, to tell a residual that is their round-off. ``cycled``:
        stopped before max_stages, the signals back to those of that many stages before (:func:`_repeated`)."""
        why = (f" (its signals came back bit for bit to those of {cycled} stages before: more stages would only go "
               "round again)") if cycled else ""
        lines = [f"interval [{t0!r}, {t1!r}] did not converge in {stages} stages{why}; failing signals:"]
        for name in failing:
            hist = ", ".join(f"{r:.3e}" for r in residuals[name][-8:])
            lines.append(f"  {name}: residual by stage (last {min(8, len(residuals[name]))}) [{hist}]")
        shorter = ("a shorter [coupling] interval (interval = \"auto\" keeps it short only where needed; "
                   "max_halvings > 0 retries a failed one shorter, every interval from its full length first)")
        trends = {_trend(residuals[n]) for n in failing}
        roundoff = _roundoff(failing, residuals, values, cycled) if trends == {"stalled"} or cycled else None
        hovering = None if roundoff is not None else _hovering(failing, residuals, values)
        if roundoff is not None:  # a shorter interval would stall at the same level: the tolerances ask too much
            name, level, size = roundoff
            lines.append(f"  to try: {_res_above(level)}: {name}'s residual stopped falling at {level:.2e}, the "
                         f"round-off of values near {size:.3g} (a relative {level / size:.1e}), which no interval or "
                         "stage count removes")
        elif hovering is not None:  # noise up and down by decades: its window trends say growing or falling at random
            name, level, size = hovering
            lines.append(f"  to try: {_res_above(level)}, or tighter tolerances in the models (an ODE solver's or an "
                         f"FMU's rtol): {name}'s residual goes up and down near {level:.1e} (a relative "
                         f"{level / size:.0e} of its values) with no trend over its last {HOVER_STAGES} stages, the "
                         "models' own error, which no interval or stage count removes")
        elif cycled:  # bit for bit round again, not in its last bits: a switch (a probe: the advice above failed)
            lines.append("  to try: a switch in the loop (a relay, a thermostat, a saturation or a quantizer whose "
                         "input depends, within one sample interval, on what it switches) has no consistent answer, "
                         "which a shorter interval does not give it: have the model that switches, or the one it "
                         "drives, read its input at the start of each sample interval (u(times[k]) for the whole "
                         "step, as a held signal gives it; docs/tutorial.md, section 7)")
        elif "growing" in trends:
            lines.append(f"  to try: {shorter}: the iteration diverges (the residuals grow), the coupling too strong "
                         "for an interval this long")
        elif "stalled" in trends:  # more stages will not help that signal
            lines.append(f"  to try: {shorter}, or tolerances no tighter than the models' round-off")
        elif "falling" in trends:
            lines.append(f"  to try: more [coupling] max_stages (the residuals still fall), or {shorter}")
        else:
            lines.append(f"  to try: more [coupling] max_stages, or {shorter}")
        super().__init__("\n".join(lines))
        self.t0, self.t1, self.stages, self.failing, self.residuals = t0, t1, stages, failing, residuals


def _res_above(level: float) -> str:
    """The absolute tolerance to try for a residual stuck at ``level``: the next power of ten above 1.5 times it."""
    return (f"res = {10.0 ** math.ceil(math.log10(1.5 * level)):.0e} (the absolute tolerance, in [coupling] or per "
            "signal in [tolerances])")


def _size(values: np.ndarray) -> float:
    """How large a signal's samples (n, width) are: the smallest channel's largest magnitude."""
    return float(np.min(np.max(np.abs(values), axis=0), initial=np.inf))


ROUNDOFF = 1e-11  # a flat residual this small against its signal's values is taken for their round-off (45,000
# ulps: what a gain makes of a settling input's last bits; a real iteration at that level still moves)


def _roundoff(failing: Sequence[str], residuals: Mapping[str, list[float]], values: Mapping[str, np.ndarray] | None,
              cycled: int = 0) -> tuple[str, float, float] | None:
    """(signal, its residual, the size of its values) with the largest residual, when every failing signal's
    residual has stayed flat over its last 8 stages (each window of 4's largest within 10 % of the one before: no
    slow contraction or growth), or went round a cycle of ``cycled`` stages, within ``ROUNDOFF`` of its values'
    size, the smallest channel's (a cycle in the last bits, as a settling signal fed through a gain makes); else
    None."""
    if not values:
        return None
    found = []
    for name in failing:
        r = residuals[name]
        if cycled:  # the iteration went round: its residuals are those of the cycle, for good
            level = max(r[-cycled:]) if r else 0.0
        elif len(r) < 8 or not 0.9 <= max(r[-4:]) / max(max(r[-8:-4]), 1e-300) <= 1.1:
            return None
        else:
            level = max(r[-4:])
        size = _size(values[name])
        if not 0.0 < level <= ROUNDOFF * size:
            return None
        found.append((level, name, size))
    level, name, size = max(found)
    return name, level, size


CYCLE_PERIOD = 4  # stages: an iteration whose checked signals come back bit for bit within this many is a cycle
CYCLE_FROM = 4  # the stage from which they are looked at (an interval that converges in fewer pays nothing for it)


def _repeated(values: Mapping[str, np.ndarray], seen: deque[dict[str, bytes]]) -> int:
    """How many stages back the checked signals ``values`` were already exactly these (0: not within ``seen``, the
    last stages' values, newest last), recording them in ``seen``. The coupling iteration is a function of them (the
    next stage runs on them, from the same committed state): values met again mean a cycle that has failed its check
    at every stage of it, and would go on so to max_stages (a newcomer's heater stood at 1.151e-12 for 100 stages).
    Equal residuals alone are not that: a signal stepping by the same amount each stage still gets somewhere."""
    now = {k: v.tobytes() for k, v in values.items()}
    back = next((len(seen) - i for i, old in enumerate(seen) if old == now), 0)
    seen.append(now)
    return back


HOVER_STAGES = 32  # stages of a residual going up and down with no trend, a small part of the values: noise
HOVER_TREND = 0.3  # decades its upper envelope may rise or fall over them (a contraction of 0.975 a stage falls 0.3)
HOVER_RELATIVE = 1e-6  # (a limit cycle of the coupling itself swings by a larger part of the values)


def _hovering(failing: Sequence[str], residuals: Mapping[str, list[float]], values: Mapping[str, np.ndarray] | None
              ) -> tuple[str, float, float] | None:
    """(signal, its level, the size of its values) with the highest level, when every failing signal's residual
    hovers: over its last ``HOVER_STAGES`` stages the upper envelope (the largest of every 4 stages) rises or falls
    by at most ``HOVER_TREND`` decades while the residuals scatter about their line by more than a tenth of a decade,
    at a level (the largest of its last 8 stages) within ``HOVER_RELATIVE`` of its values' size. That is noise, the
    models' own error (an FMU in model exchange at its solver's rtol): it goes up and down by decades, so the windows
    :func:`_trend` compares say growing or falling by chance. A contraction or growth, swinging or not, moves its
    envelope (measured on model exchange: 0.03-0.18 decades over 32 stages). Else None."""
    found = []
    for name in failing:
        r = residuals.get(name, [])
        last = r[-HOVER_STAGES:]
        envelope = [max(last[i:i + 4]) for i in range(0, len(last), 4)]
        logs = [(i, math.log10(x)) for i, x in enumerate(last) if 0.0 < x < math.inf]
        size = values.get(name) if values else None
        if len(r) < HOVER_STAGES or size is None or not all(0.0 < x < math.inf for x in envelope) or len(logs) < 8:
            return None
        rise = float(np.polyfit(np.arange(len(envelope)), np.log10(envelope), 1)[0]) * (len(envelope) - 1)
        stage, log = np.array(logs).T
        slope, offset = np.polyfit(stage, log, 1)
        scatter = float(np.std(log - (slope * stage + offset)))
        size, level = _size(size), max(r[-8:])
        if abs(rise) > HOVER_TREND or scatter < 0.1 or not 0.0 < level <= HOVER_RELATIVE * size:
            return None
        found.append((level, name, size))
    if not found:
        return None
    level, name, size = max(found)
    return name, level, size


def _trend(r: Sequence[float]) -> str:
    """How a signal's residuals go over the last stages: "growing" (the largest of the last k above 1.2 times that
    of the k before), "falling" (below 0.7 times it), "stalled", or "few" (fewer than 3). Over windows of k = 2 to 4
    stages, not stage by stage: a Jacobi iteration of two subsims changes each signal every other stage (0, 6e5, 0,
    4.8e5), and a converging one may swing on its way down."""
    if len(r) < 3:
        return "few"  # too few stages to tell
    k = min(4, max(2, len(r) // 2))
    recent, before = max(r[-k:]), max(r[-2 * k:-k])
    return "growing" if recent > 1.2 * before else "falling" if recent < 0.7 * before else "stalled"


class TooLong(Exception):
    """Thrown into a running stream by a driver whose run failed in a way a shorter interval cures (``error``, a
    subsim's error): a value the coupling iteration made non-finite (at stage 1 or later), or a model that asked for
    a shorter interval (``too_long``: an FMU that discarded its step). With ``interval = "auto"`` (or
    ``max_halvings``) the try is rolled back and retried shorter, as one that did not converge; otherwise it comes
    back out."""

    def __init__(self, error: BaseException, stage: int) -> None:
        super().__init__(str(error))
        self.error, self.stage = error, stage


DIVERGED = 100.0  # interval = "auto": a residual growing past this many times its first ones gives the try up


def _diverging(history: Mapping[str, list[float]], failing: Sequence[str]) -> bool:
    """Whether a failing signal's residuals grow (:func:`_trend`) and have left their first nonzero one far behind:
    the iteration diverges, and more stages would only reach an overflow (the residuals of round-off noise may rise
    for a stage or two, never by this much). From the first nonzero one: in a Jacobi chain a signal far down it does
    not move for its first stages (residuals 0, 0, 0, then its first change, then falling)."""
    for name in failing:
        r = history.get(name, ())
        first = next((x for x in r if x > 0.0), 0.0)
        if len(r) >= 4 and first > 0.0 and _trend(r) == "growing" and max(r[-2:]) > DIVERGED * first:
            return True
    return False


STALL_WINDOW = 4  # stages a window; interval = "auto": four windows without a trend, none passed, give up


def _stalled(history: Mapping[str, list[float]], failing: Sequence[str], unsettled: Mapping[str, int]) -> bool:
    """Whether a failing signal that has not passed by being small in the last four windows of ``STALL_WINDOW``
    checks (``unsettled``: it failed each, or did not move at all, as a Jacobi pair's signals every other stage) has
    residuals that neither fall nor grow: each window's maximum within 0.7-1.2 times the one before (as
    :func:`_trend`), and the latest within 10 % of the first's, twelve stages before. An iteration bouncing between
    the limits of a saturation, or around a switch, never bit-equal: more stages would not settle it (it ran all
    ``max_stages`` before the try was retried shorter). A signal passing now and then (noise at its tolerance) is not
    judged, nor one contracting by 1 % a stage or more (it fell by over 10 % in those stages). One contracting slower
    that was within about 2.5 times its tolerance would have passed in 100 more stages: it is retried shorter, as
    accurate, at more cost."""
    w = STALL_WINDOW
    for name in failing:
        r = history.get(name, ())
        if unsettled.get(name, 0) < 4 * w or len(r) < 4 * w:
            continue
        m = [max(r[len(r) - (j + 1) * w:len(r) - j * w]) for j in range(4)]  # latest window first
        if all(0.7 * m[j + 1] <= m[j] <= 1.2 * m[j + 1] for j in range(3)) and 0.9 * m[3] <= m[0] <= 1.1 * m[3]:
            return True
    return False


def _hopeless(history: Mapping[str, list[float]], failing: Sequence[str], unsettled: Mapping[str, int]) -> bool:
    """Whether more stages of this try would not converge: it diverges, or it has stalled (``unsettled``: as
    :func:`_count_unsettled` keeps it)."""
    return _diverging(history, failing) or _stalled(history, failing, unsettled)


def _count_unsettled(unsettled: dict[str, int], largest: Mapping[str, float], failing: Sequence[str]) -> None:
    """Update, with one check, each checked signal's count of checks in a row it failed or did not move in (residual
    0); ``largest``: the check's largest residual per signal. One that passed with a residual goes back to 0."""
    now = set(failing)
    for name, residual in largest.items():
        unsettled[name] = unsettled.get(name, 0) + 1 if name in now or residual == 0.0 else 0


class RetryInterval(Exception):
    """Thrown into a running stream by a driver that replaced a subsim: every subsim is back at the
    interval's start (committed state), and the interval runs again from stage 0."""


# --- actions ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Run:
    """Run each subsim in ``inputs`` over ``times`` from its committed state (concurrently when there are
    several); send back ``{subsim: {output port: (n, size)}}`` for exactly these subsims."""

    stage: int
    times: np.ndarray
    inputs: dict[str, dict[str, np.ndarray]]  # subsim -> input port -> (n, size)


@dataclass(frozen=True)
class StageDone:
    """A whole stage has run (emitted only with ``report_stages``): every subsim's outputs of that stage."""

    stage: int
    outputs: Outputs


@dataclass(frozen=True)
class Rollback:
    """The interval ``[t0, t1]`` did not converge: discard every subsim's trial (it is retried shorter)."""

    t0: float
    t1: float


@dataclass(frozen=True)
class Commit:
    """The interval converged: commit every subsim's latest trial and record ``interval``."""

    interval: Interval


@dataclass(frozen=True)
class Done:
    summary: RunSummary


Action = Run | StageDone | Rollback | Commit | Done
Steps = Generator[Action, Outputs | None, RunSummary | None]


def sample_times(t0: float, t1: float, samples: int) -> np.ndarray:
    """``samples`` equally spaced times from ``t0`` to ``t1``, both ends exact."""
    t = t0 + (t1 - t0) * _fractions(samples)
    t[0], t[-1] = t0, t1
    return t


@lru_cache(maxsize=8)
def _fractions(samples: int) -> np.ndarray:
    """``k / (samples - 1)`` for k = 0 .. samples - 1, made once per sample count (read-only: it is shared)."""
    fractions = np.arange(samples) / (samples - 1)
    fractions.flags.writeable = False
    return fractions


def interval_end(t_start: float, t: float, H: float) -> float:
    """The end of the interval starting at ``t``: on the grid ``t_start + k H`` (no drift over long runs)
    unless a halving moved ``t`` off it."""
    k = round((t - t_start) / H)
    return t_start + (k + 1) * H if t_start + k * H == t else t + H


def _fits(ports: Mapping[str, Any], widths: Mapping[str, int], n: int) -> bool:
    """Whether a subsim's answer has exactly its output ports, each a real (n, width) array."""
    if ports.keys() != widths.keys():
        return False
    for p, w in widths.items():
        v = ports[p]
        if type(v) is not np.ndarray or v.shape != (n, w) or v.dtype.kind not in "fiu":
            return False
    return True


def _same_inputs(ins: Mapping[str, np.ndarray], last: Mapping[str, np.ndarray]) -> bool:
    """Whether every input is, bit for bit, that of the latest run (the same array object: no bytes to compare)."""
    for p, v in ins.items():
        old = last[p]
        if v is not old and v.tobytes() != old.tobytes():
            return False
    return True


def _misanswered(got: Any, asked: Mapping[str, Any], n: int, outputs: Mapping[str, Mapping[str, int]]) -> str:
    """What is wrong with a driver's answer to a Run (see Relaxation._received)."""
    head = f"the answer sent to Run (subsims {sorted(asked)}, {n} samples)"
    if not isinstance(got, Mapping):
        return f"{head} must be {{subsim: {{output port: (n, width) array}}}}, got {type(got).__name__}"
    if got.keys() != asked.keys():
        return f"{head} has subsims {sorted(got)}: send exactly those the Run asked for"
    for name in asked:
        ports, widths = got[name], outputs[name]
        if not isinstance(ports, Mapping) or ports.keys() != widths.keys():
            found = sorted(ports) if isinstance(ports, Mapping) else type(ports).__name__
            return f"{head}: {name} has {found}, its outputs are {sorted(widths)}"
        for port, w in widths.items():
            v = ports[port]
            if type(v) is not np.ndarray or v.shape != (n, w) or v.dtype.kind not in "fiu":
                what = f"shape {v.shape}" if type(v) is np.ndarray else type(v).__name__ + (
                    " (an ndarray subclass: send np.asarray of it)" if isinstance(v, np.ndarray) else "")
                if type(v) is np.ndarray and v.shape == (n, w):  # (complex was taken, with a ComplexWarning)
                    what = f"dtype {v.dtype}"
                return f"{head}: {name}.{port} must be a real NumPy array of shape ({n}, {w}), got {what}"
    return head  # (not reached)


class Relaxation:
    """The coupling algorithm for one plan and one set of settings (see the module docstring)."""

    def __init__(self, plan: Plan, settings: Settings, report_stages: bool = False) -> None:
        self.plan, self.settings, self.report_stages = plan, settings, report_stages
        # per subsim, its input ports as (port, "subsim.port", width), built once
        self._ports = {n: [(p, f"{n}.{p}", w) for p, w in plan.inputs[n].items()] for n in plan.names}
        self._sizes = plan.sizes
        # built once: every stage evaluates the couplings
        self._all = self._evaluations(plan.couplings)
        self._feedback = self._evaluations(plan.feedback)
        self._forward_into = {name: self._evaluations(cs) for name, cs in plan.forward_into.items()}
        # per level i: the outputs of level i that level i + 1 reads (what a speculative run of i + 1 must see again)
        self._read_ahead = [self._read_by(plan.levels[i], plan.levels[i + 1]) for i in range(len(plan.levels) - 1)]
        self._tries = 0  # interval tries so far (distributed): when a missed speculation is tried again
        self._missed: dict[tuple[int, int], int] = {}  # (level, stage) -> the try at which it last missed
        self._previous: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # converged inputs of the last interval
        self.round_trips = self.requests = 0  # Run actions and subsim runs emitted so far
        self.unconverged = self.rejected_stages = 0  # tries rolled back as not converged; stages of rolled-back tries
        self._magnitudes: dict[str, np.ndarray] = {}  # interval = "auto": largest |input| per channel so far
        self._next_length: float | None = None  # interval = "auto": the length of the interval after the last one
        self._ceiling: tuple[float, int] = (math.inf, 0)  # interval = "auto": (ceiling, patience), see _auto_run
        self._give_up_early = False  # interval = "auto", above interval_min: a hopeless try is retried shorter at once
        self.resume_point: ResumePoint | None = None  # at the last Commit (None: not a point to go on from)

    def _action(self, stage: int, times: np.ndarray, inputs: dict[str, dict[str, np.ndarray]]) -> Run:
        self.round_trips += 1
        self.requests += len(inputs)
        return Run(stage, times, inputs)

    # --- the action streams -----------------------------------------------------------------------

    def run(self, t_start: float, t_stop: float, resume: ResumePoint | None = None) -> Steps:
        """Whole intervals from ``t_start`` (every subsim's committed time) past ``t_stop``; returns the summary.
        ``resume``: go on with the run that started at ``t_start`` from that point instead (every subsim's
        committed time is ``resume.t``), as it would have gone on."""
        if not (math.isfinite(t_start) and math.isfinite(t_stop)) or t_stop < t_start:  # (it ran nothing, no word)
            raise ValueError(f"run from t = {t_start!r} to t = {t_stop!r}: both finite, the stop not before the start")
        if resume is not None:
            self._previous, self._magnitudes = dict(resume.previous), dict(resume.magnitudes)
        return self._run(t_start, t_stop, resume)

    def interval(self, t0: float, t1: float) -> Steps:
        """One interval ``[t0, t1]`` (shortened by halvings when allowed), ending in one ``Commit``.
        Its length is given: ``interval = "auto"`` sizes the intervals of :meth:`run` only."""
        return self._interval(t0, t1)

    def _run(self, t_start: float, t_stop: float, resume: ResumePoint | None
             ) -> Generator[Action, Outputs | None, RunSummary]:
        if self.settings.auto is not None:
            return (yield from self._auto_run(t_start, t_stop, self.settings.auto, resume))
        H = self.settings.interval
        t = t_start if resume is None else resume.t
        summary = RunSummary(t)
        trips, requests, unconverged, rejected_stages = self.round_trips, self.requests, self.unconverged, \
            self.rejected_stages
        while t < t_stop - 1e-9 * H:
            interval = yield from self._interval(t, interval_end(t_start, t, H))  # on the grid from t_start
            summary.add(interval)
            t = float(interval.t[-1])
        self._tally(summary, trips, requests, unconverged, rejected_stages)
        yield Done(summary)
        return summary

    def _interval(self, t0: float, t1: float) -> Generator[Action, Outputs | None, Interval]:
        s = self.settings
        self._give_up_early = False  # a given length: every try runs to max_stages (an auto run before set it)
        for halvings in range(s.max_halvings + 1):
            times = sample_times(t0, t0 + (t1 - t0) / 2**halvings, s.samples)
            try:
                interval = yield from self._converge(times)
                break
            except (NotConverged, TooLong) as failed:
                yield Rollback(float(times[0]), float(times[-1]))
                if halvings == s.max_halvings:
                    raise
                self._count_rejected(failed)
        interval.halvings = halvings
        return (yield from self._commit(interval))

    def _auto_run(
        self, t_start: float, t_stop: float, control: IntervalControl, resume: ResumePoint | None
    ) -> Generator[Action, Outputs | None, RunSummary]:
        """``interval = "auto"``: each interval sized by :mod:`cosim.coupler.interval_control`.

        A try that does not converge, or whose interpolation error estimate exceeds ``interval_tol``,
        is rolled back and retried shorter; an accepted one sets the next length. The last interval
        ends at ``t_stop``."""
        s = self.settings
        q = order(s.interp, s.samples)
        t, H = (t_start, control.clip(s.interval)) if resume is None or resume.length is None else (resume.t,
                                                                                                    resume.length)
        # a length that did not converge is not grown back into for CEILING_PATIENCE intervals
        ceiling, patience = (math.inf, 0) if resume is None else (resume.ceiling, resume.patience)
        summary = RunSummary(t)
        trips, requests, unconverged, rejected_stages = self.round_trips, self.requests, self.unconverged, \
            self.rejected_stages
        while t < t_stop - 1e-9 * H:
            rejected, guessed = 0, bool(self._previous)  # the first interval's stage 0 has no extrapolation
            while True:
                t1 = t + H
                if t1 >= t_stop - 1e-3 * H:  # no sliver left after the last interval
                    t1 = t_stop
                clipped = t1 != t + H  # cut to end at t_stop: a run going further would not end an interval there
                times = sample_times(t, t1, s.samples)
                self._give_up_early = H > control.minimum  # (at interval_min a try given up ends the run)
                try:
                    interval = yield from self._converge(times)
                except (NotConverged, TooLong) as failed:
                    yield Rollback(t, t1)
                    if H <= control.minimum:
                        raise
                    self._count_rejected(failed)
                    ceiling, patience = min(ceiling, t1 - t), CEILING_PATIENCE
                    H, rejected = retry_length(H, math.inf, q, control), rejected + 1
                    continue
                ratio, _ = error_ratio(interval.inputs, s.interp, control.tol, self._magnitudes, s.tol.abs)
                if ratio > 1.0 and H > control.minimum and t1 - t > control.minimum:
                    yield Rollback(t, t1)
                    self.rejected_stages += interval.stages
                    H, rejected = retry_length(min(H, t1 - t), ratio, q, control), rejected + 1
                    continue
                break
            interval.halvings, interval.error = rejected, ratio
            summary.over_tol += ratio > 1.0
            self._magnitudes = magnitudes(interval.inputs, self._magnitudes)
            if t1 - t >= H * (1 - 1e-9):  # a clipped last interval says nothing about a longer one
                stages = interval.stages if guessed or s.first_guess != "extrapolate" else 1  # the error decides
                H = next_length(H, ratio, stages, q, control)
            if patience:
                H, patience = min(H, control.clip(CEILING_MARGIN * ceiling)), patience - 1
                ceiling = ceiling if patience else math.inf
            self._next_length, self._ceiling = H, (ceiling, patience)  # before the commit: part of its resume point
            yield from self._commit(interval, resumable=not clipped)
            summary.add(interval)
            t = t1
        self._tally(summary, trips, requests, unconverged, rejected_stages)
        yield Done(summary)
        return summary

    def _tally(self, summary: RunSummary, trips: int, requests: int, unconverged: int, rejected_stages: int) -> None:
        """The summary's counts: what this machine emitted and rejected since they were taken."""
        summary.round_trips, summary.requests = self.round_trips - trips, self.requests - requests
        summary.unconverged, summary.rejected_stages = self.unconverged - unconverged, \
            self.rejected_stages - rejected_stages

    def _count_rejected(self, failed: NotConverged | TooLong) -> None:
        self.unconverged += 1
        self.rejected_stages += failed.stages if isinstance(failed, NotConverged) else failed.stage + 1

    def _commit(self, interval: Interval, resumable: bool = True) -> Generator[Action, Outputs | None, Interval]:
        self._previous = {k: (interval.t, v) for k, v in interval.inputs.items()}
        self.resume_point = (ResumePoint(float(interval.t[-1]), self._next_length, self._previous, self._magnitudes,
                                         *self._ceiling) if resumable else None)
        yield Commit(interval)
        return interval

    def _converge(self, times: np.ndarray) -> Generator[Action, Outputs | None, Interval]:
        """The interval's stages; from stage 0 again whenever the driver throws :class:`RetryInterval`."""
        while True:
            try:
                if self.settings.method == "centralized":
                    return (yield from self._centralized(times))
                return (yield from self._distributed(times))
            except RetryInterval:
                continue

    # --- one interval ----------------------------------------------------------------------------

    def _guess(self, times: np.ndarray, couplings: Evaluations) -> dict[str, np.ndarray]:
        sizes = {k: w for k, _, w in couplings}
        return first_guess(self.settings.first_guess, times, sizes, self._previous, self.settings.interp,
                           self.plan.guess)

    def _inputs_of(self, name: str, signals: Mapping[str, np.ndarray], n: int) -> dict[str, np.ndarray]:
        """Inputs of ``name`` from coupled ``signals``; an uncoupled input is its held constant, else zero."""
        return {p: signals[k] if k in signals else self._uncoupled(k, n, w) for p, k, w in self._ports[name]}

    def _uncoupled(self, key: str, n: int, width: int) -> np.ndarray:
        held = self.plan.held.get(key)
        return np.zeros((n, width)) if held is None else np.tile(np.asarray(held, dtype=np.float64), (n, 1))

    def _evaluations(self, couplings: Sequence[Coupling]) -> Evaluations:
        return tuple((str(c.target), c, self._sizes[c.target]) for c in couplings)

    def _read_by(self, level: Sequence[str], readers: Sequence[str]) -> tuple[tuple[str, str], ...]:
        sources = {(s.subsim, s.port) for name in readers for c in self.plan.forward_into[name] for s in c.sources}
        return tuple(sorted(src for src in sources if src[0] in level))

    def _ahead(self, i: int, stage: int, last_stage: Outputs | None, outputs: Outputs, inputs: dict[str, np.ndarray],
               n: int) -> tuple[tuple[str, ...], dict[str, np.ndarray]] | None:
        """Level i + 1 and its inputs on level i's outputs of the previous stage, when it is worth running it beside
        level i; else None. A miss is tried again after ``RETRY_MISSED`` interval tries."""
        levels = self.plan.levels
        if not self.settings.speculate or last_stage is None or i + 1 >= len(levels):
            return None
        missed = self._missed.get((i, stage))
        if missed is not None and self._tries - missed < RETRY_MISSED:
            return None
        seen = {**outputs, **{name: last_stage[name] for name in levels[i]}}
        ahead = dict(inputs)
        try:
            for name in levels[i + 1]:
                for k, c, w in self._forward_into[name]:
                    ahead[k] = c.evaluate(seen, w, n)
        except ValueError:  # a mix of stages no in-order run would see: not worth an error, run in order instead
            return None
        return levels[i + 1], ahead

    def _repeated(self, i: int, outputs: Outputs, last_stage: Outputs) -> bool:
        """Whether level i gave, bit for bit, the outputs of the previous stage that level i + 1 reads."""
        return all(outputs[name][port].tobytes() == last_stage[name][port].tobytes()
                   for name, port in self._read_ahead[i])

    def _run_changed(self, stage: int, times: np.ndarray, runs: dict[str, dict[str, np.ndarray]],
                     latest: Latest) -> Generator[Action, Outputs | None, Outputs]:
        """The outputs of every subsim in ``runs``; only those whose inputs differ, in one bit at least, from those
        of its latest run in this interval are run (one ``Run``, none if all repeat). ``advance`` is pure and a
        subsim commits its latest trial, so a repeat would give, and commit, exactly what that run did."""
        outputs: Outputs = {}
        changed = {}
        for name, ins in runs.items():
            last = latest.get(name)
            if last is not None and _same_inputs(ins, last[0]):
                outputs[name] = last[1]
            else:
                changed[name] = ins
        if changed:
            got = self._received((yield self._action(stage, times, changed)), changed, times.size)
            for name, ins in changed.items():
                latest[name] = (ins, got[name])
                outputs[name] = got[name]
        return outputs

    def _received(self, got: Any, asked: Mapping[str, Any], n: int) -> Outputs:
        """The driver's answer to a ``Run``: each subsim asked, every output port an (n, width) array. A driver's
        mistake is named here (a KeyError or an IndexError deep in a coupling or the check said nothing)."""
        try:
            outputs = self.plan.outputs
            if got.keys() == asked.keys() and all(_fits(got[name], outputs[name], n) for name in asked):
                return got
        except (AttributeError, KeyError, TypeError):
            pass
        raise ValueError(_misanswered(got, asked, n, self.plan.outputs))

    def _check(self, new: dict, old: dict, history: dict[str, list[float]]) -> Check:
        """The convergence check of one stage; appends each signal's largest residual to ``history``."""
        result = check(new, old, self.settings.tol, self.settings.tolerances)
        for k, r in result.largest_each.items():
            history.setdefault(k, []).append(r)
        return result

    def _centralized(self, times: np.ndarray) -> Generator[Action, Outputs | None, Interval]:
        n, s, plan = times.size, self.settings, self.plan
        inputs = self._guess(times, self._all)
        history: dict[str, list[float]] = {}
        seen: deque[dict[str, bytes]] = deque(maxlen=CYCLE_PERIOD)  # the checked outputs of the latest stages
        last_stage: dict[str, np.ndarray] | None = None  # the flat outputs of the stage before, for the check
        latest: Latest = {}
        failing: tuple[str, ...] = ()  # the signals the latest check failed
        unsettled: dict[str, int] = {}  # (see _count_unsettled)
        for stage in range(s.max_stages):
            runs = {name: self._inputs_of(name, inputs, n) for name in plan.names}
            outputs = yield from self._run_changed(stage, times, runs, latest)
            if self.report_stages:
                yield StageDone(stage, outputs)
            flat = {f"{name}.{p}": v for name, ports in outputs.items() for p, v in ports.items()}
            if last_stage is not None:
                result = self._check(flat, last_stage, history)
                if result.converged:
                    return Interval(times, outputs, inputs, stage + 1, history, converged_last=failing)
                failing = tuple(result.failing)
                _count_unsettled(unsettled, result.largest_each, failing)
                if self._give_up_early and _hopeless(history, failing, unsettled):  # retried shorter: no use going on
                    raise NotConverged(float(times[0]), float(times[-1]), stage + 1, result.failing, history)
                back = _repeated(flat, seen) if stage >= CYCLE_FROM else 0
                if back:
                    raise NotConverged(float(times[0]), float(times[-1]), stage + 1, result.failing, history, flat,
                                       cycled=back)
            last_stage = flat
            inputs = {k: c.evaluate(outputs, w, n) for k, c, w in self._all}
        raise NotConverged(float(times[0]), float(times[-1]), s.max_stages, result.failing, history, last_stage)

    def _distributed(self, times: np.ndarray) -> Generator[Action, Outputs | None, Interval]:
        n, s, plan = times.size, self.settings, self.plan
        forward_into = self._forward_into
        fed_back = self._guess(times, self._feedback)
        history: dict[str, list[float]] = {}
        seen: deque[dict[str, bytes]] = deque(maxlen=CYCLE_PERIOD)  # the fed-back signals of the latest stages
        last_stage: Outputs | None = None  # the outputs of the stage before (self._previous: of the interval before)
        self._tries += 1
        latest: Latest = {}
        failing: tuple[str, ...] = ()  # the signals the latest check failed
        unsettled: dict[str, int] = {}  # (see _count_unsettled)
        for stage in range(s.max_stages):
            inputs = dict(fed_back)
            outputs: Outputs = {}
            i = 0
            while i < len(plan.levels):  # in order; a level's subsims read nothing of each other: one Run
                level = plan.levels[i]
                for name in level:
                    for k, c, w in forward_into[name]:
                        inputs[k] = c.evaluate(outputs, w, n)
                runs = {name: self._inputs_of(name, inputs, n) for name in level}
                ahead = self._ahead(i, stage, last_stage, outputs, inputs, n)
                if ahead is not None:
                    runs.update({name: self._inputs_of(name, ahead[1], n) for name in ahead[0]})
                got = yield from self._run_changed(stage, times, runs, latest)
                outputs.update({name: got[name] for name in level})
                i += 1
                if ahead is not None:
                    assert last_stage is not None
                    if self._repeated(i - 1, outputs, last_stage):  # the inputs it ran on were the in-order ones
                        outputs.update({name: got[name] for name in ahead[0]})
                        inputs = ahead[1]
                        i += 1
                    else:  # run it again, in order, on this stage's outputs
                        self._missed[(i - 1, stage)] = self._tries
            last_stage = outputs
            if self.report_stages:
                yield StageDone(stage, outputs)
            if not plan.feedback:  # nothing to iterate: a feed-forward chain is exact in one stage
                return Interval(times, outputs, inputs, stage + 1, history)
            new = {k: c.evaluate(outputs, w, n) for k, c, w in self._feedback}
            if stage > 0:
                result = self._check(new, fed_back, history)
                if result.converged:
                    return Interval(times, outputs, inputs, stage + 1, history, converged_last=failing)
                failing = tuple(result.failing)
                _count_unsettled(unsettled, result.largest_each, failing)
                if self._give_up_early and _hopeless(history, failing, unsettled):  # retried shorter: no use going on
                    raise NotConverged(float(times[0]), float(times[-1]), stage + 1, result.failing, history)
                back = _repeated(new, seen) if stage >= CYCLE_FROM else 0
                if back:
                    raise NotConverged(float(times[0]), float(times[-1]), stage + 1, result.failing, history, new,
                                       cycled=back)
            fed_back = new
        raise NotConverged(float(times[0]), float(times[-1]), s.max_stages, result.failing, history, fed_back)

