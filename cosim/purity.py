"""Check a model against the author contract's one hidden rule: ``advance`` is pure.

The runtime re-runs ``advance`` from the same committed state for every stage of an interval and
after every rollback, so a model that keeps anything between calls (a counter, a cached state, an
input array it writes into) gives a silently wrong coupled run. Use this in your model's tests::

    from cosim import check_pure

    def test_my_model_is_pure():
        check_pure(MyModel, {"mass": 2.0}, times=np.linspace(0, 0.4, 5), inputs={"force": np.ones((5, 3))})
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from cosim.runtime import Runtime
from cosim.subsim import Subsim


class ImpureModel(AssertionError):
    """``advance`` broke the contract; the message says how."""


def check_pure(
    model: Subsim | Callable[[], Subsim],
    params: Mapping[str, Any],
    times: np.ndarray,
    inputs: Mapping[str, np.ndarray],
    interp: str = "linear",
) -> None:
    """Configure ``model`` with ``params``, call ``advance`` twice on the same arguments, and raise
    :class:`ImpureModel` unless both calls return the same outputs and end state, bit for bit, and
    neither changed the state passed in, the input samples, or the model's own attributes."""
    runtime = Runtime(model)
    runtime.configure(params, t0=float(times[0]))
    m, state = runtime.model, np.array(runtime.state)  # a writable copy, as a model could receive
    samples = {k: np.array(v, dtype=np.float64) for k, v in inputs.items()}
    u = runtime._input_function(np.asarray(times, dtype=np.float64), samples, interp)
    before_state, before_inputs, before_attrs = state.copy(), copy.deepcopy(samples), copy.deepcopy(vars(m))

    first_out, first_end = m.advance(state, times, u)
    first = _frozen(first_out, first_end)
    if not np.array_equal(state, before_state):
        raise ImpureModel("advance() wrote into the state it was given (copy it before changing it)")
    if not all(np.array_equal(samples[k], before_inputs[k]) for k in samples):
        raise ImpureModel("advance() wrote into the input samples")
    changed = _changed_attributes(before_attrs, vars(m))
    if changed:
        raise ImpureModel(f"advance() changed the model's attributes {changed}: keep run state in the state vector")
    second = _frozen(*m.advance(state, times, u))
    if first != second:
        raise ImpureModel("advance() gave a different answer the second time on the same arguments")


def _frozen(outputs: Mapping[str, Any], end_state: Any) -> tuple:
    return (tuple(sorted((k, np.asarray(v, dtype=np.float64).tobytes()) for k, v in outputs.items())),
            np.asarray(end_state, dtype=np.float64).tobytes())


def _changed_attributes(before: dict[str, Any], after: dict[str, Any]) -> list[str]:
    names = sorted(set(before) | set(after))
    return [n for n in names if n not in before or n not in after or not _same(before[n], after[n])]


def _same(a: Any, b: Any) -> bool:
    if a is b:  # (a NaN is not equal to itself; deep copies keep numbers as they are)
        return True
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.shape == b.shape and \
            a.tobytes() == b.tobytes()
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if type(a) is type(b) and type(a).__eq__ is object.__eq__:  # a deep copy is another object: compare insides
        return _same(vars(a), vars(b)) if hasattr(a, "__dict__") and hasattr(b, "__dict__") else True
    try:
        return bool(a == b)
    except Exception:  # objects without a usable equality: compare what they hold
        return _same(vars(a), vars(b)) if hasattr(a, "__dict__") and hasattr(b, "__dict__") else a is b
