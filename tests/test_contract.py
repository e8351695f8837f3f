"""The subsim contract (commit/rollback/state semantics, bad input), same body for both handles."""

from __future__ import annotations

import numpy as np
import pytest

from cosim.contract import SubsimError
from cosim.handles import InProcessHandle, SubsimHandle
from cosim.subsim import Port, Subsim
from subsims.integrator.subsim import Integrator

N = 5
TIMES = np.linspace(0.0, 0.4, N)


@pytest.fixture(params=["inprocess", pytest.param("remote", marks=pytest.mark.zenoh)])
def handle(request: pytest.FixtureRequest) -> SubsimHandle:
    if request.param == "inprocess":
        h = InProcessHandle(Integrator(), name="integ")
    else:
        h = request.getfixturevalue("spawn_subsim")("subsims.integrator", name="integ")
    h.configure({"size": 2, "y0": [1.0, -2.0]})
    return h


def ramp(t: np.ndarray) -> dict[str, np.ndarray]:
    return {"u": np.column_stack([np.ones_like(t), t])}


def committed(h: SubsimHandle) -> tuple[float, bytes]:
    s = h.get_state()
    return s.time, s.state.tobytes()


def test_describe_reports_ports(handle: SubsimHandle) -> None:
    d = handle.describe()
    assert d.name == "integ" and d.configured and d.time == 0.0
    assert {k: p.size for k, p in d.inputs.items()} == {"u": 2}
    assert {k: p.size for k, p in d.outputs.items()} == {"y": 2}
    assert d.protocol == 1 and not d.algebraic


def test_run_interval_changes_nothing_committed_and_is_deterministic(handle: SubsimHandle) -> None:
    before = committed(handle)
    a = handle.run_interval(TIMES, ramp(TIMES))
    b = handle.run_interval(TIMES, ramp(TIMES))
    assert committed(handle) == before
    assert a.outputs["y"].tobytes() == b.outputs["y"].tobytes()
    assert a.end_time == 0.4
    # y' = (1, t) from y0 = (1, -2): y = (1 + t, -2 + t^2/2), exact for the linear interpolant
    np.testing.assert_allclose(a.outputs["y"], np.column_stack([1 + TIMES, -2 + TIMES**2 / 2]), rtol=0, atol=1e-15)


def test_commit_promotes_latest_trial(handle: SubsimHandle) -> None:
    handle.run_interval(TIMES, {"u": np.zeros((N, 2))})
    last = handle.run_interval(TIMES, ramp(TIMES))
    assert handle.commit() == 0.4
    state = handle.get_state()
    assert state.time == 0.4
    assert state.state.tobytes() == last.outputs["y"][-1].tobytes()
    with pytest.raises(SubsimError) as err:
        handle.commit()
    assert err.value.code == "no_trial" and err.value.subsim == "integ" and err.value.command == "commit"


def test_run_interval_with_commit_equals_commit_then_run_interval(handle: SubsimHandle) -> None:
    first = handle.run_interval(TIMES, ramp(TIMES))
    nxt = TIMES + 0.4
    with pytest.raises(SubsimError) as err:  # the grid must start where the trial to commit ends
        handle.run_interval(TIMES, ramp(TIMES), commit=True)
    assert err.value.code == "time_mismatch" and "trial to commit ends" in err.value.message
    assert committed(handle)[0] == 0.0
    second = handle.run_interval(nxt, ramp(nxt), commit=True)
    state = handle.get_state()
    assert state.time == 0.4 and state.state.tobytes() == first.outputs["y"][-1].tobytes()
    assert handle.commit() == 0.8  # the new trial is the one left to commit
    assert handle.get_state().state.tobytes() == second.outputs["y"][-1].tobytes()
    # the same two intervals with separate commits give the same bytes
    handle.rollback(to_time=0.0)
    handle.run_interval(TIMES, ramp(TIMES))
    handle.commit()
    assert handle.run_interval(nxt, ramp(nxt)).outputs["y"].tobytes() == second.outputs["y"].tobytes()


