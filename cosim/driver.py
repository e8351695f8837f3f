"""Drive the sans-IO relaxation machine over subsim handles: the coupler's thin I/O shell.

The machine (:mod:`cosim.coupler.relaxation`) decides what runs; this module sends it through
:class:`~cosim.handles.SubsimHandle` objects (in-process or remote, with bit-identical results),
measures wall time, rides each commit on the subsim's next request, and (with a :class:`Recovery`)
replaces a subsim that died or hung: a new process, the last checkpoint of its committed state
(``set_state``), the committed intervals since then replayed on the very inputs they converged
with, then the interrupted interval again from stage 0. ``advance`` is pure, so the result is
bit-identical to an undisturbed run.
"""

from __future__ import annotations

import math
import os
import statistics
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NoReturn, TypeVar

import numpy as np

from cosim.contract import SubsimDied, SubsimError, SubsimHung, SubsimLeft
from cosim.coupler.couplings import Coupling, CouplingError, check_units
from cosim.coupler.plan import Plan
from cosim.coupler.relaxation import (
    Commit,
    Done,
    Interval,
    Outputs,
    Relaxation,
    ResumePoint,
    RetryInterval,
    Rollback,
    Run,
    RunSummary,
    Settings,
    StageDone,
    Steps,
    TooLong,
    sample_times,
)
from cosim.handles import Description, IntervalResult, SubsimHandle, SubsimState

T = TypeVar("T")

OnStage = Callable[[int, Outputs], None]
# Called with each committed interval, in order; if it returns an iterator, the interval is recorded one item
# at a time, in the coordinator's idle moments (``cosim.runner`` writes a result file so).
OnInterval = Callable[[Interval], Iterable[object] | None]
Revive = Callable[[str, str], SubsimHandle]  # (name, why it was lost): a new process, configured at the run start
OnCheckpoint = Callable[[ResumePoint, dict[str, SubsimState]], None]  # every subsim's committed state there


ROUND_TRIPS_KEPT = 10_000  # the latest Runs' times, whose median the run's summary gives
CORES = os.cpu_count() or 1  # a run of fewer subsims leaves a core to the coordinator's own writing


