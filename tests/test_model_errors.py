"""A bug in a user's model is reported as its own error code, with the model's own traceback (file and line)
under a one-line summary; nothing committed changes. Runs the CLI as a process, over Zenoh and in-process."""

from __future__ import annotations

import functools
import subprocess
import sys
from collections import deque
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from cosim import Port, Subsim, check_pure
from cosim.contract import SubsimError
from cosim.handles import InProcessHandle
from cosim.runtime import Runtime

BUGGY = '''
import numpy as np
from cosim import Port, Subsim


class Buggy(Subsim):
    inputs = {"u": Port(1)}
    outputs = {"x": Port(1)}

    def initial_state(self, params):
        if params.get("crash_at_start"):
            return np.array([1.0 / (int(params["crash_at_start"]) - 1)])  # a bug: Python float division by zero
        return np.array([1.0])

    def advance(self, state, times, u):
        out = [state.copy()]
        x = state.copy()
        for t in times[1:]:
            x = x + helper(t)
            out.append(x.copy())
        return {"x": np.array(out)}, x


def helper(t):
    if t > 0.15:
        raise ZeroDivisionError("the model divided by zero")
    return np.zeros(1)
'''

SCENARIO = '''
stop = 0.4
[coupling]
method = "distributed"
interval = 0.1
samples = 3
[subsims.a]
model = "buggy:Buggy"
params = {}
[subsims.b]
model = "buggy:Buggy"
[[couplings]]
to = "a.u"
from = "b.x"
[[couplings]]
to = "b.u"
from = "a.x"
'''


@pytest.fixture
def project(tmp_path: Path) -> Path:
    (tmp_path / "buggy.py").write_text(BUGGY)
    (tmp_path / "s.toml").write_text(SCENARIO)
    return tmp_path