def test_run_interval_with_commit_and_no_trial_or_a_failed_run_commits_nothing(handle: SubsimHandle) -> None:
    with pytest.raises(SubsimError) as err:
        handle.run_interval(TIMES, ramp(TIMES), commit=True)
    assert err.value.code == "no_trial" and err.value.command == "run_interval"
    trial = handle.run_interval(TIMES, ramp(TIMES))
    nxt = TIMES + 0.4
    with pytest.raises(SubsimError) as err:
        handle.run_interval(nxt, {"u": np.full((N, 2), np.nan)}, commit=True)
    assert err.value.code == "bad_value"
    assert committed(handle) == (0.0, np.array([1.0, -2.0]).tobytes())
    assert handle.commit() == 0.4  # the trial survived the failed request
    assert handle.get_state().state.tobytes() == trial.outputs["y"][-1].tobytes()


def test_commit_of_a_trial_made_stale_by_set_state_is_refused(handle: SubsimHandle) -> None:
    snapshot = handle.get_state()
    handle.run_interval(TIMES, ramp(TIMES))
    handle.set_state(snapshot)
    with pytest.raises(SubsimError) as err:
        handle.commit()
    assert err.value.code == "stale_trial"
    assert committed(handle) == (snapshot.time, snapshot.state.tobytes())


def test_rollback_discards_trial_and_returns_to_earlier_committed_time(handle: SubsimHandle) -> None:
    states, start = [], 0.0
    for _ in range(3):
        t = start + TIMES
        handle.run_interval(t, ramp(t))
        start = handle.commit()
        states.append(committed(handle))
    handle.run_interval(start + TIMES, ramp(start + TIMES))
    assert handle.rollback() == start
    with pytest.raises(SubsimError) as err:
        handle.commit()
    assert err.value.code == "no_trial"
    assert handle.rollback(to_time=states[0][0]) == states[0][0]
    assert committed(handle) == states[0]
    with pytest.raises(SubsimError) as err:
        handle.rollback(to_time=states[1][0])  # later than the committed time: gone from history
    assert err.value.code == "not_in_history"
    assert committed(handle) == states[0]


def test_get_and_set_state_round_trip_exactly(handle: SubsimHandle) -> None:
    odd = np.array([np.nextafter(1.0, 2.0), -0.0])
    handle.set_state(type(handle.get_state())(time=0.0, state=odd, model=""))
    got = handle.get_state()
    assert got.time == 0.0 and got.state.tobytes() == odd.tobytes()
    assert got.model.endswith("Integrator")


BAD_REQUESTS = {
    "wrong_input_size": lambda h: h.run_interval(TIMES, {"u": np.zeros((N, 3))}),
    "wrong_sample_count": lambda h: h.run_interval(TIMES, {"u": np.zeros((N - 1, 2))}),
    "nan_input": lambda h: h.run_interval(TIMES, {"u": np.full((N, 2), np.nan)}),
    "inf_time": lambda h: h.run_interval(np.array([0.0, np.inf]), {"u": np.zeros((2, 2))}),
    "time_not_increasing": lambda h: h.run_interval(TIMES[::-1].copy(), {"u": np.zeros((N, 2))}),
    "start_not_committed_time": lambda h: h.run_interval(TIMES + 1.0, {"u": np.zeros((N, 2))}),
    "missing_input": lambda h: h.run_interval(TIMES, {}),
    "unknown_input": lambda h: h.run_interval(TIMES, {"u": np.zeros((N, 2)), "w": np.zeros((N, 1))}),
    "unknown_scheme": lambda h: h.run_interval(TIMES, {"u": np.zeros((N, 2))}, interp="spline9"),
    "unknown_field": lambda h: h._call("commit", force=True),
    "set_state_wrong_size": lambda h: h._call("set_state", time=0.0, state=np.zeros(3)),
    "set_state_nan": lambda h: h._call("set_state", time=0.0, state=np.array([np.nan, 0.0])),
    "configure_bad_param": lambda h: h.configure({"size": 2, "y0": [1.0]}),
}


@pytest.mark.parametrize("bad", list(BAD_REQUESTS))
def test_bad_request_gets_error_and_leaves_committed_state_untouched(handle: SubsimHandle, bad: str) -> None:
    handle.run_interval(TIMES, ramp(TIMES))
    handle.commit()
    before = committed(handle)
    good = handle.run_interval(TIMES + 0.4, ramp(TIMES + 0.4))
    with pytest.raises(SubsimError) as err:
        BAD_REQUESTS[bad](handle)
    assert err.value.subsim == "integ" and err.value.code in {"bad_value", "bad_request", "time_mismatch"}
    assert err.value.message
    assert committed(handle) == before
    # the subsim still serves, and the earlier good trial is still the one a commit promotes
    assert handle.status()["configured"]
    assert handle.commit() == 0.8
    assert handle.get_state().state.tobytes() == good.outputs["y"][-1].tobytes()


