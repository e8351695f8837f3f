"""Small numerics shared by the satellite models: the listings' RK4 (RKSYS) and 3-vector helpers.

Everything works on plain Python floats (lists/tuples of 3 or of the state size): for 3-vectors this
is several times faster than NumPy, and the paper's 60,000 s runs make millions of derivative calls.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

Vec = Sequence[float]
Mat = Sequence[Sequence[float]]
Derivative = Callable[[float, list[float]], list[float]]


def rk4_step(deriv: Derivative, t: float, y: Vec, h: float, k1: Vec | None = None,
             t_end: float | None = None) -> list[float]:
    """One classical RK4 step exactly as RKSYS/RKSYS1/RKSYS2 (spec §3.3).

    Stages at t, t+h/2 (twice) and ``t_end`` (default t+h; pass the grid time to hit it exactly).
    ``k1`` = deriv(t, y) if the caller already has it. Returns y(t+h); ``y`` is not modified.
    """
    h2 = h / 2.0
    h3 = h / 3.0
    h6 = h / 6.0
    tm = t + h2
    f = deriv(t, list(y)) if k1 is None else k1
    ytemp = [a + b * h6 for a, b in zip(y, f)]
    ys = [a + b * h2 for a, b in zip(y, f)]
    f = deriv(tm, ys)
    ytemp = [a + b * h3 for a, b in zip(ytemp, f)]
    ys = [a + b * h2 for a, b in zip(y, f)]
    f = deriv(tm, ys)
    ytemp = [a + b * h3 for a, b in zip(ytemp, f)]
    ys = [a + b * h for a, b in zip(y, f)]
    f = deriv(t + h if t_end is None else t_end, ys)
    return [a + b * h6 for a, b in zip(ytemp, f)]


def vecnorm(x: Vec) -> tuple[tuple[float, float, float], float]:
    """VECNORM: (unit vector, magnitude); the zero vector gives ((0, 0, 0), 0) (guard needed by RF-C stage 0)."""
    mag = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])
    if mag <= 0.0:
        return (0.0, 0.0, 0.0), 0.0
    return (x[0] / mag, x[1] / mag, x[2] / mag), mag


def cross(a: Vec, b: Vec) -> tuple[float, float, float]:
    """vcross: a x b."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def matvec(m: Mat, v: Vec) -> tuple[float, float, float]:
    """MATVEC: m v for a 3x3 matrix given as rows."""
    r0, r1, r2 = m
    return (r0[0] * v[0] + r0[1] * v[1] + r0[2] * v[2],
            r1[0] * v[0] + r1[1] * v[1] + r1[2] * v[2],
            r2[0] * v[0] + r2[1] * v[1] + r2[2] * v[2])


def matTvec(m: Mat, v: Vec) -> tuple[float, float, float]:
    """TRAN3 then MATVEC: m^T v."""
    r0, r1, r2 = m
    return (r0[0] * v[0] + r1[0] * v[1] + r2[0] * v[2],
            r0[1] * v[0] + r1[1] * v[1] + r2[1] * v[2],
            r0[2] * v[0] + r1[2] * v[1] + r2[2] * v[2])


def as_vec3(value: object, name: str) -> tuple[float, float, float]:
    """A parameter as 3 finite floats, or ValueError naming it."""
    try:
        v = tuple(float(x) for x in value)  # type: ignore[union-attr]
    except TypeError:
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


def input_reader(u: Callable[[float], Any], *names: str) -> Callable[[float], tuple[list[float], ...]]:
    """Wrap a subsim input function ``u(t) -> {name: array}``: return t -> (list of floats per name).

    Remembers the last call, because RK4 asks twice at t+h/2 and the next step starts where this ends.
    """
    last_t: list[float | None] = [None]
    last_v: list[tuple[list[float], ...]] = [()]

    def read(t: float) -> tuple[list[float], ...]:
        if t != last_t[0]:
            d = u(t)
            last_v[0] = tuple(np.asarray(d[n], dtype=np.float64).reshape(-1).tolist() for n in names)
            last_t[0] = t
        return last_v[0]

    return read
