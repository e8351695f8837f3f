"""Speculative levels of the distributed method (``speculate = true``): a level runs beside the one before it on
that one's previous-stage outputs and is kept only when those come back bit for bit the same, so the results are
the in-order ones to the bit, in fewer round trips when a subsim stops moving at double precision, and in the same
round trips (a few requests more, bounded) when nothing does.
"""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path

import numpy as np
import pytest

from cosim.coupler.convergence import Tolerance
from cosim.coupler.couplings import Coupling, SignalRef
from cosim.coupler.plan import Plan
from cosim.coupler.relaxation import RETRY_MISSED, Commit, Done, Relaxation, Run, Settings
from cosim.runner import run_scenario
from cosim.scenario import ScenarioError, load, parse

ROOT = Path(__file__).resolve().parents[1]


def integrate(y0: float, times: np.ndarray, u: np.ndarray) -> np.ndarray:
    """y' = u by the trapezoid rule: a deterministic stand-in for a subsim."""
    steps = np.diff(times) * (u[1:] + u[:-1]) / 2.0
    return y0 + np.concatenate(([0.0], np.cumsum(steps)))


def line(feedback_gain: float, into_b: float | None = None) -> Plan:
    """a -> b -> c in order, c fed back to a with ``feedback_gain``: three levels of one subsim. With ``into_b``, c is
    also fed back into b (input ``v``) with that gain, so that b's inputs change at every stage even when a's
    outputs do not (a subsim whose inputs repeat bit for bit is not run again)."""
    couplings = [Coupling.make("b.u", "a.y"), Coupling.make("c.u", "b.y"),
                 Coupling.make("a.u", "c.y", "gain", {"k": feedback_gain})]
    inputs = {n: {"u": 1} for n in "abc"}
    if into_b is not None:
        couplings.append(Coupling.make("b.v", "c.y", "gain", {"k": into_b}))
        inputs["b"]["v"] = 1
    plan = Plan.build(inputs, {n: {"y": 1} for n in "abc"}, couplings, "distributed", order=["a", "b", "c"])
    assert plan.levels == (("a",), ("b",), ("c",))
    return plan


def drive(plan: Plan, speculate: bool, t_stop: float,
          names: str = "abc") -> tuple[list[tuple[int, int, tuple[str, ...]]], list[dict]]:
    """Every Run as (interval, stage, subsims), and every committed interval's outputs."""
    s = Settings(method="distributed", interval=0.25, samples=5, first_guess="zero", tol=Tolerance(1e-13, 1e-15),
                 speculate=speculate)
    steps = Relaxation(plan, s).run(0.0, t_stop)
    runs: list[tuple[int, int, tuple[str, ...]]] = []
    commits: list[dict] = []
    action = steps.send(None)
    while not isinstance(action, Done):
        reply = None
        if isinstance(action, Run):  # each subsim starts from its own y0 = 1, 2, 3 in every interval
            runs.append((len(commits), action.stage, tuple(action.inputs)))
            reply = {n: {"y": integrate(1.0 + names.index(n), action.times, sum(ins.values())[:, 0])[:, None]}
                     for n, ins in action.inputs.items()}
        elif isinstance(action, Commit):
            commits.append(action.interval.outputs)
        action = steps.send(reply)
    return runs, commits


def same_bits(x: list[dict], y: list[dict], names: str = "abc") -> bool:
    return len(x) == len(y) and all(a[n]["y"].tobytes() == b[n]["y"].tobytes() for a, b in zip(x, y) for n in names)


