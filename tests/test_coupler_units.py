"""Coupler parts: the convrg check, order/feedback derivation, first guesses, settings, remote stages."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np
import pytest

from cosim.coupler.convergence import Tolerance, check, convrg
from cosim.coupler.couplings import Coupling, SignalRef
from cosim.coupler.first_guess import POLICIES, first_guess
from cosim.coupler.order import derive_order, feedback_weight
from cosim.coupler.relaxation import Interval, Settings
from cosim.driver import Coordinator
from cosim.handles import InProcessHandle
from subsims.integrator.subsim import Integrator


def test_convrg_is_relative_to_the_newest_span_or_absolute() -> None:
    new = np.array([[0.0, 5.0], [2.0, 5.0], [4.0, 5.0]])  # spans 4 and 0
    d1, d2 = 2.0**-5, 2.0**-23  # exact in binary, so the boundary case below is exact too
    old = new + np.array([[0.0, 0.0], [d1, d2], [0.0, 0.0]])
    residual, ok = convrg(new, old, Tolerance(rel=0.01, abs=1e-6))
    np.testing.assert_array_equal(residual, [d1, d2])
    np.testing.assert_array_equal(ok, [True, True])  # d1 <= 0.01*4 ; d2 <= res (span 0)
    _, ok = convrg(new, old, Tolerance(rel=0.005, abs=1e-8))
    np.testing.assert_array_equal(ok, [False, False])
    _, ok = convrg(new, old, Tolerance(rel=2.0**-7, abs=0.0))  # boundary d1 == rel * span: <= passes
    np.testing.assert_array_equal(ok, [True, False])


def test_convrg_span_is_the_newest_stages_per_channel_and_bounds_are_inclusive() -> None:
    """Cases that tell the paper's ``convrg`` from plausible wrong versions of it (all values exact in binary).

    Each row is (new, old, rel, abs, expected pass) for one channel; the perturbation sits on an END
    sample, so the newest and the previous stage have different spans, and every channel sits on an
    offset, so a "span" of max|new| or of max-min over all channels would differ too.
    Wrong versions each case catches: span of the previous stage (a, b); rel and abs swapped (c, d);
    ``<`` instead of ``<=`` (a, e); span over all channels instead of per channel (f, with a);
    max |new| or mean |new| instead of the span (a, b, g); ``and`` instead of ``or`` (d); the span
    of |new - old| instead of the span of new (a).
    """
    base = 100.0
    cases = [
        # a: residual 1, newest span 4, previous span 3: 1 <= 0.25*4 passes (on the boundary)
        ([0.0, 1.0, 4.0], [0.0, 1.0, 3.0], 0.25, 0.0, True),
        # b: residual 1, newest span 3, previous span 4: 1 > 0.25*3 fails
        ([0.0, 1.0, 3.0], [0.0, 1.0, 4.0], 0.25, 0.0, False),
        # c: rel alone would pass (1 <= 0.5*4), abs alone would not (1 > 0.5): passes through rel
        ([0.0, 2.0, 4.0], [1.0, 2.0, 4.0], 0.5, 0.5, True),
        # d: abs alone passes (0.5 <= 0.5, boundary), rel alone does not (0.5 > 0.0625*4)
        ([0.0, 2.0, 4.0], [0.5, 2.0, 4.0], 0.0625, 0.5, True),
        # e: just over both bounds fails
        ([0.0, 2.0, 4.0], [0.0, 2.0, 4.0 + 2.0**-20], 2.0**-23, 2.0**-21, False),
        # f: a constant channel (span 0) with a residual above abs fails whatever the other channels' span
        ([5.0, 5.0, 5.0], [5.0, 5.0, 5.0 + 2.0**-10], 0.5, 2.0**-11, False),
        # g: a signal near a large offset: span 2, not max|new| = 102 (before the offset is added: 2)
        ([0.0, 1.0, 2.0], [0.0, 1.0, 2.5], 0.125, 0.0, False),
    ]
    new = base + np.column_stack([np.array(c[0]) for c in cases])
    old = base + np.column_stack([np.array(c[1]) for c in cases])
    expected_residual = np.abs(np.column_stack([np.subtract(c[0], c[1]) for c in cases])).max(axis=0)
    for j, (_, _, rel, ab, ok) in enumerate(cases):
        residual, passed = convrg(new[:, [j]], old[:, [j]], Tolerance(rel=rel, abs=ab))
        assert residual[0] == expected_residual[j], (j, residual)
        assert bool(passed[0]) is ok, f"case {'abcdefg'[j]}: expected {'pass' if ok else 'fail'}"
    # all channels at once with one tolerance: each channel is judged on its own span
    residual, passed = convrg(new[:, [0, 5]], old[:, [0, 5]], Tolerance(rel=0.25, abs=0.0))
    np.testing.assert_array_equal(residual, [1.0, 2.0**-10])
    np.testing.assert_array_equal(passed, [True, False])  # a global span (4) would pass channel f
    residual, passed = convrg(new[:, [0, 1]], old[:, [0, 1]], Tolerance(rel=0.25, abs=0.0))
    np.testing.assert_array_equal(passed, [True, False])
    # the same through check(): per-signal tolerances and the converged flag
    result = check({"s.a": new[:, [0]], "s.b": new[:, [1]]}, {"s.a": old[:, [0]], "s.b": old[:, [1]]},
                   Tolerance(rel=0.25, abs=0.0))
    assert result.failing == ["s.b"] and not result.converged and result.largest == 1.0
    assert check({"s.b": new[:, [1]]}, {"s.b": old[:, [1]]}, Tolerance(0.25, 0.0),
                 {"s.b": Tolerance(1 / 3 + 2.0**-50, 0.0)}).converged  # 1 <= rel * 3


def test_check_uses_per_signal_tolerances_and_names_failures() -> None:
    new = {"a.x": np.array([[0.0], [1.0]]), "b.y": np.array([[0.0], [1000.0]])}
    old = {"a.x": np.array([[0.0], [1.001]]), "b.y": np.array([[0.0], [1000.5]])}
    result = check(new, old, Tolerance(1e-4, 0.0), {"b.y": Tolerance(0.0, 1.0)})
    assert result.failing == ["a.x"] and not result.converged
    assert result.largest == pytest.approx(0.5)


@pytest.mark.parametrize("bad", [-1.0, -5e-324, math.nan, math.inf, "1e-3", True, None])
def test_tolerance_rejects_bad_values(bad) -> None:
    with pytest.raises(ValueError, match=r"^tol \(Tolerance.rel\) must be a finite number >= 0, got "):
        Tolerance(bad, 0.0)
    with pytest.raises(ValueError, match=r"^res \(Tolerance.abs\) must be a finite number >= 0, got "):
        Tolerance(0.0, bad)


def test_tolerance_accepts_zero_large_and_integer_values_and_is_frozen() -> None:
    for rel, ab in [(0.0, 0.0), (1.0, 2.0), (1e300, 5e-324), (3, 0)]:
        tol = Tolerance(rel, ab)
        assert (tol.rel, tol.abs) == (rel, ab)
    with pytest.raises(dataclasses.FrozenInstanceError):
        tol.rel = 1.0  # type: ignore[misc]
    empty = check({}, {}, Tolerance(0.0, 0.0))
    assert empty.converged and empty.failing == [] and empty.largest == 0.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        empty.residuals = {}  # type: ignore[misc]


def satellite_like() -> tuple[list[str], list[Coupling], dict[SignalRef, int]]:
    """The paper's three subsims and couplings (spec §4.3/§5.1) with their sizes."""
    couplings = [
        Coupling.make("orbit.f", ["aero.force", "attitude.phi"], "linear", {"gains": [1, 1]}),
        Coupling.make("attitude.R", "orbit.R"),
        Coupling.make("attitude.torque", ["aero.torque", "aero.force"], "linear", {"gains": [1, 1]}),
        Coupling.make("aero.R_body", ["orbit.R", "attitude.phi"], "linear", {"gains": [1, 1]}),
        Coupling.make("aero.V_body", ["orbit.V", "attitude.phi"], "linear", {"gains": [1, 1]}),
    ]
    sizes = {c.target: 3 for c in couplings}
    return ["aero", "attitude", "orbit"], couplings, sizes


