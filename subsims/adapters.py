"""What the thin subsim adapters share. Adapters (``*/subsim.py``, ``*/__main__.py``, plots) and this module are
the only code under ``subsims/`` that imports ``cosim``; the physics imports NumPy/SciPy and ``subsims.numerics``."""

from __future__ import annotations

import functools
from collections.abc import Callable, Collection, Iterator, Mapping
from typing import Any, ClassVar, TypeVar

import numpy as np

from cosim.subsim import InputFunction, ModelError, Param, Subsim
from subsims.numerics import PhysicsError

Advance = TypeVar("Advance", bound=Callable[..., Any])
Advanced = tuple[dict[str, np.ndarray], np.ndarray]  # what advance returns: outputs by port, the end state


def reports_physics_errors(advance: Advance) -> Advance:
    """Decorate ``advance``: a :class:`PhysicsError` of the physics becomes the runtime's ``ModelError``
    (reported to the coordinator, not an internal error)."""

    @functools.wraps(advance)
    def wrapped(self: Subsim, state: np.ndarray, times: np.ndarray, u: InputFunction) -> Any:
        try:
            return advance(self, state, times, u)
        except PhysicsError as exc:
            raise ModelError(str(exc)) from exc

    return wrapped  # type: ignore[return-value]


class Unset(Mapping[str, Any]):
    """``params`` without the ``optional`` names whose value is None: a parameter declared with the default None
    ("not set") reads as absent, as the physics expects (``"r0" in params`` is False until a value is given).

    A read-through view: every lookup goes to ``params`` itself, nothing is copied."""

    def __init__(self, params: Mapping[str, Any], optional: Collection[str]) -> None:
        self._params, self._optional = params, frozenset(optional)

    def __getitem__(self, key: str) -> Any:
        value = self._params[key]
        if value is None and key in self._optional:
            raise KeyError(key)
        return value

    def __iter__(self) -> Iterator[str]:
        return (k for k, v in self._params.items() if not (v is None and k in self._optional))

    def __len__(self) -> int:
        return sum(1 for _ in self)


def unset_by_default(declared: Mapping[str, Param]) -> frozenset[str]:
    """The declared parameters whose default is None (optional, "not set")."""
    return frozenset(k for k, p in declared.items() if p.default is None)


class ParamsSubsim(Subsim):
    """An adapter whose physics reads its parameters as ``params_type.from_mapping(params)`` (kept as ``self.p``)
    and whose initial state is ``self.p.initial_state()``. Declared parameters with the default None are absent
    from the mapping the physics reads until they are given (see :class:`Unset`)."""

    params_type: ClassVar[Any]

    def initial_state(self, params: Mapping[str, Any]) -> np.ndarray:
        self.p = self.params_type.from_mapping(Unset(params, unset_by_default(self.params)))
        return self.p.initial_state()