def test_commands_before_configure_are_refused() -> None:
    h = InProcessHandle(Integrator())
    with pytest.raises(SubsimError) as err:
        h.run_interval(TIMES, {"u": np.zeros((N, 1))})
    assert err.value.code == "not_configured"


@pytest.mark.parametrize(("end_state", "code"), [(np.zeros(3), "model_error"), (np.array([np.nan, 0.0]), "model_error"),
                                                 ("garbage", "model_error")])
def test_a_bad_end_state_from_the_model_is_not_the_callers_fault(end_state, code: str) -> None:
    class Broken(Integrator):
        def advance(self, state, times, u):
            outputs, _ = super().advance(state, times, u)
            return outputs, end_state

    h = InProcessHandle(Broken(), name="broken")
    h.configure({"size": 2})
    before = committed(h)
    with pytest.raises(SubsimError) as err:
        h.run_interval(TIMES, ramp(TIMES))
    assert err.value.code == code and "the end state advance() returned over t in [0, " in err.value.message
    assert committed(h) == before
    with pytest.raises(SubsimError, match="no_trial|commit without"):
        h.commit()


@pytest.mark.parametrize(("result", "message"), [
    (lambda n, out, end: ({}, end), "advance() did not return output 'y'"),
    (lambda n, out, end: ({"y": np.zeros((n - 1, 2))}, end),
     f"advance() output 'y' has shape ({N - 1}, 2), expected ({N}, 2)"),
    (lambda n, out, end: ([np.zeros((n, 2))], end), "advance() must return a map of outputs, got list"),
    (lambda n, out, end: ({"y": np.r_[np.zeros((n - 1, 2)), [[0.0, np.nan]]]}, end),
     f"output 'y' is not finite at t = {float(TIMES[-1])!r}"),
    # the end state forgotten: it read as the model raising 'not enough values to unpack', or as outputs that are
    # not a map (a dict's keys unpacked)
    (lambda n, out, end: out, "advance() must return (outputs, end_state), got dict"),
    (lambda n, out, end: (out,), "advance() must return (outputs, end_state), got a tuple of 1"),
    (lambda n, out, end: [out, end], "advance() must return (outputs, end_state), got list"),
    # these were a bare ValueError in one process and [internal] over Zenoh, a complex value lost its imaginary part
    # with only a ComplexWarning, an undeclared output was dropped without a word (a probe, as a library user)
    (lambda n, out, end: ({"y": [[0.0, 1.0]] * (n - 1) + [[0.0]]}, end),
     "advance() output 'y' is not an array of numbers (ValueError: ..."),  # (then NumPy's own words)
    (lambda n, out, end: ({"y": out["y"] + 1j}, end), "advance() output 'y' is complex (complex128): outputs are real"),
    (lambda n, out, end: (out, end + 0j), f"the end state advance() returned over t in [0, {TIMES[-1]:g}] is complex "
     "(complex128): a state is real numbers"),
    (lambda n, out, end: (out, None), "the end state advance() returned over t in [0, 0.4] is None: a state is a 1-D "
     "array of floats (return it)"),
    (lambda n, out, end: ({**out, "yy": out["y"]}, end),
     "advance() returned undeclared output(s) ['yy']; this subsim declares: y(2)"),
    (lambda n, out, end: ({"z": out["y"]}, end), "advance() did not return output 'y' (it returned 'z' instead)"),
])
def test_a_result_that_breaks_the_contract_is_the_models_error_and_changes_nothing(result, message: str) -> None:
    """Not ``internal`` (which reads as a fault of cosim's): the model's, naming what was wrong."""
    class Broken(Integrator):
        def advance(self, state, times, u):
            return result(times.size, *super().advance(state, times, u))

    h = InProcessHandle(Broken(), name="broken")
    h.configure({"size": 2})
    before = committed(h)
    with pytest.raises(SubsimError) as err:
        h.run_interval(TIMES, ramp(TIMES))
    assert err.value.code == "model_error"
    assert err.value.message.startswith(message[:-3]) if message.endswith("...") else err.value.message == message
    assert committed(h) == before