def test_derived_order_has_fewest_feedback_signals() -> None:
    names, couplings, sizes = satellite_like()
    order = derive_order(names, couplings, sizes)
    weight = feedback_weight(order, couplings, sizes)
    assert weight == 6  # the paper's 6 signals: aero force and torque (or an equivalent cut)
    assert weight == min(feedback_weight(p, couplings, sizes) for p in
                         [("orbit", "attitude", "aero"), ("aero", "orbit", "attitude"), ("attitude", "aero", "orbit")])
    assert feedback_weight(["orbit", "attitude", "aero"], couplings, sizes) == 6
    assert feedback_weight(["attitude", "orbit", "aero"], couplings, sizes) == 9


def test_given_order_decides_feedback_edges() -> None:
    handles = {n: InProcessHandle(Integrator(), n) for n in ("p", "q")}
    for h in handles.values():
        h.configure({})
    couplings = [Coupling.make("p.u", "q.y"), Coupling.make("q.u", "p.y")]
    c = Coordinator(handles, couplings, Settings(method="distributed", order=["q", "p"]))
    assert c.order == ["q", "p"] and [str(f) for f in c.feedback] == ["p.y -> q.u"]
    with pytest.raises(ValueError, match="every subsim"):
        Coordinator(handles, couplings, Settings(method="distributed", order=["q"]))


