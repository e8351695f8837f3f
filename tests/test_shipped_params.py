"""Every shipped subsim declares its parameters: exactly the names its initial_state reads, with the model's own
defaults; a misspelled name is refused at configure with a "did you mean" and the list of known ones.

(subsims.fmu is not here: its parameters are the variables of the FMU file it is given, so it declares none and
refuses unknown variables itself, listing the settable ones.)"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

import subsims.flexbody.config as flex_config
import subsims.flexbody_control.law as control_law
import subsims.lagrange_pair.model as pair_model
from cosim.contract import CosimError
from cosim.handles import Description
from cosim.protocol.messages import decode_reply, encode_request
from cosim.protocol.service import answer
from cosim.runtime import Runtime
from cosim.subsim import Param, Subsim, resolve_params
from subsims.aero import model as aero_model
from subsims.aero.subsim import Aero
from subsims.attitude import model as attitude_model
from subsims.attitude.subsim import Attitude
from subsims.double_integrator.subsim import DoubleIntegrator
from subsims.flexbody.subsim import FlexBody
from subsims.flexbody.vehicle import SAMPLE_VEHICLE
from subsims.flexbody_control.subsim import AttitudeControl
from subsims.integrator.subsim import Integrator
from subsims.lagrange_pair.subsim import LagrangePair
from subsims.lagrange_pair_aero.subsim import LagrangePairAero
from subsims.orbit import model as orbit_model
from subsims.orbit.subsim import Orbit
from subsims.oscillator.subsim import Mass

# model, a misspelling, the declared name it is close to, where the physics merges its own defaults in (patched to
# record the reads on the merged mapping), the names the physics itself knows (None: only the declarations)
FAMILIES: list[tuple[type[Subsim], str, str, tuple[tuple[Any, str], ...], Any]] = [
    (Orbit, "idvi", "idiv", (), orbit_model.PARAM_NAMES),
    (Attitude, "omega_0", "omega0", (), attitude_model.PARAM_NAMES),
    (Aero, "rhoo", "rho", (), aero_model.PARAM_NAMES),
    (DoubleIntegrator, "v_0", "v0", (), None),
    (FlexBody, "n_mode", "n_modes", ((flex_config, "merged_params"),),
     (set(SAMPLE_VEHICLE) - {"t_end", "print_dt", "plot_dt"}) | flex_config.OPTIONAL_KEYS),
    (AttitudeControl, "t_swich", "t_switch", ((control_law, "merged_params"),), control_law.DEFAULT_CONTROL),
    (LagrangePair, "weigth_B", "weight_B", ((pair_model, "merged_params"),), pair_model.DEFAULT_PARAMS),
    (Mass, "idvi", "idiv", (), None),
    (Integrator, "sise", "size", (), None),
]
IDS = [f[0].__name__ for f in FAMILIES]


class Recording(dict):
    """A parameter dict that notes every name looked up (``[]``, ``get``, ``in``), not the names iterated over."""

    def __init__(self, data: Any, seen: set[str]) -> None:
        super().__init__(data)
        self.seen = seen

    def __getitem__(self, key: str) -> Any:
        self.seen.add(key)
        return super().__getitem__(key)

    def get(self, key: str, default: Any = None) -> Any:
        self.seen.add(key)
        return super().get(key, default)

    def __contains__(self, key: object) -> bool:
        self.seen.add(key)  # type: ignore[arg-type]
        return super().__contains__(key)


def keys_read(model: type[Subsim], merges: tuple[tuple[Any, str], ...], monkeypatch: pytest.MonkeyPatch) -> set[str]:
    """The names ``initial_state`` looks up, given the declared defaults. Where the physics merges the given
    parameters over its own defaults, the lookups on the merged mapping are the ones that count."""
    seen: set[str] = set()
    for module, attr in merges:
        merge: Callable = getattr(module, attr)
        monkeypatch.setattr(module, attr, lambda p, merge=merge: Recording(merge(p), seen))
    outer: set[str] = set() if merges else seen  # copying into the merged dict looks up every given name
    model().initial_state(Recording(resolve_params(model.params, {}), outer))
    return seen


@pytest.mark.parametrize(("model", "typo", "hint", "merges", "known"), FAMILIES, ids=IDS)
def test_a_misspelled_parameter_is_refused_naming_the_close_one(model, typo, hint, merges, known) -> None:
    rt = Runtime(model)
    with pytest.raises(CosimError) as err:
        rt.configure({typo: model.params[hint].default})
    assert err.value.code == "bad_value"
    assert f"{typo!r} (did you mean {hint!r}?)" in err.value.message
    assert f"this model takes: {', '.join(model.params)}" in err.value.message
    rt.configure({hint: model.params[hint].default})  # spelled right, the same value is taken


@pytest.mark.parametrize(("model", "typo", "hint", "merges", "known"), FAMILIES, ids=IDS)
def test_the_declared_names_are_the_names_initial_state_reads(model, typo, hint, merges, known, monkeypatch) -> None:
    assert keys_read(model, merges, monkeypatch) == set(model.params)
    if known is not None:  # the physics' own list of names (it refuses others when called directly)
        assert set(known) == set(model.params)


def test_the_check_notices_an_undeclared_name(monkeypatch) -> None:
    class Undeclared(Orbit):
        params = {k: p for k, p in Orbit.params.items() if k != "r0"}

    class Stale(FlexBody):
        params = {**FlexBody.params, "t_end": Param(60.0, "s", "not read by the model")}

    assert keys_read(Undeclared, (), monkeypatch) - set(Undeclared.params) == {"r0"}
    assert set(Stale.params) - keys_read(Stale, ((flex_config, "merged_params"),), monkeypatch) == {"t_end"}


OWN_DEFAULTS = [f[0] for f in FAMILIES if f[4] is not None]


@pytest.mark.parametrize("model", OWN_DEFAULTS, ids=[m.__name__ for m in OWN_DEFAULTS])
def test_the_declared_defaults_are_the_models_own(model) -> None:
    """Configured with nothing (every declared default) == the physics with nothing given (its own defaults).
    (The others, e.g. DoubleIntegrator, have no defaults but the declared ones.)"""
    rt = Runtime(model)
    rt.configure({})
    direct = model()
    np.testing.assert_array_equal(rt.state, direct.initial_state({}))
    if isinstance(direct, (Orbit, Attitude, Aero)):  # frozen dataclasses of every constant
        assert rt.model.p == direct.p


@pytest.mark.parametrize("model", [f[0] for f in FAMILIES], ids=IDS)
def test_describe_carries_every_declaration_over_the_wire(model) -> None:
    d = Description.from_result(decode_reply("describe", answer(Runtime(model), encode_request("describe"))))
    assert list(d.params) == list(model.params)
    for k, p in model.params.items():
        assert (d.params[k].unit, d.params[k].doc) == (p.unit, p.doc) and p.doc
        assert np.array_equal(np.asarray(d.params[k].default, dtype=object), np.asarray(p.default, dtype=object))


def test_optional_parameters_stay_unset_until_given() -> None:
    """Declared with the default None: the physics sees them absent (circular orbit, boom stiffness, zero
    deflections), and a given value is used."""
    rt = Runtime(Orbit)
    rt.configure({"altitude_km": 400.0})
    assert np.linalg.norm(rt.state[:3]) == pytest.approx((6367.65 + 400.0) * 1e3)
    rt.configure({"r0": [7.0e6, 0.0, 0.0], "v0": [0.0, 7.5e3, 0.0]})
    assert rt.state.tolist() == [7.0e6, 0.0, 0.0, 0.0, 7.5e3, 0.0]
    with pytest.raises(CosimError, match="'r0' must not be the zero vector"):
        rt.configure({"r0": [0.0, 0.0, 0.0]})

    flex = Runtime(FlexBody)
    flex.configure({"mode": "attitude", "eta0": [0.1, 0.0]})
    assert flex.state.tolist() == [0.1, 0.0, 0.0, 0.0]
    with pytest.raises(CosimError) as err:  # supplied modes need both omega2 and Phi, as before
        flex.configure({"omega2": [1.0]})
    assert err.value.code == "bad_value" and "Phi" in err.value.message


def test_the_pair_aero_takes_no_parameters() -> None:
    assert LagrangePairAero.params == {}
    rt = Runtime(LagrangePairAero)
    rt.configure({})
    with pytest.raises(CosimError) as err:
        rt.configure({"rho": 1.0})
    assert err.value.code == "bad_value" and "takes no parameters" in err.value.message and "'rho'" in err.value.message


SHIPPED = [f[0] for f in FAMILIES] + [LagrangePairAero]


@pytest.mark.parametrize(("cls", "name"), [(cls, name) for cls in SHIPPED for name, p in cls().params.items()
                                           if isinstance(p.default, float)])
def test_a_nan_parameter_is_refused_at_configure(cls: type[Subsim], name: str) -> None:
    """NaN passes a check written ``x <= 0`` (every comparison with NaN is false): the oscillator then ran and
    stopped at its first output, not at configure naming the parameter."""
    rt = Runtime(cls)
    with pytest.raises(CosimError) as err:
        rt.configure({name: float("nan")})
    assert err.value.code == "bad_value" and name in err.value.message, err.value.message
    assert rt.state is None


WRONG = [-6378.0, 0.0, 1e308, {"a": 1}, ["x"], "abc", [[1.0]], True]


@pytest.mark.parametrize("cls", SHIPPED, ids=[c.__name__ for c in SHIPPED])
def test_a_refused_parameter_is_named_whatever_the_model_said(cls: type[Subsim]) -> None:
    """Values of the wrong kind or range, each parameter alone: a refusal names the parameter. It said "bad
    parameter: math domain error" (orbit, altitude_km = -6378) or "could not convert string to float: 'a'"
    (r0 = {a = 1}), naming nothing (a red-team probe); every shipped model had such messages."""
    unnamed = []
    for name in cls().params:
        for value in WRONG:
            rt = Runtime(cls)
            try:
                with np.errstate(all="ignore"), warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    rt.configure({name: value})
            except CosimError as exc:
                if name not in exc.message:
                    unnamed.append(f"{name} = {value!r}: {exc.message}")
    assert not unnamed, "\n".join(unnamed)


def test_numpy_numbers_and_arrays_are_parameters_as_before() -> None:
    """The check of a table where numbers are due refused np.int64(2), np.float32 and arrays (a sweep over
    np.arange through cosim.run(params=...): a red team); only tables and strings are refused by it."""
    from subsims.oscillator.subsim import Mass

    Runtime(Mass).configure({"idiv": np.int64(2), "k": np.float32(3.0)})
    Runtime(Integrator).configure({"size": 3, "y0": np.zeros(3)})
    for value in ({"a": 1}, ["x"], [[1.0], ["y"]]):
        with pytest.raises(CosimError, match="parameter 'k' must be a number or numbers"):
            Runtime(Mass).configure({"k": value})