def test_a_subsim_that_stops_moving_lets_the_next_level_run_beside_it_with_the_same_bits() -> None:
    # a's input is far below a's rounding: a repeats its output bit for bit at every stage; b's other input moves
    plan = line(1e-30, into_b=-0.5)
    in_order, expected = drive(plan, False, 1.0)
    speculated, commits = drive(plan, True, 1.0)
    assert same_bits(commits, expected) and len(commits) == 4
    assert all(len(names) == 1 for _, _, names in in_order)
    # stage 0 in order (nothing to speculate on yet), then a and b together in every later stage
    assert [names for _, stage, names in speculated if stage == 0] == [("a",), ("b",), ("c",)] * 4
    later = [names for _, stage, names in speculated if stage > 0]
    assert later and later == [("a", "b"), ("c",)] * (len(later) // 2)
    assert len(in_order) - len(speculated) == sum(1 for _, stage, _ in in_order if stage > 0) // 3


def test_when_nothing_repeats_the_results_and_round_trips_are_the_in_order_ones() -> None:
    # tightly coupled: every subsim moves at every stage. (Without c -> b, b's speculative inputs would be a's outputs
    # of the previous stage alone: b's inputs of its latest run, which is not run again, so a try would cost nothing)
    plan = line(-1.0, into_b=-0.5)
    in_order, expected = drive(plan, False, 20.0)
    speculated, commits = drive(plan, True, 20.0)
    assert same_bits(commits, expected) and len(commits) == 80
    assert len(speculated) == len(in_order)  # every miss runs its level again: no round trip gained or lost
    level = {"a": 0, "b": 1, "c": 2}
    attempts: dict[tuple[int, int], list[int]] = {}
    for interval, stage, names in speculated:
        if len(names) == 2:
            attempts.setdefault((level[names[0]], stage), []).append(interval)
    assert attempts
    for tried in attempts.values():  # a (level, stage) that missed is tried again RETRY_MISSED intervals later
        assert tried[0] == 0 and all(b - a == RETRY_MISSED for a, b in zip(tried, tried[1:]))
    requests = sum(len(names) for _, _, names in speculated)
    assert requests - sum(len(names) for _, _, names in in_order) == sum(map(len, attempts.values()))


def test_a_coupling_that_fails_on_a_speculative_mix_of_stages_only_costs_the_speculation() -> None:
    # x -> a -> b, b fed back to x; b reads x and a. Run ahead beside a, b would read x of this stage with a of the
    # previous one, a pair no in-order run sees: this transform refuses any such pair, as a real one may refuse
    # inputs out of its range
    in_order_pairs: set[tuple[bytes, bytes]] = set()
    refused: list[int] = []

    def pair_sum(xy: np.ndarray, ay: np.ndarray) -> np.ndarray:
        pair = (xy.tobytes(), ay.tobytes())
        if recording:
            in_order_pairs.add(pair)
        elif pair not in in_order_pairs:
            refused.append(1)
            raise ValueError("x and a from different stages")
        return xy + ay

    couplings = [Coupling.make("a.u", "x.y"),
                 Coupling(SignalRef.parse("b.u"), (SignalRef.parse("x.y"), SignalRef.parse("a.y")), pair_sum, {},
                          "pair_sum"),
                 Coupling.make("x.u", "b.y", "gain", {"k": -1.0})]
    plan = Plan.build({n: {"u": 1} for n in "xab"}, {n: {"y": 1} for n in "xab"}, couplings, "distributed",
                      order=["x", "a", "b"])
    recording = True
    in_order, expected = drive(plan, False, 2.0, names="xab")
    recording = False
    speculated, commits = drive(plan, True, 2.0, names="xab")
    assert refused  # the speculative evaluation was tried, and refused
    assert same_bits(commits, expected, names="xab") and len(commits) == 8
    assert len(speculated) == len(in_order)  # b ran in order every time


def test_speculate_must_be_a_boolean() -> None:
    with pytest.raises(ValueError, match="speculate must be true or false"):
        Settings(method="distributed", speculate="yes")  # type: ignore[arg-type]
    raw = tomllib.loads((ROOT / "scenarios/oscillator.toml").read_text())
    raw.setdefault("coupling", {}).setdefault("distributed", {})["speculate"] = "yes"
    with pytest.raises(ScenarioError, match="speculate must be true or false"):
        parse(raw, ROOT / "scenarios/oscillator.toml")


def test_the_paper_satellite_runs_8_round_trips_an_interval_instead_of_9_with_the_same_results(tmp_path: Path) -> None:
    scenario = load(ROOT / "scenarios/satellite/case1.toml")
    assert scenario.settings["distributed"].speculate  # the paper scenarios speculate
    off = dataclasses.replace(scenario, settings={**scenario.settings, "distributed": dataclasses.replace(
        scenario.settings["distributed"], speculate=False)})
    reports = {}
    for name, s in (("on", scenario), ("off", off)):
        reports[name] = run_scenario(s, "distributed", stop=40.0, output=tmp_path / f"{name}.csv", inprocess=True,
                                     progress=False, log=lambda *a, **k: None)
    on, off_ = reports["on"].summary, reports["off"].summary
    assert (tmp_path / "on.csv").read_bytes() == (tmp_path / "off.csv").read_bytes()
    assert on.intervals == off_.intervals == 100 and on.stages == off_.stages == {3: 100}
    assert off_.round_trips == 9 * 100
    # stage 2 runs orbit and attitude together (orbit's R repeats bit for bit); stage 1 misses (stage 0 ran on
    # zero aero force), and is tried again every RETRY_MISSED intervals
    assert 8 * 100 <= on.round_trips <= 8 * 100 + RETRY_MISSED  # a miss at stage 2 waits RETRY_MISSED intervals
    # a miss costs one request: at most one per (level with a successor, stage 1 or 2) every RETRY_MISSED intervals
    assert 0 < on.requests - off_.requests <= 2 * 2 * -(-100 // RETRY_MISSED)