def test_first_guess_policies() -> None:
    prev_t = np.array([0.0, 0.5, 1.0])
    prev = {"s.u": (prev_t, np.column_stack([2 * prev_t, np.ones(3)]))}
    times = np.array([1.0, 1.5, 2.0])
    sizes = {"s.u": 2}
    np.testing.assert_array_equal(first_guess("zero", times, sizes, prev)["s.u"], np.zeros((3, 2)))
    np.testing.assert_array_equal(first_guess("hold", times, sizes, prev)["s.u"], [[2, 1]] * 3)
    np.testing.assert_allclose(first_guess("extrapolate", times, sizes, prev)["s.u"],
                               [[2, 1], [3, 1], [4, 1]], rtol=1e-15)
    np.testing.assert_array_equal(first_guess("extrapolate", times, sizes, None)["s.u"], np.zeros((3, 2)))
    with pytest.raises(ValueError, match=r"^unknown first-guess policy 'oracle'; known: zero, hold, extrapolate$"):
        first_guess("oracle", times, sizes, prev)
    # a signal the previous interval did not have starts at zero under every policy; the others keep theirs
    both = {"s.u": 2, "s.w": 1}
    for policy in ("zero", "hold", "extrapolate"):
        guess = first_guess(policy, times, both, prev)
        assert sorted(guess) == ["s.u", "s.w"]
        np.testing.assert_array_equal(guess["s.w"], np.zeros((3, 1)))
        assert guess["s.u"].shape == (3, 2) and (policy == "zero") == (not guess["s.u"].any())
    np.testing.assert_array_equal(first_guess("hold", times, sizes, {})["s.u"], np.zeros((3, 2)))
    # extrapolation uses the coupling's interpolation: a quadratic continued by the cubic scheme stays exact,
    # by the linear one it continues the last chord
    quad = {"s.u": (prev_t, np.column_stack([prev_t**2, prev_t]))}
    np.testing.assert_allclose(first_guess("extrapolate", times, sizes, quad, interp="cubic")["s.u"],
                               np.column_stack([times**2, times]), rtol=1e-14)
    np.testing.assert_allclose(first_guess("extrapolate", times, sizes, quad)["s.u"],
                               np.column_stack([1.0 + 1.5 * (times - 1.0), times]), rtol=1e-14)