def test_outputs_a_model_hands_back_in_the_same_buffer_every_call_stay_what_that_run_gave() -> None:
    """A model writing its outputs into one scratch array: in one process the caller (the coupler, keeping each
    stage's outputs) held that array, and the next run rewrote what it held; centralized runs then "converged"
    on a 0.9-wrong answer, where over Zenoh (outputs copied onto the wire) they were right (a probe)."""
    scratch = np.zeros((N, 2))

    class Reusing(Integrator):
        def advance(self, state, times, u):
            outputs, end = super().advance(state, times, u)
            scratch[...] = outputs["y"]
            return {"y": scratch}, end

    h = InProcessHandle(Reusing(), name="reusing")
    h.configure({"size": 2})
    first = h.run_interval(TIMES, ramp(TIMES)).outputs["y"]
    kept = first.copy()
    h.run_interval(TIMES, {"u": 10.0 * ramp(TIMES)["u"]})
    assert first.tobytes() == kept.tobytes()


def test_advance_in_one_process_gets_times_it_cannot_change_as_over_zenoh() -> None:
    """``times -= times[0]`` in advance(): over Zenoh a clear read-only error; in one process it changed the
    caller's own array (the coupler's), and the run failed later blaming another subsim's time (a probe)."""
    class Shifting(Integrator):
        def advance(self, state, times, u):
            times -= times[0]
            return super().advance(state, times, u)

    h = InProcessHandle(Shifting(), name="shifting")
    h.configure({"size": 2})
    t = TIMES.copy()
    with pytest.raises(SubsimError) as err:
        h.run_interval(t, ramp(t))
    assert err.value.code == "model_exception" and "read-only" in err.value.message
    assert t.tobytes() == TIMES.tobytes()


def test_times_rewritten_in_place_between_requests_are_checked_and_run_on_anew() -> None:
    """The runtime keeps the latest request's checked times for the next stage's (the same grid): the caller's
    array rewritten in place, or the same bytes in another shape, are checked anew, not served from what it kept."""
    seen = []

    class Recording(Integrator):
        def advance(self, state, times, u):
            seen.append(times.tobytes())
            return super().advance(state, times, u)

    h = InProcessHandle(Recording(), name="recording")
    h.configure({"size": 2})
    t = TIMES.copy()
    h.run_interval(t, ramp(t))
    t[1:] = [0.05, 0.1, 0.3, 0.5]  # another grid from the same start, in the same array
    got = h.run_interval(t, ramp(t))
    assert got.t.tobytes() == seen[-1] == t.tobytes() and got.end_time == 0.5
    with pytest.raises(SubsimError) as err:  # the bytes of the grid kept
        h.run_interval(t.reshape(-1, 1), ramp(t))
    assert (err.value.code, err.value.message) == ("bad_value", "t must be a non-empty 1-D array, got shape (5, 1)")
    t[2] = t[1]
    with pytest.raises(SubsimError) as err:
        h.run_interval(t, ramp(t))
    assert (err.value.code, err.value.message) == ("bad_value", "t must be strictly increasing: t[1]=0.05 >= t[2]=0.05")


def test_inputs_are_taken_by_the_ports_of_the_latest_configure() -> None:
    """Where each input goes among the joined samples is worked out once per configure: ports that depend on the
    parameters follow a new configure."""
    class Sized(Subsim):
        def initial_state(self, params):
            self.inputs = {"a": Port(params["k"]), "b": Port(1)}
            self.outputs = {"y": Port(params["k"] + 1)}
            return np.zeros(0)

        def advance(self, state, times, u):
            x = u(times)
            return {"y": np.column_stack([x["a"], x["b"]])}, state

    h = InProcessHandle(Sized(), name="sized")
    for k in (1, 3, 2):
        h.configure({"k": k})
        a, b = np.arange(N * k, dtype=float).reshape(N, k), -np.arange(N, dtype=float).reshape(N, 1)
        assert h.run_interval(TIMES, {"a": a, "b": b}).outputs["y"].tobytes() == np.hstack([a, b]).tobytes()


