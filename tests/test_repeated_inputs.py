"""A subsim whose inputs at a stage are, bit for bit, those of its latest run in the interval is not run again.

``advance`` is pure (the author contract) and a subsim commits its latest trial, so the run would give and commit
exactly what that latest run did: the coupler reuses its outputs, and a stage where nothing changed sends no
request at all. The subsims here are written in the test, so every expected value comes from outside the coupler.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from cosim.contract import SubsimDied
from cosim.coupler.convergence import Tolerance
from cosim.coupler.couplings import Coupling
from cosim.coupler.plan import Plan
from cosim.coupler.relaxation import Commit, Done, Relaxation, Run, Settings
from cosim.driver import Coordinator, Recovery, Restart
from cosim.handles import InProcessHandle
from cosim.runner import run_scenario
from cosim.scenario import load
from cosim.subsim import Subsim
from subsims.integrator.subsim import Integrator

ROOT = Path(__file__).resolve().parents[1]
Models = dict[str, Callable[[np.ndarray, np.ndarray], np.ndarray]]  # subsim -> (times, u (n,)) -> y (n,)


def trapezoid(y0: float, times: np.ndarray, u: np.ndarray) -> np.ndarray:
    """y' = u by the trapezoid rule: a pure stand-in for a subsim."""
    return y0 + np.concatenate(([0.0], np.cumsum(np.diff(times) * (u[1:] + u[:-1]) / 2.0)))


def drive(plan: Plan, method: str, models: Models, t_stop: float) -> tuple[list[list[tuple[str, ...]]], list, list]:
    """The subsims of every Run, grouped per interval; every committed Interval; every (subsim, inputs) run."""
    s = Settings(method=method, interval=0.5, samples=5, first_guess="zero", tol=Tolerance(1e-13, 1e-15))
    steps = Relaxation(plan, s).run(0.0, t_stop)
    runs: list[list[tuple[str, ...]]] = [[]]
    commits, calls = [], []
    action = steps.send(None)
    while not isinstance(action, Done):
        reply = None
        if isinstance(action, Run):
            runs[-1].append(tuple(action.inputs))
            reply = {}
            for name, ins in action.inputs.items():
                calls.append((name, {p: v.copy() for p, v in ins.items()}))
                reply[name] = {"y": models[name](action.times, ins["u"][:, 0])[:, None]}
        elif isinstance(action, Commit):
            commits.append(action.interval)
            runs.append([])
        action = steps.send(reply)
    return runs[:-1], commits, calls


def pair(method: str) -> Plan:
    """a and b, each reading the other's y."""
    couplings = [Coupling.make("a.u", "b.y"), Coupling.make("b.u", "a.y")]
    return Plan.build({"a": {"u": 1}, "b": {"u": 1}}, {"a": {"y": 1}, "b": {"y": 1}}, couplings, method,
                      order=["a", "b"] if method == "distributed" else None)


def test_centralized_runs_again_only_the_subsims_whose_inputs_moved() -> None:
    # b ignores its input (a constant source), so from stage 1 on a's input is b's constant 2: a's stage-2 input is its
    # stage-1 input, bit for bit, and a is not run again; b's input (a's output) moved from stage 0 to 1, so b runs
    models = {"a": lambda t, u: trapezoid(1.0, t, u), "b": lambda t, u: np.full(t.size, 2.0)}
    runs, commits, calls = drive(pair("centralized"), "centralized", models, 1.0)
    assert len(commits) == 2
    assert runs == [[("a", "b"), ("a", "b"), ("b",)]] * 2
    for interval in commits:
        assert interval.stages == 3  # the stage series of the paper's check: stage 2 equals stage 1, converged
        t = interval.t
        assert interval.outputs["a"]["y"][:, 0].tobytes() == trapezoid(1.0, t, np.full(t.size, 2.0)).tobytes()
        assert interval.outputs["b"]["y"][:, 0].tobytes() == np.full(t.size, 2.0).tobytes()
    # a's latest run (stage 1) had the inputs its stage 2 would have had
    a_runs = [ins["u"] for name, ins in calls if name == "a"]
    assert np.array_equal(a_runs[1], np.full((5, 1), 2.0)) and len(a_runs) == 4


def test_a_stage_whose_inputs_all_repeat_sends_no_request() -> None:
    # outputs equal to the zero first guess: stage 1's inputs are stage 0's, so stage 1 is the check alone
    models = {"a": lambda t, u: np.zeros(t.size), "b": lambda t, u: np.zeros(t.size)}
    for method in ("centralized", "distributed"):
        runs, commits, _ = drive(pair(method), method, models, 1.5)
        assert len(commits) == 3 and all(i.stages == 2 for i in commits)
        expected = [("a", "b")] if method == "centralized" else [("a",), ("b",)]
        assert runs == [expected] * 3, method