@pytest.mark.parametrize(
    ("field", "value"),
    [("method", "jacobi"), ("interval", 0.0), ("samples", 1), ("first_guess", "x"), ("interp", "spline"),
     ("max_stages", 1), ("max_halvings", -1), ("tol", 1e-10), ("tolerances", {"a.x": 1e-10})],
)
def test_settings_reject_bad_values_naming_the_field(field: str, value) -> None:
    with pytest.raises(ValueError, match=field):
        Settings(**{field: value})


@pytest.mark.parametrize("method", ["centralized", "distributed"])
def test_taylor_stages_over_zenoh_equal_in_process_bit_for_bit(spawn_subsim, method: str) -> None:
    """Eq. 5 through real processes: same stage values, bit for bit, as in-process."""
    k, ndp, H = -1.7, 6, 0.9
    settings = Settings(method=method, interval=H, samples=ndp, first_guess="zero", interp="lagrange",
                        tol=Tolerance(1e-13, 1e-15))
    coupling = [Coupling.make("y.u", "y.y", "gain", {"k": k})]
    runs = []
    for handle in (InProcessHandle(Integrator(), "y"), spawn_subsim("subsims.integrator", name="y")):
        handle.configure({"y0": [2.0]})
        seen: list[np.ndarray] = []
        c = Coordinator({"y": handle}, coupling, settings,
                        on_stage=lambda n, out, seen=seen: seen.append(out["y"]["y"]))
        c.advance(0.0, H)
        runs.append(seen)
    t = c.sample_times(0.0, H)
    for n in range(ndp):
        taylor = 2.0 * sum((k * t) ** i / math.factorial(i) for i in range(n + 1))
        np.testing.assert_allclose(runs[1][n][:, 0], taylor, rtol=1e-12)
    assert len(runs[0]) == len(runs[1])
    assert all(a.tobytes() == b.tobytes() for a, b in zip(runs[0], runs[1]))


@pytest.mark.parametrize("method", ["centralized", "distributed"])
def test_run_sends_each_commit_with_the_next_interval_and_commits_all_at_the_end(method: str) -> None:
    """One request per subsim per stage, plus one final commit: no commit round trip per interval."""
    a, b = InProcessHandle(Integrator(), "a"), InProcessHandle(Integrator(), "b")
    for h in (a, b):
        h.configure({"y0": [1.0]})
    couplings = [Coupling.make("a.u", "b.y", "gain", {"k": -1.0}), Coupling.make("b.u", "a.y")]
    c = Coordinator({"a": a, "b": b}, couplings, Settings(method=method, interval=0.1, samples=3))
    stages: list[int] = []
    summary = c.run(0.0, 1.0, on_interval=lambda iv: stages.append(iv.stages))
    assert summary.intervals == 10 and summary.t_end == pytest.approx(1.0)
    for h in (a, b):
        status = h.status()
        assert status["time"] == summary.t_end and not status["has_trial"]
        # configure, describe, one run per stage, the final commit, and this status
        assert status["requests"] == 2 + sum(stages) + 1 + 1
    # the same run with a commit after every interval (advance) ends in the same committed state
    a2, b2 = InProcessHandle(Integrator(), "a"), InProcessHandle(Integrator(), "b")
    for h in (a2, b2):
        h.configure({"y0": [1.0]})
    c2 = Coordinator({"a": a2, "b": b2}, couplings, Settings(method=method, interval=0.1, samples=3))
    t = 0.0
    for k in range(10):
        t = float(c2.advance(t, (k + 1) * 0.1).t[-1])
    assert a2.get_state().state.tobytes() == a.get_state().state.tobytes()
    assert b2.get_state().state.tobytes() == b.get_state().state.tobytes()


