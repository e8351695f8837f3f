"""What the thin subsim adapters share. Adapters (``*/subsim.py``, ``*/__main__.py``, plots) and this module are
the only code under ``subsims/`` that imports ``cosim``; the physics imports NumPy/SciPy and ``subsims.numerics``."""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from typing import Any, ClassVar, TypeVar

import numpy as np

from cosim.subsim import InputFunction, ModelError, Subsim
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


class ParamsSubsim(Subsim):
    """An adapter whose physics reads its parameters as ``params_type.from_mapping(params)`` (kept as ``self.p``)
    and whose initial state is ``self.p.initial_state()``."""

    params_type: ClassVar[Any]

    def initial_state(self, params: Mapping[str, Any]) -> np.ndarray:
        self.p = self.params_type.from_mapping(params)
        return self.p.initial_state()
