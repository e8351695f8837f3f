"""A subsim asked again, within one try of an interval, on the very inputs of its latest run is answered from that
run: ``advance`` is pure (the subsim contract), so the request could only return the same bits. Both methods; the
driver sees fewer requests (and no Run at all when every subsim of it repeats), and every committed interval's
outputs are still what its subsims give on the inputs recorded with it.
"""

from __future__ import annotations

import numpy as np

from cosim.coupler.convergence import Tolerance
from cosim.coupler.couplings import Coupling
from cosim.coupler.plan import Plan
from cosim.coupler.relaxation import Commit, Done, Interval, Relaxation, Run, Settings

Y0 = {"a": 1.0, "b": 2.0, "c": 3.0}


def integrate(name: str, times: np.ndarray, inputs: dict[str, np.ndarray]) -> np.ndarray:
    """y' = the sum of the inputs by the trapezoid rule, from Y0[name]: a pure stand-in for a subsim."""
    u = sum(inputs.values())[:, 0]
    return (Y0[name] + np.concatenate(([0.0], np.cumsum(np.diff(times) * (u[1:] + u[:-1]) / 2.0))))[:, None]


def drive(plan: Plan, method: str, t_stop: float) -> tuple[list[Run], list[Interval]]:
    s = Settings(method=method, interval=0.25, samples=5, first_guess="zero", tol=Tolerance(1e-13, 1e-15))
    steps = Relaxation(plan, s).run(0.0, t_stop)
    runs: list[Run] = []
    commits: list[Interval] = []
    action = steps.send(None)
    while not isinstance(action, Done):
        reply = None
        if isinstance(action, Run):
            runs.append(action)
            reply = {n: {"y": integrate(n, action.times, ins)} for n, ins in action.inputs.items()}
        elif isinstance(action, Commit):
            commits.append(action.interval)
        action = steps.send(reply)
    return runs, commits


def outputs_are_those_of_the_recorded_inputs(commits: list[Interval], plan: Plan) -> bool:
    return all(
        iv.outputs[n]["y"].tobytes()
        == integrate(n, iv.t, {p: iv.inputs[f"{n}.{p}"] for p in plan.inputs[n]}).tobytes()
        for iv in commits for n in plan.names
    )


def test_distributed_a_level_whose_inputs_repeat_sends_nothing() -> None:
    # a -> b -> c, c fed back to a far below a's rounding: from stage 1 on a's outputs repeat bit for bit, so b and
    # c are asked on the inputs of their stage-0 runs, and the stage-1 check finds the fed-back signal unchanged
    couplings = [Coupling.make("b.u", "a.y"), Coupling.make("c.u", "b.y"),
                 Coupling.make("a.u", "c.y", "gain", {"k": 1e-30})]
    plan = Plan.build({n: {"u": 1} for n in "abc"}, {n: {"y": 1} for n in "abc"}, couplings, "distributed",
                      order=["a", "b", "c"])
    runs, commits = drive(plan, "distributed", 1.0)
    assert len(commits) == 4 and all(iv.stages == 2 for iv in commits)
    # per interval: a, b, c at stage 0; only a at stage 1 (its input moved from the zero guess to 1e-30 c)
    assert [(r.stage, tuple(r.inputs)) for r in runs] == [(0, ("a",)), (0, ("b",)), (0, ("c",)), (1, ("a",))] * 4
    assert outputs_are_those_of_the_recorded_inputs(commits, plan)


def test_centralized_a_subsim_fed_zeros_twice_runs_once() -> None:
    # a reads b through a zero gain: its stage-1 inputs are the zero first guess again. Then b's stage-2 inputs
    # are a's stage-0 outputs again, so stage 2 needs no Run at all, and it converges (nothing moved)
    couplings = [Coupling.make("a.u", "b.y", "gain", {"k": 0.0}), Coupling.make("b.u", "a.y")]
    plan = Plan.build({n: {"u": 1} for n in "ab"}, {n: {"y": 1} for n in "ab"}, couplings, "centralized")
    runs, commits = drive(plan, "centralized", 1.0)
    assert len(commits) == 4 and all(iv.stages == 3 for iv in commits)
    assert [(r.stage, tuple(r.inputs)) for r in runs] == [(0, ("a", "b")), (1, ("b",))] * 4
    assert outputs_are_those_of_the_recorded_inputs(commits, plan)