class LoggedHandle(InProcessHandle):
    """An in-process integrator that logs when each run_interval is sent (a failing one from ``fail_at`` on)."""

    def __init__(self, name: str, log: list, fail_at: float = math.inf, polls: int = 0) -> None:
        super().__init__(Integrator(), name)
        self.log, self.fail_at = log, fail_at
        self.polls, self._unanswered = polls, 0  # replied() says no this many times after each send, as if busy

    def start_run_interval(self, times, inputs, interp="linear", commit=False):  # noqa: ANN001, ANN201
        self.log.append(("sent", self.name, float(times[0])))
        self._unanswered = self.polls
        if times[0] >= self.fail_at:
            raise RuntimeError(f"{self.name} fails at t = {times[0]}")
        return super().start_run_interval(times, inputs, interp, commit)

    def replied(self) -> bool:
        self._unanswered -= 1
        return self._unanswered < 0


def test_a_committed_interval_is_recorded_once_the_next_run_is_sent_and_none_is_lost_on_failure() -> None:
    log: list = []
    handles = {n: LoggedHandle(n, log) for n in ("a", "b")}
    for h in handles.values():
        h.configure({"y0": [1.0]})
    couplings = [Coupling.make("a.u", "b.y", "gain", {"k": -1.0}), Coupling.make("b.u", "a.y")]
    settings = Settings(method="centralized", interval=0.1, samples=3)
    c = Coordinator(handles, couplings, settings)
    c.run(0.0, 0.3, on_interval=lambda iv: log.append(("recorded", float(iv.t[0]))))
    recorded = [i for i, e in enumerate(log) if e[0] == "recorded"]
    assert [log[i][1] for i in recorded] == pytest.approx([0.0, 0.1, 0.2])  # each once, in order
    for i in recorded[:-1]:  # the next interval's first requests are already out (overlapping the writing)
        assert log[i - 1][0] == "sent" and log[i - 1][2] == pytest.approx(log[i][1] + 0.1)
    assert recorded[-1] == len(log) - 1  # the last one when the run ends
    # a run that fails in its third interval has still recorded the two it committed
    log.clear()
    handles = {n: LoggedHandle(n, log, fail_at=0.2 - 1e-9 if n == "b" else math.inf) for n in ("a", "b")}
    for h in handles.values():
        h.configure({"y0": [1.0]})
    with pytest.raises(RuntimeError, match="b fails"):
        Coordinator(handles, couplings, settings).run(0.0, 0.3, on_interval=lambda iv: log.append(
            ("recorded", float(iv.t[0]))))
    assert [e[1] for e in log if e[0] == "recorded"] == pytest.approx([0.0, 0.1])


def recorded_in_steps(handles: dict[str, LoggedHandle], log: list) -> tuple[Coordinator, Callable]:
    """RF-D over a and b side by side, then c, and an on_interval that records an interval in three steps, logged."""
    for h in handles.values():
        h.configure({"y0": [1.0]})
    couplings = [Coupling.make("a.u", "c.y", "gain", {"k": -1.0}), Coupling.make("b.u", "c.y"),
                 Coupling.make("c.u", "a.y")]
    settings = Settings(method="distributed", interval=0.1, samples=3, order=("a", "b", "c"))

    def record(iv: Interval):  # noqa: ANN202
        for k in range(3):
            log.append(("step", float(iv.t[0]), k))
            yield
        log.append(("recorded", float(iv.t[0])))

    return Coordinator(handles, couplings, settings), record


