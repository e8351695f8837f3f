"""Declared model parameters: defaults filled in, unknown names refused with a hint, described on the wire."""

from __future__ import annotations

import re

import numpy as np
import pytest

from cosim.contract import SubsimError
from cosim.handles import Description, InProcessHandle
from cosim.protocol.messages import decode_reply, encode_request
from cosim.protocol.service import answer
from cosim.runtime import Runtime
from cosim.subsim import Param, Port, Subsim
from subsims.integrator.subsim import Integrator
from subsims.oscillator.subsim import Mass


class Seen(Subsim):
    """Records the parameters initial_state was given."""

    inputs = {}
    outputs = {"x": Port(1)}
    params = {"gain": Param(2.5, "1", "a gain"), "offset": Param(0.0, "m", "an offset")}

    def initial_state(self, params):
        self.seen = dict(params)
        return np.zeros(1)

    def advance(self, state, times, u):
        return {"x": np.zeros((times.size, 1))}, state


class Undeclared(Seen):
    params = {}


def test_declared_defaults_are_filled_in_and_given_values_win() -> None:
    h = InProcessHandle(Seen())
    h.configure({"offset": 3.0})
    assert h.runtime.model.seen == {"gain": 2.5, "offset": 3.0}


def test_unknown_parameter_is_refused_with_the_known_ones_and_a_close_match() -> None:
    h = InProcessHandle(Seen())
    h.configure({"gain": 1.0})
    with pytest.raises(SubsimError) as err:
        h.configure({"gian": 1.0, "zzz": 2})
    msg = err.value.message
    assert err.value.code == "bad_value" and err.value.command == "configure"
    assert "'gian' (did you mean 'gain'?)" in msg and "'zzz'" in msg and "did you mean" not in msg.split("'zzz'")[1]
    assert "gain, offset" in msg
    assert h.runtime.model.seen == {"gain": 1.0, "offset": 0.0}  # the old configuration stays


def test_a_model_without_declarations_takes_any_names_as_given() -> None:
    h = InProcessHandle(Undeclared())
    h.configure({"anything": 1})
    assert h.runtime.model.seen == {"anything": 1}


def test_describe_carries_the_declarations_over_the_wire() -> None:
    rt = Runtime(Mass)
    result = decode_reply("describe", answer(rt, encode_request("describe")))
    d = Description.from_result(result)
    assert d.params["m"] == Param(1.0, "kg", "mass, > 0")
    assert d.params["k"].default == 4 * np.pi**2 and d.params["idiv"].default == 1
    assert list(d.params) == ["m", "k", "u0", "v0", "idiv"]


@pytest.mark.parametrize(("model", "typo", "hint"), [(Mass, "u_0", "u0"), (Integrator, "sise", "size")])
def test_shipped_models_refuse_typos(model: type[Subsim], typo: str, hint: str) -> None:
    with pytest.raises(SubsimError) as err:
        InProcessHandle(model()).configure({typo: 1.0})
    assert f"did you mean {hint!r}" in err.value.message


def test_a_scenario_typo_is_reported_as_the_scenario_page_says(tmp_path) -> None:
    from pathlib import Path

    from cosim.runner import open_session
    from cosim.scenario import ScenarioError, load

    root = Path(__file__).parents[1]
    shown = re.search(r"suggesting the closest one: `oscillator.toml: (.*?)`", (root / "docs" / "scenarios.md")
                      .read_text(), re.S).group(1).replace("\n  ", " ")
    sc = tmp_path / "oscillator.toml"
    sc.write_text((root / "scenarios" / "oscillator.toml").read_text().replace("u0 = 1.0", "u_0 = 1.0"))
    with pytest.raises(ScenarioError) as err:
        open_session(load(sc), inprocess=True).close()
    assert str(err.value) == f"{sc}: {shown}"


class ReadsAMisspelledKey(Seen):
    def initial_state(self, params):
        return np.array([params["Gain"]])  # a bug: the declared name is "gain"


def test_a_key_error_in_initial_state_is_a_bad_parameter_with_the_models_frames() -> None:
    """A KeyError may be the model refusing a parameter (as the contract allows) or a bug in it: the error says
    both, names the exception, and carries the model's traceback, which tells which."""
    h = InProcessHandle(ReadsAMisspelledKey())
    with pytest.raises(SubsimError) as err:
        h.configure({})
    assert err.value.code == "bad_value"
    assert err.value.message == "configure: bad parameter (or a bug in initial_state()): KeyError: 'Gain'"
    assert 'params["Gain"]' in err.value.traceback and "in initial_state" in err.value.traceback


@pytest.mark.parametrize(("given", "says"), [
    ({"m": True}, "parameter 'm' must be a number (its default is 1.0), got True"),
    ({"k": False}, "parameter 'k' must be a number"),
    ({"idiv": 1.5}, "parameter 'idiv' must be a whole number (its default is 1), got 1.5"),
    ({"idiv": True}, "parameter 'idiv' must be a number (its default is 1), got True"),
])
def test_a_boolean_for_a_number_or_a_fraction_for_a_count_is_refused(given: dict, says: str) -> None:
    """true is 1 to Python and int(1.5) is 1: m = true ran as m = 1 and idiv = 1.5 as 1, silently."""
    h = InProcessHandle(Mass())
    h.configure({"m": 2.0})
    with pytest.raises(SubsimError) as err:
        h.configure(given)
    assert err.value.code == "bad_value" and says in err.value.message
    assert h.runtime.model.m == 2.0  # the old configuration stays
    h.configure({"idiv": 2.0})  # a whole number written as a float is one
    assert h.runtime.model.idiv == 2


def test_a_request_for_more_rk4_steps_than_a_call_may_take_is_a_model_error_at_once() -> None:
    """idiv = 10**7 held the oscillator's serving thread for 38 s on a 2-sample request, status unanswered."""
    h = InProcessHandle(Mass())
    h.configure({"idiv": 10**7})
    with pytest.raises(SubsimError) as err:
        h.run_interval(np.array([0.0, 0.1]), {"F": np.zeros((2, 1))})
    assert err.value.code == "model_error" and "10000000 RK4 steps asked for in one call" in err.value.message
    h.configure({"idiv": 1000})
    assert h.run_interval(np.array([0.0, 0.1]), {"F": np.zeros((2, 1))}).end_time == 0.1
