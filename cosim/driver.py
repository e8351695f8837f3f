"""Drive the sans-IO relaxation machine over subsim handles: the coupler's thin I/O shell.

The machine (:mod:`cosim.coupler.relaxation`) decides what runs; this module sends it through
:class:`~cosim.handles.SubsimHandle` objects (in-process or remote, with bit-identical results),
measures wall time, and rides each commit on the subsim's next request.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from cosim.coupler.couplings import Coupling
from cosim.coupler.plan import Plan
from cosim.coupler.relaxation import (
    Commit,
    Done,
    Interval,
    Outputs,
    Relaxation,
    Rollback,
    Run,
    RunSummary,
    Settings,
    StageDone,
    Steps,
    sample_times,
)
from cosim.handles import Description, IntervalResult, SubsimHandle

OnStage = Callable[[int, Outputs], None]


def plan_for(
    descriptions: Mapping[str, Description], couplings: Sequence[Coupling], settings: Settings
) -> Plan:
    """The coupling plan of described subsims (raises ``CouplingError`` naming the first bad coupling)."""
    inputs = {n: {p: port.size for p, port in d.inputs.items()} for n, d in descriptions.items()}
    outputs = {n: {p: port.size for p, port in d.outputs.items()} for n, d in descriptions.items()}
    return Plan.build(inputs, outputs, couplings, settings.method, settings.order)


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
    ) -> None:
        self.handles = dict(handles)
        self.settings = settings
        self.on_stage = on_stage
        if isinstance(couplings, Plan):
            self.plan = couplings
        else:
            desc = dict(descriptions) if descriptions else {n: h.describe() for n, h in self.handles.items()}
            self.plan = plan_for(desc, couplings, settings)
        self._machine: Relaxation | None = None
        # converged subsims whose commit has not been sent: it rides on their next run_interval
        self._uncommitted: set[str] = set()

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
            self._machine = Relaxation(self.plan, self.settings, report_stages=True)
        self._machine.report_stages = self.on_stage is not None
        return self._machine

    # --- a run --------------------------------------------------------------------------------

    def run(
        self, t_start: float, t_stop: float, on_interval: Callable[[Interval], None] | None = None
    ) -> RunSummary:
        """Advance whole intervals from ``t_start`` (every subsim's committed time) past ``t_stop``."""
        summary = self._drive(self._relaxation().run(t_start, t_stop), on_interval)
        self.commit_pending()
        assert summary is not None
        return summary

    def advance(self, t0: float, t1: float) -> Interval:
        """Converge the interval [t0, t1], commit every subsim, and return what converged.

        With ``max_halvings`` > 0 a non-converging interval is retried on its first half, then
        its first quarter, ...; the returned interval then ends before ``t1``.
        """
        done: list[Interval] = []
        self._drive(self._relaxation().interval(t0, t1), done.append)
        self.commit_pending()
        return done[0]

    def commit_pending(self) -> None:
        """Commit, in one concurrent round trip, the converged trials still waiting for a next interval."""
        names = [n for n in self.handles if n in self._uncommitted]
        for wait in [self.handles[n].start_commit() for n in names]:
            wait()
        self._uncommitted.clear()

    # --- performing the machine's actions -------------------------------------------------------

    def _drive(self, steps: Steps, on_interval: Callable[[Interval], None] | None) -> RunSummary | None:
        started = time.perf_counter()
        reply: Outputs | None = None
        while True:
            try:
                action = steps.send(reply)
            except StopIteration as stop:
                return stop.value
            reply = None
            if isinstance(action, Run):
                reply = self._run(action)
            elif isinstance(action, StageDone):
                if self.on_stage is not None:
                    self.on_stage(action.stage, action.outputs)
            elif isinstance(action, Rollback):
                for h in self.handles.values():
                    h.rollback()
            elif isinstance(action, Commit):
                self._uncommitted = set(self.handles)
                action.interval.wall_time = time.perf_counter() - started
                if on_interval is not None:
                    on_interval(action.interval)
                started = time.perf_counter()
            elif isinstance(action, Done):
                return action.summary

    def _run(self, action: Run) -> Outputs:
        """Start every run of the action, then wait for all (none is left in flight). A subsim that
        answered has committed its previous interval if asked to. Raises the first error after all answered."""
        interp, uncommitted = self.settings.interp, self._uncommitted
        pending: dict[str, Callable[[], IntervalResult]] = {
            name: self.handles[name].start_run_interval(action.times, inputs, interp, commit=name in uncommitted)
            for name, inputs in action.inputs.items()
        }
        outputs, error = {}, None
        for name, wait in pending.items():
            try:
                outputs[name] = wait().outputs
            except Exception as exc:
                error = error or exc
                continue
            uncommitted.discard(name)
        if error is not None:
            raise error
        return outputs