@pytest.mark.parametrize("cores", [1, 2, 3])
def test_an_interval_is_recorded_during_a_run_that_leaves_a_core_to_the_coordinator(monkeypatch, cores: int) -> None:
    """RF-D with a and b side by side, then c; every request looks busy for its first two looks (replied()).
    With 2 cores the run of c alone leaves one free: the writing goes there, in steps (it stops at the look
    that finds the replies), never during the run of a and b (which would share the cores three
    ways); with 3 cores already the run of a and b leaves one; with 1 none does, and the first run gets the
    interval whole. Each interval once, in order, never more than one behind."""
    import cosim.driver

    monkeypatch.setattr(cosim.driver, "CORES", cores)
    log: list = []
    coordinator, record = recorded_in_steps({n: LoggedHandle(n, log, polls=2) for n in ("a", "b", "c")}, log)
    coordinator.run(0.0, 0.4, on_interval=record)
    assert [e[1] for e in log if e[0] == "recorded"] == pytest.approx([0.0, 0.1, 0.2, 0.3])
    end = max(i for i, e in enumerate(log) if e[0] == "sent")  # after it, the run's end records what is left
    last_sent, steps_in_run = None, 0
    for i, e in enumerate(log[:end + 1]):
        if e[0] == "sent":
            last_sent, steps_in_run = e, 0
            # never more than one interval behind: those ending before the previous interval are recorded
            done = [r[1] for r in log[:i] if r[0] == "recorded"]
            assert all(any(d == pytest.approx(t0) for d in done) for t0 in np.arange(0.0, e[2] - 0.15, 0.1))
        elif e[0] == "step":
            steps_in_run += 1
            # the run it happens in, by the last request sent (a and b go in either order: the slower first)
            assert last_sent is not None and last_sent[1] in {1: "ab", 2: "c", 3: "ab"}[cores], (i, log[:i + 1])
            if cores > 1:  # the look that finds the replies ends the writing: two steps a busy request at most
                assert steps_in_run <= 2 * (cores - 1)  # the run of c, or of a and b
    if cores == 1:  # whole, right after the first run of the next interval is out
        for i, e in enumerate(log):
            if e[0] == "step" and e[2] == 0:
                assert [x[0] for x in log[i:i + 4]] == ["step", "step", "step", "recorded"]


def test_a_stop_while_an_interval_is_being_recorded_in_steps_still_records_it_whole() -> None:
    """A signal that stops the run between two steps of recording (here: while the coordinator looks for a
    reply) leaves the interval's steps where they were; the run's end finishes them, so every committed
    interval is recorded, in order, before the stop propagates."""
    log: list = []

    class Stopping(LoggedHandle):
        def replied(self) -> bool:
            if sum(e[0] == "step" for e in log) == 2 and not any(e[0] == "stop" for e in log):
                log.append(("stop",))
                raise KeyboardInterrupt
            return super().replied()

    handles = {n: (Stopping if n == "c" else LoggedHandle)(n, log, polls=3) for n in ("a", "b", "c")}
    coordinator, record = recorded_in_steps(handles, log)
    committed: list[float] = []
    with pytest.raises(KeyboardInterrupt):
        coordinator.run(0.0, 1.0, on_interval=lambda iv: (committed.append(float(iv.t[0])), record(iv))[1])
    stop = log.index(("stop",))
    assert [e[1] for e in log if e[0] == "recorded"] == pytest.approx(committed) and committed
    assert any(e[0] == "step" for e in log[stop:])  # the interrupted interval's steps were finished after the stop


def test_a_start_value_stands_in_for_the_zeros_of_every_policy() -> None:
    """[subsims.<name>.guess]: where no value is known (the first interval; every interval with 'zero') a signal
    starts at its given value; where one is known, the policy's value as before."""
    times = np.linspace(0.0, 1.0, 3)
    start = {"b.q": (1.0, 0.0)}
    previous = {"b.q": (np.linspace(-1.0, 0.0, 3), np.array([[0.5, 0.5], [0.6, 0.4], [0.7, 0.3]])),
                "b.r": (np.linspace(-1.0, 0.0, 3), np.ones((3, 1)))}
    for policy in POLICIES:
        first = first_guess(policy, times, {"b.q": 2, "b.r": 1}, None, "linear", start)
        assert first["b.q"].tolist() == [[1.0, 0.0]] * 3 and first["b.r"].tolist() == [[0.0]] * 3
        later = first_guess(policy, times, {"b.q": 2, "b.r": 1}, previous, "linear", start)
        if policy == "zero":
            assert later["b.q"].tolist() == [[1.0, 0.0]] * 3 and later["b.r"].tolist() == [[0.0]] * 3
        else:
            assert later["b.q"][0].tolist() == [0.7, 0.3] and later["b.r"].tolist() == [[1.0]] * 3