@dataclass
class Deadline:
    """How long to wait for a reply before calling a subsim hung.

    ``fixed`` seconds if given; otherwise the largest of ``floor``, ``typical`` times the median and
    ``spike`` times the slowest of the last ``window`` runs; ``initial`` until ``warmup`` runs have been
    timed (the first requests pay imports and caches). A median-based deadline follows the model's real
    cost; the spike term keeps a loaded machine's occasional slow request from being called a hang.
    """

    fixed: float | None = None
    floor: float = 1.5
    typical: float = 50.0
    spike: float = 3.0
    initial: float = 30.0
    warmup: int = 5
    window: int = 200
    _recent: deque = field(default_factory=deque, repr=False)
    _current: float | None = field(default=None, repr=False)
    _seen: int = field(default=0, repr=False)

    def seconds(self) -> float:
        if self.fixed is not None:
            return self.fixed
        if self._current is None:
            return self.initial
        return self._current

    def observe(self, seconds: float) -> None:
        recent = self._recent
        recent.append(seconds)
        if len(recent) > self.window:
            recent.popleft()
        self._seen = seen = self._seen + 1
        # re-derived at the end of the warm-up, then every 20 runs (not per request: the hot path stays cheap),
        # and at once when a run is slower than the spike allowance of the current deadline
        if seen == self.warmup or (seen > self.warmup and (
                seen % 20 == 0 or (self._current is not None and self.spike * seconds > self._current))):
            ordered = sorted(recent)
            self._current = max(self.floor, self.typical * ordered[len(ordered) // 2], self.spike * ordered[-1])


@dataclass
class Recovery:
    """Replace subsims that die or hang: ``revive(name, why)`` gives a new one in the state the run starts from
    (configured; a subsim lost before the first checkpoint is taken as it is); at most ``restarts``
    replacements in a run; a checkpoint of every subsim's committed state each ``checkpoint_every`` intervals."""

    revive: Revive
    restarts: int = 2
    checkpoint_every: int = 200
    log: Callable[[str], None] = print


class Abandoned(SubsimError):
    """Raised by a :data:`Revive`: the lost subsim was waited for as long as the run allows and did not come back (an
    external one not started again): the run stops with this, and no other replacement is tried or counted."""


@dataclass(frozen=True)
class Restart:
    """One replacement, for the diagnostics."""

    subsim: str
    at: float  # the committed time it was restored to
    reason: str
    replayed: int  # committed intervals replayed since the checkpoint
    restored: bool = True  # False: this replacement failed while being restored (and used up a restart)
    charged: bool = True  # False: another subsim lost in the same pause of this coordinator used the restart


def _recoverable(exc: BaseException) -> bool:
    return isinstance(exc, (SubsimDied, SubsimHung))


def _lost_while_restoring(exc: BaseException) -> bool:
    """A replacement that died, hung, or did not come up (its start is a ``spawn``/``connect`` error)."""
    return _recoverable(exc) or (isinstance(exc, SubsimError) and exc.command in {"spawn", "connect"})


def plan_for(
    descriptions: Mapping[str, Description], couplings: Sequence[Coupling], settings: Settings
) -> Plan:
    """The coupling plan of described subsims (raises ``CouplingError`` naming the first bad coupling)."""
    inputs = {n: {p: port.size for p, port in d.inputs.items()} for n, d in descriptions.items()}
    outputs = {n: {p: port.size for p, port in d.outputs.items()} for n, d in descriptions.items()}
    try:
        plan = Plan.build(inputs, outputs, couplings, settings.method, settings.order)
    except CouplingError as exc:  # a port the subsim has as a variable it cannot couple: say why
        why = _no_port(couplings[exc.index], descriptions) if 0 <= exc.index < len(couplings) else ""
        if not why:
            raise
        raise CouplingError(exc.index, f"{exc} ({why})") from None
    check_units(couplings, {n: {p: port.unit for p, port in d.inputs.items()} for n, d in descriptions.items()},
                {n: {p: port.unit for p, port in d.outputs.items()} for n, d in descriptions.items()})
    return plan


def _no_port(coupling: Coupling, descriptions: Mapping[str, Description]) -> str:
    """Why the ends of ``coupling`` that are no ports of their subsims are not, as those subsims say."""
    ends = (coupling.target, *coupling.sources)
    reasons = [f"{end} is {why}" for end in ends if end.subsim in descriptions
               and (why := descriptions[end.subsim].not_ports.get(end.port))]
    return "; ".join(dict.fromkeys(reasons))


class Coordinator:
    """Couples subsims through handles only; the same object drives in-process and remote runs.

    ``couplings`` is a :class:`Plan` already built (a scenario run builds it once) or a list of
    couplings, checked here against ``descriptions`` (asked of the handles when not given).
    ``on_stage(stage, outputs)`` sees every stage's outputs (diagnostics, the exact tests).
    """

    def __init__(
        self,
        handles: Mapping[str, SubsimHandle],
        couplings: Plan | Sequence[Coupling],
        settings: Settings,
        descriptions: Mapping[str, Description] | None = None,
        on_stage: OnStage | None = None,
        recovery: Recovery | None = None,
        deadline: Deadline | None = None,
        on_checkpoint: OnCheckpoint | None = None,
        checkpoint_every: int = 200,
    ) -> None:
        if not isinstance(settings, Settings):  # (a dict failed later: "'dict' object has no attribute 'method'")
            raise TypeError(f"settings must be a cosim.coupler.relaxation.Settings (Settings(**table) of a dict), got "
                            f"{type(settings).__name__}")
        if not isinstance(couplings, Plan) and not all(isinstance(c, Coupling) for c in couplings):
            raise TypeError("couplings must be a Plan or a list of Coupling (Coupling.make(to, from, transform, "
                            "params)), got " + ", ".join(sorted({type(c).__name__ for c in couplings})))
        self.handles = dict(handles)
        # a checkpoint every so many intervals: for replacements (recovery's setting), and handed to on_checkpoint
        self.on_checkpoint = on_checkpoint
        self._checkpoint_every = recovery.checkpoint_every if recovery is not None else checkpoint_every
        self.settings = settings
        self.on_stage = on_stage
        self.recovery = recovery
        self.deadline = deadline or Deadline()
        self.restarts: list[Restart] = []
        self._pauses: list[tuple[float, float]] = []  # this coordinator's pauses that made subsims leave, charged
        # what a replacement needs: each subsim's last checkpoint, the committed intervals since (their times and
        # the inputs each subsim converged with), and the inputs sent to each subsim in its latest run
        self._checkpoints: dict[str, SubsimState] = {}
        self._journal: list[tuple[np.ndarray, dict[str, dict[str, np.ndarray]]]] = []
        self._sent: dict[str, dict[str, np.ndarray]] = {}
        self._commits = 0
        if isinstance(couplings, Plan):
            self.plan = couplings
        else:
            desc = dict(descriptions) if descriptions else {n: h.describe() for n, h in self.handles.items()}
            self.plan = plan_for(desc, couplings, settings)
        self._machine: Relaxation | None = None
        # converged subsims whose commit has not been sent: it rides on their next run_interval
        self._uncommitted: set[str] = set()
        # committed intervals not yet handed to on_interval: recorded while the next run is in flight
        self._unrecorded: list[Interval] = []
        self._recording: Iterator[object] | None = None  # the steps left of the interval being recorded
        self._on_interval: OnInterval | None = None
        self._spare_seen = False  # a run left a core idle: intervals are recorded during such runs
        # seconds from sending to the reply of each subsim's latest run that was waited for (see _run)
        self._took: dict[str, float] = {}
        self._round_trips: deque[float] = deque(maxlen=ROUND_TRIPS_KEPT)  # s, each Run's requests to its last reply
        self._slowest = 0.0  # s, the longest of them in the run

    @property
    def order(self) -> list[str]:
        return list(self.plan.order)

    @property
    def feedback(self) -> list[Coupling]:
        return list(self.plan.feedback)

    @property
    def feedback_signals(self) -> int:
        return self.plan.feedback_signals

    def sample_times(self, t0: float, t1: float) -> np.ndarray:
        return sample_times(t0, t1, self.settings.samples)

    def _relaxation(self) -> Relaxation:
        # one machine for the coordinator's life: it keeps the previous interval for the first guess
        if self._machine is None:
            self._machine = Relaxation(self.plan, self.settings)
        self._machine.report_stages = self.on_stage is not None
        return self._machine

    # --- a run --------------------------------------------------------------------------------

    def run(
        self, t_start: float, t_stop: float, on_interval: OnInterval | None = None, resume: ResumePoint | None = None
    ) -> RunSummary:
        """Advance whole intervals from ``t_start`` (every subsim's committed time) past ``t_stop``. ``resume``:
        go on with such a run from a checkpoint's resume point instead (every subsim restored to its state there)."""
        if self.recovery is not None and not self._checkpoints:
            self._checkpoint()
        summary = self._drive(self._relaxation().run(t_start, t_stop, resume), on_interval)
        self.commit_pending()
        assert summary is not None
        return summary

    def advance(self, t0: float, t1: float) -> Interval:
        """Converge the interval [t0, t1], commit every subsim, and return what converged.

        With ``max_halvings`` > 0 a non-converging interval is retried on its first half, then
        its first quarter, ...; the returned interval then ends before ``t1``.
        """
        done: list[Interval] = []
        if self.recovery is not None and not self._checkpoints:
            self._checkpoint()
        self._drive(self._relaxation().interval(t0, t1), done.append)
        self.commit_pending()
        return done[0]

    def commit_pending(self) -> None:
        """Commit, in one concurrent round trip, the converged trials still waiting for a next interval."""
        names = [n for n in self.handles if n in self._uncommitted]
        self._gather({n: _send(self.handles[n].start_commit) for n in names})
        self._uncommitted.clear()

    # --- performing the machine's actions -------------------------------------------------------

    def _drive(self, steps: Steps, on_interval: OnInterval | None) -> RunSummary | None:
        """Perform the machine's actions. A committed interval is handed to ``on_interval`` (written, shown)
        once the next run's requests are out, so that writing it overlaps the subsims' work instead of
        delaying it: during runs of fewer subsims than cores, if the runs have such ones (RF-D's aero alone,
        not attitude and orbit side by side, which would share two cores three ways), in steps between
        which the coordinator looks for the replies, and stops at the first look that finds them all (an
        ``on_interval`` that returns an iterator is recorded one item a step); else during the first run,
        whole. At the latest at the next commit. Whatever is left is handed over before this returns or
        raises."""
        self._on_interval = on_interval
        try:
            return self._perform(steps)
        finally:
            self._record()

    def _record(self) -> None:
        """Hand every committed interval not yet recorded to ``on_interval``, in order, to the end."""
        while self._record_step():
            pass

    def _record_step(self) -> bool:
        """One step of recording (an ``on_interval`` that returns an iterator is recorded one item at a time);
        False when nothing is left to record."""
        if self._recording is None:
            if not self._unrecorded:
                return False
            interval = self._unrecorded.pop(0)
            steps = self._on_interval(interval) if self._on_interval is not None else None
            if steps is None:
                return True
            self._recording = iter(steps)
        try:
            next(self._recording)
        except StopIteration:
            self._recording = None
        except BaseException:
            self._recording = None
            raise
        return True

    def _record_while_waiting(self, names: Sequence[str]) -> None:
        """Record in steps until every request to ``names`` has its reply (or nothing is left to record)."""
        handles = [self.handles[name] for name in names]
        while not all(h.replied() for h in handles) and self._record_step():
            pass

    def _perform(self, steps: Steps) -> RunSummary | None:
        started = time.perf_counter()
        restarts_before = len(self.restarts)
        reply: Outputs | None = None
        retry = False
        too_long: TooLong | None = None
        while True:
            try:
                if too_long is not None:  # the machine retries shorter (interval = "auto"), or it comes back out
                    action = steps.throw(too_long)
                else:
                    action = steps.throw(RetryInterval()) if retry else steps.send(reply)
            except StopIteration as stop:
                return stop.value
            except TooLong as unhandled:
                raise unhandled.error from None
            reply, retry, too_long = None, False, None
            if isinstance(action, Run):
                try:
                    reply = self._run(action)
                except _Replaced:
                    retry = True
                except SubsimError as exc:
                    shorter = "interval_min" if self.settings.auto is not None else "interval"
                    if exc.code == "too_long":  # the model asked for shorter steps
                        exc.add_note(f"a shorter [coupling] {shorter} is the cure (interval = \"auto\" or "
                                     "max_halvings shortens only the intervals that need it)")
                        too_long = TooLong(exc, action.stage)
                        continue
                    if action.stage > 0 and exc.code in ("model_error", "bad_value") and \
                            ("not finite" in exc.message or "NaN or inf" in exc.message):  # (the runtime's words)
                        exc.add_note(f"it was at stage {action.stage} of the interval [{action.times[0]:g}, "
                                     f"{action.times[-1]:g}], on inputs the coupling iteration made: if that iteration "
                                     f"diverged (values growing stage by stage), a shorter [coupling] {shorter} is "
                                     "the cure")
                        too_long = TooLong(exc, action.stage)
                        continue
                    raise
            elif isinstance(action, StageDone):
                if self.on_stage is not None:
                    self.on_stage(action.stage, action.outputs)
            elif isinstance(action, Rollback):
                for name in list(self.handles):  # a replacement is restored committed: rolled back already
                    self._call_replacing(name, lambda h: h.rollback())
            elif isinstance(action, Commit):
                self._uncommitted = set(self.handles)
                action.interval.wall_time = time.perf_counter() - started
                action.interval.restarts, restarts_before = len(self.restarts) - restarts_before, len(self.restarts)
                self._journal_commit(action.interval)
                self._record()  # an interval that found no run to overlap with (at most one waits)
                self._unrecorded.append(action.interval)
                started = time.perf_counter()
            elif isinstance(action, Done):
                if self._round_trips:  # (an operator reads a slow or lossy link here)
                    action.summary.round_trip_median = statistics.median(self._round_trips)
                    action.summary.round_trip_max = self._slowest
                return action.summary

    def _run(self, action: Run) -> Outputs:
        """Start every run of the action, then wait for all (none is left in flight). A subsim that
        answered has committed its previous interval if asked to. Raises the first error after all answered,
        or :class:`_Replaced` when every failure was a subsim that died or hung and has been replaced."""
        interp, uncommitted, handles, sent_inputs = self.settings.interp, self._uncommitted, self.handles, self._sent
        times, inputs = action.times, action.inputs
        deadline = self.deadline.seconds()
        pending: dict[str, Callable[[], IntervalResult]] = {}
        sent = time.perf_counter()
        # the slowest first (longest processing time first): with more runs than cores, the one that decides
        # when the action ends starts at once and the others share what is left (remote case 2-auto, RF-C:
        # 10 % less wall time than in the plan's order). In process nothing is waited for: the plan's order.
        took = self._took
        for name in sorted(inputs, key=lambda n: -took.get(n, 0.0)) if took else inputs:
            handle = handles[name]
            handle.deadline = deadline
            sent_inputs[name] = inputs[name]
            pending[name] = _send(handle.start_run_interval, times, inputs[name], interp, name in uncommitted)
        recording: BaseException | None = None
        spare = len(pending) < CORES
        self._spare_seen = self._spare_seen or spare
        # (with nothing to record, the common case, the replies need no looking at)
        if (spare or not self._spare_seen) and (self._recording is not None or self._unrecorded):
            try:  # the last committed interval, while this run's requests are being served
                if spare:  # in steps, looking at the replies between them: a reply waits one step at most
                    self._record_while_waiting(list(pending))
                else:
                    self._record()
            except BaseException as exc:  # raised once every request has answered: none is left in flight
                recording = exc
        try:
            results = self._gather(pending, replace=True, sent=sent if len(pending) > 1 else None)  # 1: no order
        except _Replaced as replaced:  # who answered has committed what rode on the request
            uncommitted.difference_update(replaced.answered)
            if recording is not None:
                raise recording from None
            raise
        if recording is not None:
            raise recording
        took = time.perf_counter() - sent
        self.deadline.observe(took)
        self._round_trips.append(took)
        if took > self._slowest:
            self._slowest = took
        uncommitted.difference_update(results)
        return {name: results[name].outputs for name in inputs}

    def _gather(self, pending: Mapping[str, Callable[[], object]], replace: bool = False,
                sent: float | None = None) -> dict:
        """Wait for every pending request; replace the subsims that died or hung (when a recovery is set and
        restarts are left), then raise :class:`_Replaced` if ``replace``; raise any other error. With ``sent``
        (when the requests went), a wait that had to block times its subsim's run into ``_took``."""
        results, errors = {}, {}
        for name, wait in pending.items():
            blocks = sent is not None and not self.handles[name].replied()
            try:
                results[name] = wait()
            except Exception as exc:
                errors[name] = exc
            if blocks:  # its reply came after every earlier one here: how long it took is known
                self._took[name] = time.perf_counter() - sent
        if not errors:
            return results
        fatal = [e for e in errors.values() if not _recoverable(e)]
        left = 0 if self.recovery is None else self.recovery.restarts - self._used()
        if fatal or self._cost(errors.values()) > left:
            raise fatal[0] if fatal else self._out_of_restarts(next(iter(errors.values())))
        for name, exc in errors.items():
            self._replace(name, exc)
        if replace:
            raise _Replaced(set(results))
        results.update({name: None for name in errors})  # a replaced subsim is restored committed
        return results

    # --- recovery -------------------------------------------------------------------------------

    def _checkpoint(self) -> None:
        """Every subsim's committed state now; the journal keeps only what a checkpoint does not cover."""
        self.commit_pending()
        self._checkpoints = {name: self._call_replacing(name, lambda h: h.get_state()) for name in list(self.handles)}
        oldest = min(cp.time for cp in self._checkpoints.values())
        self._journal = [entry for entry in self._journal if entry[0][0] >= oldest]

    def _journal_commit(self, interval: Interval) -> None:
        if self.recovery is None and self.on_checkpoint is None:
            return
        if self.recovery is not None:
            self._journal.append((interval.t, dict(self._sent)))
        self._commits += 1
        if self._commits % self._checkpoint_every == 0:
            self._checkpoint()
            point = None if self._machine is None else self._machine.resume_point
            if self.on_checkpoint is not None and point is not None:
                self.on_checkpoint(point, dict(self._checkpoints))

    def _call_replacing(self, name: str, call: Callable[[SubsimHandle], T]) -> T:
        """``call(handle)`` outside a run (a checkpoint, a rollback); a subsim that died or hung meanwhile is
        replaced, restored to its committed state, and asked again, as in a run."""
        while True:
            try:
                return call(self.handles[name])
            except Exception as exc:
                if not _recoverable(exc):
                    raise
                if self.recovery is None or (self._cost([exc]) and self._used() >= self.recovery.restarts):
                    raise self._out_of_restarts(exc) from None
                self._replace(name, exc)

    def _out_of_restarts(self, exc: Exception) -> Exception:
        """A subsim lost with every restart used: the error says so (the replacements were only logged), and for a
        hung one how to wait longer, in case it was only slow."""
        if not isinstance(exc, SubsimError):
            return exc
        notes = []
        if self.recovery is not None and self.recovery.restarts:
            notes.append(f"no restarts left: {self._used()} of {self.recovery.restarts} used")
        if isinstance(exc, SubsimHung) and getattr(exc, "pause", None) is None:  # (not a reply lost in our pause)
            notes.append("a model this slow at times needs a longer deadline: timeout (--timeout S, [run] timeout)")
        if not notes:
            return exc
        told = type(exc).__new__(type(exc))  # the same error (its kind and what it carries), told more
        told.__dict__.update(vars(exc))
        told.message = f"{exc.message} ({'; '.join(notes)})"
        told.args = (f"{exc.subsim}.{exc.command}: [{exc.code}] {told.message}",)
        return told

    def _used(self) -> int:
        """Restarts used so far."""
        return sum(r.charged for r in self.restarts)

    def _charged(self, pause: tuple[float, float], pauses: list[tuple[float, float]]) -> bool:
        return any(pause[0] < end and start < pause[1] for start, end in pauses)  # the same pause, seen twice

    def _cost(self, errors: Iterable[Exception]) -> int:
        """Restarts replacing the subsims of ``errors`` uses: one each, but one for all that left in one pause of
        this coordinator (its own stop, not theirs: every subsim leaves a coordinator silent that long)."""
        pauses, cost = list(self._pauses), 0
        for exc in errors:
            pause = getattr(exc, "pause", None)  # a SubsimLeft's, or a reply lost in the pause
            if pause is not None:
                if self._charged(pause, pauses):
                    continue
                pauses.append(pause)
            cost += 1
        return cost

    def _replace(self, name: str, why: Exception) -> None:
        """A new process for ``name`` at its last checkpoint, with every committed interval since replayed. A
        replacement that dies, hangs or cannot start while it is being restored uses up a restart too, and
        the next one is tried while restarts are left. Subsims that left in one pause of this coordinator use
        one restart between them."""
        assert self.recovery is not None
        charged = self._cost([why]) > 0
        if charged and getattr(why, "pause", None) is not None:
            self._pauses.append(why.pause)  # type: ignore[attr-defined]
        how = "left" if isinstance(why, SubsimLeft) else "hung" if not isinstance(why, SubsimDied) else \
            "died" if getattr(self.handles[name], "exit_status", None) is not None else "is gone"  # (external: how?)
        reason = f"{how} ({why})"
        self.handles[name].close()
        while True:
            try:
                handle, at, replayed = self._restored(name, reason)
                break
            except Exception as exc:
                if isinstance(exc, Abandoned) or not _lost_while_restoring(exc):
                    raise
                checkpoint = self._checkpoints.get(name)
                self.restarts.append(Restart(name, checkpoint.time if checkpoint else math.nan, reason, 0,
                                             restored=False))
                used, allowed = self._used(), self.recovery.restarts
                self.recovery.log(f"cosim: {name} {reason}; its replacement ({used} of {allowed}) failed while "
                                  f"being restored: {exc}")
                if used >= allowed:
                    raise SubsimError(exc.code, f"{exc.message} (its replacement {used} of {allowed}, while being "
                                      "restored)", name, exc.command) from None
                reason = f"replacement failed ({exc})"
        self.handles[name] = handle
        self._uncommitted.discard(name)
        self.restarts.append(Restart(name, at, reason, replayed, charged=charged))
        checkpoint = self._checkpoints.get(name)
        where = (f"restored to t = {at:g} (checkpoint at t = {checkpoint.time:g}, {replayed} intervals replayed)"
                 if checkpoint is not None else f"at its start, t = {at:g}")
        count = (f"{self._used()} of {self.recovery.restarts}" if charged else
                 f"the restart of that pause, {self._used()} of {self.recovery.restarts} used")
        self.recovery.log(f"cosim: {name} {reason}; replaced ({count}), {where}")

    def _restored(self, name: str, reason: str) -> tuple[SubsimHandle, float, int]:
        """A new process for ``name`` (lost for ``reason``) in its committed state: its handle, that time, and the
        intervals replayed."""
        assert self.recovery is not None
        handle = self.recovery.revive(name, reason)
        try:
            checkpoint = self._checkpoints.get(name)
            if checkpoint is None:  # dead before the first checkpoint, taken before the first interval: revive()
                return handle, float(handle.status()["time"]), 0  # made it as it started, its committed state
            handle.set_state(checkpoint)
            replay = [(t, inputs[name]) for t, inputs in self._journal if t[0] >= checkpoint.time]
            for i, (t, inputs) in enumerate(replay):
                handle.run_interval(t, inputs, self.settings.interp, commit=i > 0)
            if replay:
                handle.commit()
            return handle, float(replay[-1][0][-1]) if replay else checkpoint.time, len(replay)
        except BaseException:
            handle.close()
            raise


class _Replaced(Exception):
    """Every failed subsim of a run was replaced: the interval starts again. ``answered``: the others."""

    def __init__(self, answered: set[str]) -> None:
        super().__init__(answered)
        self.answered = answered


def _send(start: Callable[..., Callable[[], T]], *args: Any, **kwargs: Any) -> Callable[[], T]:
    """``start(...)``, the wait it returns; a subsim known to be gone before sending fails when waited for, as
    one that dies while its request waits does, so that both are replaced the same way."""
    try:
        return start(*args, **kwargs)
    except SubsimError as exc:
        error = exc  # the except block unbinds ``exc``

    def fail() -> NoReturn:
        raise error

    return fail