@pytest.mark.parametrize("where", ["zenoh", "inprocess"])
def test_a_model_exception_shows_its_own_traceback_under_one_line(project: Path, where: str) -> None:
    cmd = [sys.executable, "-m", "cosim.cli", "run", "s.toml", "--quiet", "--restarts", "0",
           *(["--inprocess"] if where == "inprocess" else [])]
    done = subprocess.run(cmd, cwd=project, capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    lines = done.stderr.strip().splitlines()  # (launched subsims also say on stderr when they start and stop)
    at = next(i for i, line in enumerate(lines) if line.startswith("cosim: run stopped"))
    first, rest = lines[at], lines[at + 1:]
    assert first.startswith("cosim: run stopped: a.run_interval: [model_exception] advance() raised ZeroDivisionError")
    assert "the model divided by zero (buggy.py:" in first and " in helper)" in first  # where, in the one line
    text = "\n".join(rest)
    assert "Traceback" not in first and "the model's traceback (in subsim 'a')" in text
    assert f'File "{project / "buggy.py"}", line' in text and "in helper" in text and "in advance" in text
    assert "cosim/runtime.py" not in text  # the model's frames, not the framework's


def test_an_exception_in_initial_state_names_the_params_key_and_shows_the_traceback(project: Path) -> None:
    (project / "s.toml").write_text(SCENARIO.replace("params = {}", "params = { crash_at_start = 1 }"))
    done = subprocess.run([sys.executable, "-m", "cosim.cli", "run", "s.toml", "--inprocess", "--quiet"],
                          cwd=project, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert "[subsims.a.params] initial_state() raised ZeroDivisionError" in done.stderr
    assert f'File "{project / "buggy.py"}", line' in done.stderr and "in initial_state" in done.stderr


def test_a_model_exception_changes_nothing_committed(project: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(project))
    from buggy import Buggy

    h = InProcessHandle(Buggy(), "a")
    h.configure({})
    before = h.get_state()
    with pytest.raises(SubsimError) as err:
        h.run_interval(np.linspace(0.0, 0.3, 4), {"u": np.zeros((4, 1))})
    assert err.value.code == "model_exception" and "in helper" in err.value.traceback
    after = h.get_state()
    assert (after.time, after.state.tobytes()) == (before.time, before.state.tobytes())
    assert h.status()["has_trial"] is False


class _BuildsTwice(Subsim):
    """Its constructor works for the runtime and the first configure, then raises (a model's bug)."""

    inputs = {"u": Port(1)}
    outputs = {"x": Port(1)}
    built = 0

    def __init__(self) -> None:
        type(self).built += 1
        if type(self).built > 2:
            raise RuntimeError("out of licences")

    def initial_state(self, params: dict) -> np.ndarray:
        return np.array([float(params.get("x0", 1.0))])

    def advance(self, state: np.ndarray, times: np.ndarray, u: Callable) -> tuple[dict, np.ndarray]:
        return {"x": np.tile(state, (times.size, 1))}, state


def test_an_exception_in_the_constructor_at_configure_is_the_models_and_changes_nothing() -> None:
    _BuildsTwice.built = 0
    h = InProcessHandle(Runtime(_BuildsTwice), "a")
    h.configure({"x0": 3.0})
    with pytest.raises(SubsimError) as err:
        h.configure({"x0": 5.0})
    assert err.value.code == "model_exception"
    assert "_BuildsTwice() raised RuntimeError: out of licences" in err.value.message
    assert "in __init__" in err.value.traceback
    state = h.get_state()
    assert (state.time, state.state.tolist()) == (0.0, [3.0])


class _Drifting(Subsim):
    """A newcomer's model: the wheel momentum kept on ``self`` instead of in the state vector. Every stage and every
    replay integrates it again (a coupled run's results were 3x off, exit 0)."""

    inputs = {"u": Port(1)}
    outputs = {"h": Port(1)}

    def __init__(self) -> None:
        self.h = 0.0

    def initial_state(self, params):
        return np.zeros(1)

    def advance(self, state, times, u):
        self.h = self.h + float(times[-1] - times[0])
        return {"h": np.full((times.size, 1), self.h)}, state


class _Lagging(Subsim):
    """Keeps an array attribute and writes into it in place (the same mistake, an ndarray)."""

    inputs = {"u": Port(1)}
    outputs = {"x": Port(1)}

    def __init__(self) -> None:
        self.last = np.zeros(1)

    def initial_state(self, params):
        return np.zeros(1)

    def advance(self, state, times, u):
        self.last[0] = times[-1]
        return {"x": np.zeros((times.size, 1))}, state


class _Cached(Subsim):
    """Builds a cache in its constructor and only reads it in advance: pure, and not refused."""

    inputs = {"u": Port(1)}
    outputs = {"x": Port(1)}

    def __init__(self) -> None:
        self.table = np.arange(3.0)

    def initial_state(self, params):
        return np.zeros(1)

    def advance(self, state, times, u):
        return {"x": np.full((times.size, 1), self.table[1])}, state


class _Counting(_Cached):
    """Counts its calls in a dict made in initial_state, changed in place (the newcomer probe's model, whose state
    changed after 50 calls: the check compared the dict with itself)."""

    def initial_state(self, params):
        self.calls = {"n": 0}
        return np.zeros(1)

    def advance(self, state, times, u):
        self.calls["n"] += 1
        return super().advance(state, times, u)


class _Appending(_Cached):
    """Appends to a list inside a list it keeps."""

    def __init__(self) -> None:
        super().__init__()
        self.history = [[]]

    def advance(self, state, times, u):
        self.history[0].append(float(times[-1]))
        return super().advance(state, times, u)


class _Queued(_Cached):
    """Keeps the last inputs in a deque (any list, dict or set subclass is looked into too)."""

    def __init__(self) -> None:
        super().__init__()
        self.recent: deque = deque(maxlen=3)

    def advance(self, state, times, u):
        self.recent.append(float(times[-1]))
        return super().advance(state, times, u)


class _DictHistory(_Cached):
    """Keeps a history in a dict, one new key a call, and reads it back: a hidden integrator (a red team found a
    rule letting dicts grow, for caches, let it run)."""

    def __init__(self) -> None:
        super().__init__()
        self.seen: dict[int, int] = {}

    def advance(self, state, times, u):
        self.seen[len(self.seen)] = self.seen.get(len(self.seen) - 1, 0) + 1
        return super().advance(state, times, u)


class _TableAndCounter(_Counting):
    """A big read-only table before the counter: it used up the items looked into, for every attribute after it."""

    def __init__(self) -> None:
        super().__init__()
        self.lookup = [[float(i), 2.0 * i] for i in range(40_000)]


@pytest.mark.parametrize(("model", "name"), [(_Drifting, "h"), (_Lagging, "last"), (_Counting, "calls"),
                                             (_Appending, "history"), (_Queued, "recent"), (_DictHistory, "seen"),
                                             (_TableAndCounter, "calls")])
def test_a_model_that_keeps_run_state_in_its_attributes_is_refused_by_name(model: type[Subsim], name: str) -> None:
    h = InProcessHandle(model(), "m")
    h.configure({})
    t = np.linspace(0.0, 0.4, 3)
    with pytest.raises(SubsimError) as err:
        h.run_interval(t, {"u": np.zeros((3, 1))})
    assert err.value.code == "model_error", err.value
    assert f"advance() changed the model's attribute(s) ['{name}'] (over t in [0, 0.4]): what evolves belongs in the " \
           "state vector" in str(err.value)
    assert h.status()["time"] == 0.0  # nothing committed


class _Rebinding(_Cached):
    """Binds its attributes again to equal values (a fresh float, a fresh tuple): pure, as check_pure agrees (the
    runtime refused it, comparing by identity; red team)."""

    def __init__(self) -> None:
        super().__init__()
        self.k, self.shape = 2.0, (2,)

    def advance(self, state, times, u):
        self.k, self.shape = float(self.k) * 1.0, tuple([2])
        return super().advance(state, times, u)


class _Holding(_Cached):
    """Keeps containers it only reads, one holding a helper object and a NaN, and a list nested 600 deep (a red team
    found the runtime's recursion end in a RecursionError there), and binds a NumPy number and a NaN anew: pure."""

    def __init__(self) -> None:
        super().__init__()
        self.parts = {"helper": object(), "limits": [float("nan"), 1.0], "table": np.arange(4.0)}
        self.k, self.nan = np.int64(3), float("nan")
        self.stamps = np.array(["2020-01-01"], dtype="datetime64[s]")  # (no buffer of its own: it crashed a run)

    def initial_state(self, params):
        nested = None
        for i in range(600):
            nested = (float(i), nested)
        self.nested = nested
        return super().initial_state(params)

    def advance(self, state, times, u):
        self.k, self.nan = np.int64(3), float("nan")
        return super().advance(state, times, u)


class _Memo(_Cached):
    """Fills a cache of pure results as advance needs them, declared as one."""

    caches = ("factors",)

    def __init__(self) -> None:
        super().__init__()
        self.factors: dict[float, float] = {}

    def advance(self, state, times, u):
        self.factors.setdefault(round(float(times[-1] - times[0]), 12), 1.0)
        return super().advance(state, times, u)


@pytest.mark.parametrize("model", [_Cached, _Rebinding, _Holding, _Memo])
def test_a_model_that_only_reads_its_attributes_runs(model: type[Subsim]) -> None:
    check_pure(model(), {}, np.linspace(0.0, 0.4, 3), {"u": np.zeros((3, 1))})
    h = InProcessHandle(model(), "m")
    h.configure({})
    for i in range(5):
        out = h.run_interval(np.linspace(0.4 * i, 0.4 * (i + 1), 3), {"u": np.zeros((3, 1))}, commit=i > 0)
        assert out.outputs["x"][0, 0] == 1.0


class _InPlace(Subsim):
    """Changes the state it is given in place: numpy says 'output array is read-only', and nothing else."""

    inputs = {"u": Port(1)}
    outputs = {"x": Port(1)}

    def initial_state(self, params):
        return np.zeros(1)

    def advance(self, state, times, u):
        x = state
        x += 1.0
        return {"x": np.zeros((times.size, 1))}, x


def test_a_write_into_the_state_given_says_to_change_a_copy() -> None:
    h = InProcessHandle(_InPlace(), "m")
    h.configure({})
    with pytest.raises(SubsimError) as err:
        h.run_interval(np.linspace(0.0, 0.4, 3), {"u": np.zeros((3, 1))})
    assert err.value.code == "model_exception"
    assert str(err.value).endswith("the state and inputs advance() is given are read-only; change a copy "
                                   "(x = state.copy())"), err.value


class _LegacyPanel:
    """A stand-alone simulation as engineering code has it: a class whose step() changes its own attributes."""

    def __init__(self, temperature: float) -> None:
        self.temperature = temperature

    def step(self, dt: float, power: float) -> None:
        self.temperature += dt * (power - 0.1 * self.temperature)


class _SteppedHelper(Subsim):
    """The natural wrapper of it (a legacy-code probe): the helper object is made in initial_state and stepped in
    advance. The attribute check looks at the helper as itself (it may be reloaded from the state, which is right),
    so a coupled run went on with results 7 K off."""

    inputs = {"power": Port(1)}
    outputs = {"T": Port(1)}

    def initial_state(self, params):
        self.panel = _LegacyPanel(20.0)
        return np.array([20.0])

    def advance(self, state, times, u):
        out = [self.panel.temperature]
        for t0, t1 in zip(times[:-1], times[1:]):
            self.panel.step(float(t1 - t0), float(u(t0)["power"][0]))
            out.append(self.panel.temperature)
        return {"T": np.array(out)}, np.array([self.panel.temperature])


class _ReloadedHelper(_SteppedHelper):
    """The right wrapper: the helper object is set from the state at each call, and stepped."""

    def advance(self, state, times, u):
        self.panel.temperature = float(state[0])
        return super().advance(state, times, u)


_STEPS = {"count": 0}  # a module-level variable a model steps


class _ModuleCounter(_Cached):
    def advance(self, state, times, u):
        _STEPS["count"] += 1
        return {"x": np.full((times.size, 1), float(_STEPS["count"]))}, state


class _LateLatch(_Cached):
    """A mode flag on self that latches once a level is passed, late in the run (a legacy-code probe: the attribute
    check looked at the first three runs only, and the run went on with the flag carried across rollbacks)."""

    def initial_state(self, params):
        self.saturated = False
        return np.zeros(1)

    def advance(self, state, times, u):
        if times[-1] > 4.0:
            self.saturated = True
        return {"x": np.full((times.size, 1), 2.0 if self.saturated else 1.0)}, state


@pytest.mark.parametrize("model", [_SteppedHelper, _ModuleCounter])
def test_a_model_keeping_state_outside_its_attributes_is_refused_at_its_first_run(model: type[Subsim]) -> None:
    h = InProcessHandle(model(), "m")
    h.configure({})
    port = next(iter(model.inputs))
    with pytest.raises(SubsimError) as err:
        h.run_interval(np.linspace(0.0, 0.4, 3), {port: np.ones((3, 1))})
    assert err.value.code == "model_error", err.value
    assert ("advance() gave other outputs when called again on the same state, times and inputs (over t in [0, 0.4], "
            "the first run after configure, made twice to check that it gives the same outputs): it keeps something "
            "between calls outside the state vector (a helper object it steps, a module-level variable") \
        in str(err.value), err.value
    assert h.status()["time"] == 0.0 and not h.status()["has_trial"]  # nothing committed, no trial to commit


def test_a_helper_object_set_from_the_state_at_each_call_runs() -> None:
    h = InProcessHandle(_ReloadedHelper(), "m")
    h.configure({})
    for i in range(40):  # past the runs whose attributes are compared
        out = h.run_interval(np.linspace(0.4 * i, 0.4 * (i + 1), 3), {"power": np.ones((3, 1))}, commit=i > 0)
    assert out.outputs["T"][-1, 0] < 20.0  # cooling towards power / 0.1 = 10


def test_an_attribute_that_changes_late_in_the_run_is_found_at_a_later_look() -> None:
    h = InProcessHandle(_LateLatch(), "m")
    h.configure({})
    with pytest.raises(SubsimError) as err:
        for i in range(40):
            h.run_interval(np.linspace(0.4 * i, 0.4 * (i + 1), 3), {"u": np.zeros((3, 1))}, commit=i > 0)
    assert i == 15  # the 16th run looks again (the flag latched in the 11th, over [4, 4.4])
    assert str(err.value).startswith("m.run_interval: [model_error] advance() changed the model's attribute(s) "
                                     "['saturated'] (found over t in [6, 6.4], in one of the runs since the look at "
                                     "t = 1.2): what evolves belongs in the state vector"), err.value


class _OnlyOnce(_SteppedHelper):
    """A legacy object that refuses to step back to a time it has passed: only the repeated call fails."""

    def advance(self, state, times, u):
        if self.panel.temperature != 20.0:
            raise RuntimeError("cannot step backwards")
        return super().advance(state, times, u)


def test_a_failure_of_the_repeated_first_run_says_it_was_the_repeat() -> None:
    h = InProcessHandle(_OnlyOnce(), "m")
    h.configure({})
    with pytest.raises(SubsimError) as err:
        h.run_interval(np.linspace(0.0, 0.4, 3), {"power": np.ones((3, 1))})
    assert str(err.value).startswith("m.run_interval: [model_exception] advance() called again on the same state, "
                                     "times and inputs (over t in [0, 0.4], the first run after configure, made twice "
                                     "to check that it gives the same outputs) failed: advance() raised RuntimeError: "
                                     "cannot step backwards"), err.value


def test_a_slow_first_run_is_not_made_twice(monkeypatch: pytest.MonkeyPatch) -> None:
    """Its doubled time would eat into the first requests' deadline (a review): above RERUN_LIMIT it runs once."""
    import cosim.runtime as runtime

    monkeypatch.setattr(runtime, "RERUN_LIMIT", -1.0)  # every first run counts as slow
    h = InProcessHandle(_SteppedHelper(), "m")
    h.configure({})
    h.run_interval(np.linspace(0.0, 0.4, 3), {"power": np.ones((3, 1))})  # not repeated: not refused


class _BigTable(_Cached):
    """Reads a large table it keeps: pure, but each look at its attributes digests 8 MB."""

    def __init__(self) -> None:
        super().__init__()
        self.big = np.arange(1_000_000.0)


def test_looks_at_large_attributes_grow_rarer_and_keep_a_digest(monkeypatch: pytest.MonkeyPatch) -> None:
    """A model with a 61 MiB table paid 68 ms every 16th run and held a second copy of it for the run (a review)."""
    import cosim.runtime as runtime

    rt = runtime.Runtime(_BigTable(), "m")
    rt.configure({})
    kept = rt._configured_marks["big"]
    assert kept[0] == "array" and len(kept[3]) < 100  # a digest, not 8 MB of bytes
    monkeypatch.setattr(runtime, "WATCH_SHARE", 0.0)  # every look costs too much: the period doubles each time
    looks = []
    watch = rt._watch_attributes
    monkeypatch.setattr(rt, "_watch_attributes", lambda times: (looks.append(rt._runs), watch(times)))
    for i in range(200):
        rt.run_interval(np.linspace(0.4 * i, 0.4 * (i + 1), 3), {"u": np.zeros((3, 1))}, commit=i > 0)
    assert looks == [1, 2, 3, 16, 48, 112], looks


class _LazyTable(_Cached):
    """A functools.cached_property reached first late in the run: computed once from the instance, a cache."""

    @functools.cached_property
    def doubled(self) -> float:
        return 2.0 * float(self.table[1])

    def advance(self, state, times, u):
        value = self.doubled if times[0] > 8.0 else 1.0
        return {"x": np.full((times.size, 1), value)}, state


def test_a_cached_property_filled_late_is_no_changed_attribute() -> None:
    h = InProcessHandle(_LazyTable(), "m")
    h.configure({})
    for i in range(40):  # past the look at the 32nd run
        out = h.run_interval(np.linspace(0.4 * i, 0.4 * (i + 1), 3), {"u": np.zeros((3, 1))}, commit=i > 0)
    assert out.outputs["x"][0, 0] == 2.0
