"""check_pure: the author-facing test of the contract's rule that advance() is pure."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pytest

from cosim import ImpureModel, Port, Subsim, check_pure
from subsims.integrator.subsim import Integrator
from subsims.oscillator.subsim import Mass

TIMES = np.linspace(0.0, 0.4, 5)


class Decay(Subsim):
    """x' = -x + u, one explicit Euler step per sample (pure)."""

    inputs = {"u": Port(1)}
    outputs = {"x": Port(1)}

    def initial_state(self, params: Mapping[str, Any]) -> np.ndarray:
        return np.array([params.get("x0", 1.0)])

    def advance(self, state, times, u):
        x, out = state.copy(), [state.copy()]
        for t0, t1 in zip(times[:-1], times[1:]):
            x = x + (t1 - t0) * (-x + u(t0)["u"])
            out.append(x.copy())
        return {"x": np.array(out)}, x


class Counting(Decay):
    def advance(self, state, times, u):
        self.calls = getattr(self, "calls", 0) + 1
        return super().advance(state, times, u)


class InPlace(Decay):
    def advance(self, state, times, u):
        out, end = super().advance(state, times, u)
        state += 1.0
        return out, end


class Drifting(Decay):
    """Keeps a hidden integrator in a mutable array it was configured with (a classic stale-trial bug)."""

    def initial_state(self, params):
        self.bias = np.zeros(1)
        return super().initial_state(params)

    def advance(self, state, times, u):
        self.bias += 0.5
        out, end = super().advance(state + self.bias, times, u)
        return out, end


INPUTS = {"u": np.linspace(0.0, 1.0, 5)[:, None]}


@pytest.mark.parametrize(("model", "params", "inputs"), [
    (Decay, {}, INPUTS),
    (Integrator, {"size": 2, "y0": [1.0, 2.0]}, {"u": np.ones((5, 2))}),
    (Mass, {"m": 2.0, "u0": 0.1}, {"F": np.ones((5, 1))}),
])
def test_pure_models_pass(model, params, inputs) -> None:
    check_pure(model, params, TIMES, inputs)


@pytest.mark.parametrize(("model", "words"), [
    (Counting, "changed the model's attributes ['calls']"),
    (InPlace, "wrote into the state"),
    (Drifting, "changed the model's attributes ['bias']"),
])
def test_impure_models_are_named_with_what_they_broke(model, words: str) -> None:
    with pytest.raises(ImpureModel, match=words.replace("[", r"\[").replace("]", r"\]")):
        check_pure(model, {}, TIMES, INPUTS)


def test_a_prototype_instance_works_as_well_as_a_class() -> None:
    check_pure(Decay(), {"x0": 3.0}, TIMES, INPUTS)
