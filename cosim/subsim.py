"""The model author's API: subclass :class:`Subsim`, declare ports, write a pure ``advance``.

The author writes physics only. Committed state, trials, history, validation and the wire
all belong to :class:`cosim.runtime.Runtime`.

    class Integrator(Subsim):
        inputs = {"u": Port(1, "1/s")}
        outputs = {"y": Port(1)}
        params = {"y0": Param(0.0, "", "initial value of y")}

        def initial_state(self, params):          # every declared parameter is there: given or default
            return np.array([params["y0"]])

        def advance(self, state, times, u):
            ...  # integrate from times[0] to times[-1], reading u(t)["u"]
            return {"y": samples_of_y}, end_state
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

InputFunction = Callable[[float], Mapping[str, np.ndarray]]


@dataclass(frozen=True)
class Port:
    """One named vector signal of a subsim: its width, unit and a short description."""

    size: int
    unit: str = ""
    doc: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.size, int) or self.size < 1:
            raise ValueError(f"port size must be a positive int, got {self.size!r}")


PortSpec = Port | int | tuple


def as_port(spec: PortSpec) -> Port:
    """Accept ``Port``, ``3`` or ``(3, "m")`` / ``(3, "m", "doc")``."""
    if isinstance(spec, Port):
        return spec
    if isinstance(spec, int):
        return Port(spec)
    if isinstance(spec, tuple):
        return Port(*spec)
    raise TypeError(f"cannot make a port from {spec!r}")


def as_ports(specs: Mapping[str, PortSpec]) -> dict[str, Port]:
    return {name: as_port(spec) for name, spec in specs.items()}


@dataclass(frozen=True)
class Param:
    """One declared model parameter: its default, unit and meaning.

    The default is a plain value (number, string, bool, or a list/table of them), as in a scenario.
    """

    default: Any
    unit: str = ""
    doc: str = ""


def resolve_params(declared: Mapping[str, Param], given: Mapping[str, Any]) -> dict[str, Any]:
    """The parameters a model's ``initial_state`` sees: ``given`` over the declared defaults.

    A model that declares no parameters takes ``given`` as it is. Otherwise a name it does not
    declare is refused (ValueError listing the known names, with a "did you mean" when one is close),
    and so is a string where the default is a number or a boolean.
    """
    if not declared:
        return dict(given)
    unknown = [k for k in given if k not in declared]
    if unknown:
        hints = []
        for k in unknown:
            close = closest(str(k), declared)
            hints.append(f"{k!r} (did you mean {close!r}?)" if close else repr(k))
        raise ValueError(f"unknown parameter(s) {', '.join(hints)}; this model takes: {', '.join(declared)}")
    for k, v in given.items():  # a number in quotes would otherwise fail deep inside the model
        default = declared[k].default
        if isinstance(v, str) and isinstance(default, (bool, int, float)):
            kind = "true or false" if isinstance(default, bool) else "a number"
            raise ValueError(f"parameter {k!r} must be {kind} (its default is {default!r}), got the string {v!r}; "
                             "write it without quotes")
        if _finite_numbers(default) and not _finite_numbers(v, allow_other=True):  # NaN slips past `x <= 0`
            raise ValueError(f"parameter {k!r} must be finite (its default is {default!r}), got {v!r}")
        number = isinstance(default, (int, float)) and not isinstance(default, bool)
        if number and isinstance(v, bool):  # True is 1 to Python: m = true would run as m = 1
            raise ValueError(f"parameter {k!r} must be a number (its default is {default!r}), got {v!r}")
        if (number or isinstance(default, (list, tuple)) and _finite_numbers(default)) and _holds_words(v):
            # a table, or a list holding strings or tables (a model may take a list where its default is one; NumPy
            # numbers and arrays, None, an empty list: the model judges those)
            raise ValueError(f"parameter {k!r} must be a number or numbers (its default is {default!r}), got {v!r}")
        if number and isinstance(default, int) and isinstance(v, float) and not v.is_integer():  # int() truncates
            raise ValueError(f"parameter {k!r} must be a whole number (its default is {default!r}), got {v!r}")
    return {**{k: p.default for k, p in declared.items()}, **given}


def _holds_words(v: Any) -> bool:
    """Whether ``v`` is, or a (nested) list of it holds, a table or a string."""
    if isinstance(v, (str, Mapping)):
        return True
    return isinstance(v, (list, tuple)) and any(_holds_words(x) for x in v)


def _finite_numbers(v: Any, allow_other: bool = False) -> bool:
    """Whether ``v`` is a finite number or a (nested) list of them; ``allow_other``: also true for what holds no
    float at all (a string, a table: the model judges those)."""
    if isinstance(v, float):
        return math.isfinite(v)
    if isinstance(v, (list, tuple)):
        return all(_finite_numbers(x, allow_other) for x in v) and (allow_other or len(v) > 0)
    return isinstance(v, int) or allow_other


class ModelError(RuntimeError):
    """Raised by a model when it cannot advance (e.g. an attitude singularity); reported, not fatal."""


class IntervalTooLong(ModelError):
    """Raised by a model that cannot take this interval's steps but would take shorter ones (an FMU discarding its
    step). With ``interval = "auto"`` or ``max_halvings`` the coordinator retries the interval shorter; otherwise
    the run stops, saying so."""


class Subsim:
    """Base class of a subsystem simulation model.

    Class attributes (an instance may replace ``inputs``/``outputs`` in ``initial_state``
    when its ports depend on parameters):

    - ``name``: default instance name on the bus; ``configure`` sets it to the name the subsim is served under.
    - ``inputs``, ``outputs``: ``{port name: Port | size | (size, unit[, doc])}``.
    - ``algebraic``: True when the model has no state (outputs depend on inputs only).
    - ``params``: ``{parameter name: Param(default, unit, doc)}``. Optional; when given, ``configure``
      refuses any other name and ``initial_state`` sees every declared one (given or default), and
      ``describe`` (and ``cosim describe``) list them.
    - ``caches``: names of attributes ``advance`` fills with results that depend on its arguments only (a memo of
      matrix exponentials by step, say). ``advance`` must be pure; the runtime refuses a model whose attributes
      change in its first runs, but for these (``cosim.check_pure`` skips them too).
    - ``not_ports``: ``{name: why}`` of variables the model has that are no ports (an FMU's Integer output, say):
      a coupling naming one is refused with that reason instead of "has no output" alone.
    """

    name: ClassVar[str] = "subsim"
    inputs: Mapping[str, PortSpec] = {}
    outputs: Mapping[str, PortSpec] = {}
    algebraic: ClassVar[bool] = False
    params: ClassVar[Mapping[str, Param]] = {}
    caches: ClassVar[tuple[str, ...]] = ()
    not_ports: Mapping[str, str] = {}

    def initial_state(self, params: Mapping[str, Any]) -> np.ndarray:
        """Read parameters (keep what ``advance`` needs on ``self``); return the state at t0.

        Raise ``ValueError``/``KeyError`` naming the offending parameter on bad input.
        """
        raise NotImplementedError

    def advance(
        self, state: np.ndarray, times: np.ndarray, u: InputFunction
    ) -> tuple[Mapping[str, np.ndarray], np.ndarray]:
        """Advance from ``state`` at ``times[0]`` over the sample ``times`` (n,).

        ``u(t)`` returns ``{input name: array (size,)}`` interpolated at any ``t`` in the interval; given a
        1-D array of times ``(k,)`` it returns ``{input name: array (k, size)}`` in one call (evaluate the
        inputs an integrator needs once per interval, not once per step).
        Return ``({output name: array (n, size)}, state at times[-1])``. Must be pure: the same
        arguments always give the same result, and ``state`` must not be modified in place.
        """
        raise NotImplementedError


def closest(word: str, names: Iterable[str]) -> str | None:
    """The name in ``names`` a misspelled ``word`` most likely meant: one that differs only in case first (``kd``
    for ``Kd``, too short for a similarity), else the most similar, if similar enough; None if none is."""
    names = [str(n) for n in names]
    same = [n for n in names if n.lower() == word.lower()]
    if same:
        return same[0]
    close = difflib.get_close_matches(word.lower(), [n.lower() for n in names], n=1)
    return next(n for n in names if n.lower() == close[0]) if close else None