def test_distributed_skips_the_subsims_downstream_of_one_that_repeated_its_outputs() -> None:
    # a -> b -> c, c fed back to a at 1e-30: a's input moves, its output does not (far below its rounding), so b and c
    # see their inputs of stage 0 again at stage 1 and are not run; the check then finds c's feedback unchanged
    couplings = [Coupling.make("b.u", "a.y"), Coupling.make("c.u", "b.y"),
                 Coupling.make("a.u", "c.y", "gain", {"k": 1e-30})]
    plan = Plan.build({n: {"u": 1} for n in "abc"}, {n: {"y": 1} for n in "abc"}, couplings, "distributed",
                      order=["a", "b", "c"])
    models = {n: (lambda t, u, y0=y0: trapezoid(y0, t, u)) for n, y0 in zip("abc", (1.0, 2.0, 3.0))}
    runs, commits, calls = drive(plan, "distributed", models, 1.0)
    assert runs == [[("a",), ("b",), ("c",), ("a",)]] * 2
    a_inputs = [ins["u"] for name, ins in calls if name == "a"]
    assert np.count_nonzero(a_inputs[1]) > 0  # a's input did move at stage 1: a ran on it
    for interval in commits:
        t = interval.t
        a = trapezoid(1.0, t, np.zeros(t.size))
        b = trapezoid(2.0, t, a)
        c = trapezoid(3.0, t, b)
        assert interval.stages == 2
        for name, y in zip("abc", (a, b, c)):
            assert interval.outputs[name]["y"][:, 0].tobytes() == y.tobytes(), name


def test_the_paper_satellite_rf_c_runs_orbit_once_less_an_interval_with_the_paper_stage_series(
    tmp_path: Path,
) -> None:
    # at RF-C's stage 0 aero gets the zero first guess (R = V = 0), so its force is zero: orbit's stage-1 input (that
    # force, rotated to inertial axes) is the zero guess it ran on at stage 0, bit for bit. 14 requests an interval
    # instead of 15, in 5 stages as in the paper
    report = run_scenario(load(ROOT / "scenarios/satellite/case1.toml"), method="centralized", stop=20.0,
                          output=tmp_path / "x.csv", inprocess=True, progress=False, log=lambda s: None)
    summary = report.summary
    assert summary.intervals == 50
    assert summary.stages == {5: 50}
    assert summary.round_trips == 5 * 50
    assert 14 * 50 <= summary.requests <= 14 * 50 + 1


class DiesOnce(InProcessHandle):
    """An in-process subsim that "dies" (``SubsimDied``) on its ``die_at``-th run_interval, as a killed one would."""

    def __init__(self, model: Subsim, name: str, die_at: int) -> None:
        super().__init__(model, name)
        self.runs, self.die_at = 0, die_at

    def _begin(self, cmd: str, args: dict) -> Callable[[], dict]:
        if cmd == "run_interval":
            self.runs += 1
            if self.runs == self.die_at:
                def dead() -> dict:
                    raise SubsimDied("no_responder", "killed by the test", self.name, cmd)

                return dead
        return super()._begin(cmd, args)


def test_a_subsim_replaced_after_intervals_where_it_was_not_run_again_replays_to_the_same_bits() -> None:
    # RF-C over in-process integrators: a and b feed each other; "src" has no coupled input (zero), so from stage 1 on
    # its inputs repeat and it is left out of every Run but the first of each interval, the last stage's included.
    # src dies at its 6th run (interval 6, stage 0, carrying the commit of interval 5); its replacement is restored
    # from the checkpoint after interval 3 and replays 4 and 5 on the inputs the driver journaled for it, which must
    # be there although src was in none of those intervals' last runs: every result and final state as undisturbed
    couplings = [Coupling.make("a.u", "b.y", "gain", {"k": -0.8}), Coupling.make("b.u", "a.y")]
    y0 = {"src": 2.0, "a": 1.0, "b": 0.5}
    settings = Settings(method="centralized", interval=0.1, samples=4, first_guess="zero", tol=Tolerance(1e-12, 1e-14))

    def handle(name: str, die_at: int = 0) -> InProcessHandle:
        h = DiesOnce(Integrator(), name, die_at) if die_at else InProcessHandle(Integrator(), name)
        h.configure({"y0": [y0[name]]})
        return h

    def run(die_at: int) -> tuple[list[bytes], list[Restart], int]:
        handles = {name: handle(name, die_at if name == "src" else 0) for name in y0}
        recovery = Recovery(lambda name, why: handle(name), restarts=1, checkpoint_every=3, log=lambda s: None)
        coordinator = Coordinator(handles, couplings, settings, recovery=recovery)
        intervals: list = []
        coordinator.run(0.0, 8 * settings.interval, intervals.append)
        rows = [iv.t.tobytes() + b"".join(iv.outputs[n]["y"].tobytes() for n in sorted(y0)) for iv in intervals]
        states = [coordinator.handles[n].get_state() for n in sorted(y0)]
        runs = handles["src"].runs if isinstance(handles["src"], DiesOnce) else 0
        return rows + [np.float64(s.time).tobytes() + s.state.tobytes() for s in states], coordinator.restarts, runs

    undisturbed, none, _ = run(0)
    replaced, restarts, src_runs = run(6)
    assert none == [] and src_runs == 6  # src ran once an interval
    assert len(restarts) == 1 and restarts[0].subsim == "src" and restarts[0].replayed == 2
    assert replaced == undisturbed
