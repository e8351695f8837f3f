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
import types
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from cosim.runtime import Runtime, output_bits
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
    caches = set(getattr(m, "caches", ()))  # declared: filled with pure results, not compared
    before_state, before_inputs, before_attrs = state.copy(), copy.deepcopy(samples), _copies(vars(m), caches)

    first_out, first_end = m.advance(state, times, u)
    first = _frozen(first_out, first_end)
    if not np.array_equal(state, before_state):
        raise ImpureModel("advance() wrote into the state it was given (copy it before changing it)")
    if not all(np.array_equal(samples[k], before_inputs[k]) for k in samples):
        raise ImpureModel("advance() wrote into the input samples")
    changed = _changed_attributes(before_attrs, {k: v for k, v in vars(m).items() if k not in caches})
    if changed:
        raise ImpureModel(f"advance() changed the model's attributes {changed}: keep run state in the state vector")
    second = _frozen(*m.advance(state, times, u))
    if first != second:
        raise ImpureModel("advance() gave a different answer the second time on the same arguments")


def _frozen(outputs: Mapping[str, Any], end_state: Any) -> tuple:
    return output_bits(outputs), np.asarray(end_state, dtype=np.float64).tobytes()


def _copies(attrs: Mapping[str, Any], caches: set[str]) -> dict[str, Any]:
    """A deep copy of each attribute but the caches; one that cannot be copied (an FMU's C handles) is kept as itself,
    and compared by identity."""
    copies = {}
    for k, v in attrs.items():
        if k in caches:
            continue
        try:
            copies[k] = copy.deepcopy(v)
        except Exception:
            copies[k] = _Uncopied(v)
    return copies


class _Uncopied:
    __slots__ = ("obj",)

    def __init__(self, obj: Any) -> None:
        self.obj = obj


def _changed_attributes(before: dict[str, Any], after: dict[str, Any]) -> list[str]:
    names = sorted(set(before) | set(after))
    return [n for n in names if n not in before or n not in after or not _compared(before[n], after[n])]


def _compared(a: Any, b: Any) -> bool:
    try:
        return _same(a, b, set())
    except RecursionError:  # linked deeper than Python recurses (a long chain of helper objects): not told apart
        return True


def _same(a: Any, b: Any, seen: set[tuple[int, int]]) -> bool:
    """Whether a deep copy ``a`` made before a call still equals ``b``. ``seen``: the pairs being compared (a
    helper that refers back to the model is a cycle)."""
    if isinstance(a, _Uncopied):
        return a.obj is b
    if a is b:  # (a NaN is not equal to itself; deep copies keep numbers as they are)
        return True
    if isinstance(a, float) and isinstance(b, float) and a != a and b != b:  # a NaN bound anew
        return True
    if (id(a), id(b)) in seen:
        return True
    seen = seen | {(id(a), id(b))}
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        if not (isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.shape == b.shape):
            return False
        if a.dtype.hasobject:  # deep copies of its items (a ragged table): compared item by item
            return all(_same(x, y, seen) for x, y in zip(a.ravel(), b.ravel()))
        return a.tobytes() == b.tobytes()
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k], seen) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(_same(x, y, seen) for x, y in zip(a, b))
    if isinstance(a, types.MethodType) and isinstance(b, types.MethodType):  # a copied bound method: its copied self
        return a.__func__ is b.__func__ and _same(a.__self__, b.__self__, seen)
    if type(a) is type(b) and type(a).__eq__ is object.__eq__:  # a deep copy is another object: compare insides
        return _same(_insides(a), _insides(b), seen)
    try:
        return bool(a == b)
    except Exception:  # objects without a usable equality: compare what they hold
        return _same(_insides(a), _insides(b), seen)


def _insides(x: Any) -> Any:
    """What an object holds, as copying sees it: the arguments and state its ``__reduce_ex__`` gives (its
    attributes, slots, a random generator's state), else its attributes; None for an object that holds nothing."""
    try:
        reduced = x.__reduce_ex__(4)
        if isinstance(reduced, tuple):
            return list(reduced[1:3])
    except Exception:
        pass
    return vars(x) if hasattr(x, "__dict__") else None
