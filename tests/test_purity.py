"""check_pure: the author-facing test of the contract's rule that advance() is pure."""

from __future__ import annotations

import ctypes
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


class _Tally:
    __slots__ = ("n",)

    def __init__(self) -> None:
        self.n = 0


class SlotCounting(Decay):
    """Counts in a helper with __slots__ (no __dict__: it passed as pure, red team)."""

    def initial_state(self, params):
        self.tally = _Tally()
        return super().initial_state(params)

    def advance(self, state, times, u):
        self.tally.n += 1
        return super().advance(state, times, u)


class Drawing(Decay):
    """Draws from a random generator it keeps: its state changes in C (it passed as pure)."""

    def initial_state(self, params):
        self.rng = np.random.default_rng(1)
        return super().initial_state(params)

    def advance(self, state, times, u):
        self.rng.random()
        return super().advance(state, times, u)


class _Solver:
    def __init__(self, model: Subsim) -> None:
        self.model = model


class Wired(Decay):
    """A helper that refers back to the model, a stored bound method, a C pointer that cannot be copied, a ragged
    object array, a long chain of helpers and a declared cache: pure (each made check_pure fail, or raise)."""

    caches = ("cache",)

    def initial_state(self, params):
        self.solver, self.step, self.handle = _Solver(self), self.advance, ctypes.pointer(ctypes.c_double(1.0))
        self.cache: dict[float, float] = {}
        self.ragged = np.array([[1.0], [2.0, 3.0], {"a": 1}], dtype=object)  # deep-copied item by item
        chain = _Solver(self)
        for _ in range(300):  # linked deeper than the comparison recurses (it raised RecursionError)
            chain = _Solver(chain)
        self.chain = chain
        return super().initial_state(params)

    def advance(self, state, times, u):
        self.cache.setdefault(float(times[-1]), 1.0)
        return super().advance(state, times, u)


INPUTS = {"u": np.linspace(0.0, 1.0, 5)[:, None]}


@pytest.mark.parametrize(("model", "params", "inputs"), [
    (Decay, {}, INPUTS),
    (Integrator, {"size": 2, "y0": [1.0, 2.0]}, {"u": np.ones((5, 2))}),
    (Mass, {"m": 2.0, "u0": 0.1}, {"F": np.ones((5, 1))}),
    (Wired, {}, INPUTS),
])
def test_pure_models_pass(model, params, inputs) -> None:
    check_pure(model, params, TIMES, inputs)


@pytest.mark.parametrize(("model", "words"), [
    (Counting, "changed the model's attributes ['calls']"),
    (InPlace, "wrote into the state"),
    (Drifting, "changed the model's attributes ['bias']"),
    (SlotCounting, "changed the model's attributes ['tally']"),
    (Drawing, "changed the model's attributes ['rng']"),
])
def test_impure_models_are_named_with_what_they_broke(model, words: str) -> None:
    with pytest.raises(ImpureModel, match=words.replace("[", r"\[").replace("]", r"\]")):
        check_pure(model, {}, TIMES, INPUTS)


def test_a_prototype_instance_works_as_well_as_a_class() -> None:
    check_pure(Decay(), {"x0": 3.0}, TIMES, INPUTS)
