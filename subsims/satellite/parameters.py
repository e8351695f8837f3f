"""Reading the satellite models' parameters: each helper returns the value or raises ValueError naming it."""

from __future__ import annotations

import math
import numbers


def as_vec3(value: object, name: str) -> tuple[float, float, float]:
    """A parameter as 3 finite floats, or ValueError naming it."""
    try:
        v = tuple(float(x) for x in value)  # type: ignore[union-attr]
    except (TypeError, ValueError):  # (not iterable; or items that are no numbers, as a table's keys)
        raise ValueError(f"parameter {name!r} must be a sequence of 3 numbers, got {value!r}") from None
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise ValueError(f"parameter {name!r} must be 3 finite numbers, got {value!r}")
    return v  # type: ignore[return-value]


def as_float(value: object, name: str, *, positive: bool = False, nonnegative: bool = False) -> float:
    """A parameter as a finite float (optionally > 0 or >= 0), or ValueError naming it."""
    try:
        x = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"parameter {name!r} must be a number, got {value!r}") from None
    if not math.isfinite(x) or (positive and x <= 0.0) or (nonnegative and x < 0.0):
        need = " > 0" if positive else " >= 0" if nonnegative else ""
        raise ValueError(f"parameter {name!r} must be a finite number{need}, got {value!r}")
    return x


def as_int(value: object, name: str, *, minimum: int = 1) -> int:
    """A parameter as an int >= minimum, or ValueError naming it."""
    if (isinstance(value, bool) or not isinstance(value, numbers.Real)
            or not math.isfinite(value) or int(value) != value or value < minimum):
        raise ValueError(f"parameter {name!r} must be an integer >= {minimum}, got {value!r}")
    return int(value)