def test_samples_given_as_lists_run_the_same_in_one_process_and_remotely(handle: SubsimHandle) -> None:
    """A handle is the same object either way (docs/api.md): lists of samples ran in one process and were refused
    remotely as "args.inputs.u: expected an array map" (a probe); what is no array of numbers is refused by name."""
    as_lists = {"u": ramp(TIMES)["u"].tolist()}
    got = handle.run_interval(TIMES.tolist(), as_lists).outputs["y"]
    assert got.tobytes() == handle.run_interval(TIMES, ramp(TIMES)).outputs["y"].tobytes()
    # ragged; complex (a raw TypeError: red team); a complex array (in one process: cast, the imaginary part dropped)
    for bad in ([[1.0, 2.0]] * (N - 1) + [[1.0]], [[1j, 2.0]] * N, np.full((N, 2), 1.0 + 2j)):
        with pytest.raises(SubsimError) as err:
            handle.run_interval(TIMES, {"u": bad})
        assert (err.value.code, err.value.message) == ("bad_value", "inputs.u: not a float array"), err.value


def test_an_input_the_model_asks_for_by_a_wrong_name_is_named_with_the_inputs_there_are() -> None:
    """``u(t)["Temp"]`` in advance(): a bare KeyError 'Temp' (a newcomer probe)."""
    class Misnamed(Integrator):
        def advance(self, state, times, u):
            u(times[0])["Temp"]
            return super().advance(state, times, u)

    h = InProcessHandle(Misnamed(), name="misnamed")
    h.configure({"size": 2})
    with pytest.raises(SubsimError) as err:
        h.run_interval(TIMES, ramp(TIMES))
    assert err.value.code == "model_exception"
    assert "KeyError: \"'Temp' is no input of this subsim; its inputs: 'u'\"" in err.value.message, err.value.message


def test_a_model_that_cannot_be_built_is_named_as_it_was_given() -> None:
    """A red team of the constructor's one line: a partial was labelled 'partial', a missing argument located in
    cosim's own runtime.py, and an instance that cannot be copied blamed on its constructor."""
    import functools
    import threading

    class Boom(Integrator):
        def __init__(self, x: float) -> None:
            raise ValueError(f"boom {x}")

    class Locked(Integrator):
        def __init__(self) -> None:
            super().__init__()
            self.lock = threading.Lock()

    said = {}
    for key, model in (("partial", functools.partial(Boom, 2)), ("class", Boom), ("instance", Locked())):
        with pytest.raises(SubsimError) as err:
            InProcessHandle(model)
        said[key] = str(err.value)
    assert said["partial"].startswith("Boom.start: [model_exception] Boom() raised ValueError: boom 2 (test_contract")
    assert said["class"] == ("Boom.start: [model_exception] Boom() raised TypeError: test_a_model_that_cannot_be_built_"
                             "is_named_as_it_was_given.<locals>.Boom.__init__() missing 1 required positional argument:"
                             " 'x'")
    assert said["instance"].startswith("Locked.start: [model_exception] copying the Locked instance given (each "
                                       "configure works on a copy) raised TypeError: cannot pickle")


def test_outputs_of_an_array_like_whose_dtype_is_not_numpys_are_taken() -> None:
    """A tensor of another library (its dtype has no .kind) met the complex check with an AttributeError (a red
    team); it is converted as np.asarray converts it."""
    class TensorDtype:
        pass

    class Tensor:
        dtype = TensorDtype()

        def __init__(self, a: np.ndarray) -> None:
            self.a = a

        def __array__(self, dtype=None, copy=None) -> np.ndarray:  # noqa: ANN001
            return self.a if dtype is None else self.a.astype(dtype)

    class Torchy(Integrator):
        def advance(self, state, times, u):
            outputs, end = super().advance(state, times, u)
            return {"y": Tensor(outputs["y"])}, Tensor(end)

    h = InProcessHandle(Torchy(), name="torchy")
    h.configure({"size": 2})
    plain = InProcessHandle(Integrator(), name="plain")
    plain.configure({"size": 2})
    got, want = h.run_interval(TIMES, ramp(TIMES)), plain.run_interval(TIMES, ramp(TIMES))
    assert got.outputs["y"].tobytes() == want.outputs["y"].tobytes()


def test_an_initial_state_of_none_is_said_as_such() -> None:
    """It read 'initial_state() for these parameters gave a state that must have shape 1-D, got ()': the parameters
    blamed for a forgotten return (a newcomer probe)."""
    class Forgetful(Integrator):
        def initial_state(self, params):
            super().initial_state(params)

    with pytest.raises(SubsimError) as err:
        InProcessHandle(Forgetful()).configure({"size": 2})
    assert "initial_state() for these parameters gave a state that is None: a state is a 1-D array of floats (return " \
           "it)" in err.value.message, err.value.message
