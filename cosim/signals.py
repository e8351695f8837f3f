"""Signal segments: the paper's §9 "standard format for a vector analog signal segment".

A segment is a strictly increasing time grid ``times`` (n,) with samples ``values`` (n, m),
one name and unit per channel. It evaluates itself between samples by one of the schemes in
``SCHEMES``. Outside ``[times[0], times[-1]]`` each scheme extrapolates with its end piece
(used by the coupler's ``extrapolate`` first guess).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

# scheme name -> polynomial degree it reproduces exactly (None: n-1 for n samples)
SCHEMES: dict[str, int | None] = {"linear": 1, "cubic": 3, "lagrange": None}

Interpolant = Callable[[float], np.ndarray]


class SegmentError(ValueError):
    """A segment was built from inconsistent data."""


def check_time_grid(times: np.ndarray, what: str = "times") -> np.ndarray:
    """Return ``times`` as float64 (n,), n >= 1, finite and strictly increasing, or raise."""
    t = np.asarray(times, dtype=np.float64)
    if t.ndim != 1 or t.size == 0:
        raise SegmentError(f"{what} must be a non-empty 1-D array, got shape {t.shape}")
    # fast path: finite ends and positive steps make every sample finite (NaN fails every comparison)
    if math.isfinite(t[0]) and math.isfinite(t[-1]) and (t.size == 1 or bool((t[1:] > t[:-1]).all())):
        return t
    if not np.isfinite(t).all():
        raise SegmentError(f"{what} contains NaN or inf at index {int(np.argmin(np.isfinite(t)))}")
    steps = np.diff(t)
    if (steps <= 0).any():
        i = int(np.argmax(steps <= 0))
        raise SegmentError(
            f"{what} must be strictly increasing: t[{i}]={float(t[i])!r} >= t[{i + 1}]={float(t[i + 1])!r}"
        )
    return t


@dataclass(frozen=True, eq=False)
class Segment:
    """Time-sampled vector signal over one convergence interval."""

    times: np.ndarray
    values: np.ndarray
    names: tuple[str, ...]
    units: tuple[str, ...]

    def __init__(
        self,
        times: Sequence[float] | np.ndarray,
        values: Sequence[Sequence[float]] | np.ndarray,
        names: Sequence[str] | None = None,
        units: Sequence[str] | None = None,
    ) -> None:
        t = check_time_grid(times)
        v = np.asarray(values, dtype=np.float64)
        if v.ndim == 1:
            v = v.reshape(-1, 1)
        if v.ndim != 2 or v.shape[0] != t.size:
            raise SegmentError(f"values must have shape ({t.size}, m) to match {t.size} times, got {v.shape}")
        if not np.isfinite(v).all():
            i, j = np.argwhere(~np.isfinite(v))[0]
            raise SegmentError(f"values[{i}, {j}] is {float(v[i, j])!r}: samples must be finite")
        m = v.shape[1]
        names = tuple(names) if names is not None else tuple(f"y[{j}]" for j in range(m))
        units = tuple(units) if units is not None else ("",) * m
        if len(names) != m or len(units) != m:
            raise SegmentError(f"{m} channels need {m} names and units, got {len(names)} and {len(units)}")
        t.setflags(write=False)
        v.setflags(write=False)
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "values", v)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "units", units)

    @property
    def n(self) -> int:
        return self.times.size

    @property
    def width(self) -> int:
        return self.values.shape[1]

    def interpolant(self, scheme: str = "linear") -> Interpolant:
        """A function t -> values at t, shape (m,)."""
        return interpolant(self.times, self.values, scheme)

    def __call__(self, t: float, scheme: str = "linear") -> np.ndarray:
        return self.interpolant(scheme)(t)


def interpolant(times: np.ndarray, values: np.ndarray, scheme: str = "linear") -> Interpolant:
    """Interpolant of samples already checked as a :class:`Segment` checks them (hot path: no re-check)."""
    try:
        build = _BUILDERS[scheme]
    except KeyError:
        raise SegmentError(f"unknown interpolation scheme {scheme!r}; known: {', '.join(SCHEMES)}") from None
    return build(times, values)


def _linear(times: np.ndarray, values: np.ndarray) -> Interpolant:
    grid = times.tolist()
    n = len(grid)
    if n == 1:
        return lambda t: values[0].copy()

    def at(t: float) -> np.ndarray:
        i = min(max(bisect.bisect_right(grid, t) - 1, 0), n - 2)
        w = (t - grid[i]) / (grid[i + 1] - grid[i])
        # exact at both ends of the step (w = 0 or 1), and no overflow of values[i + 1] - values[i]
        return (1.0 - w) * values[i] + w * values[i + 1]

    return at


def _barycentric(nodes: np.ndarray, vals: np.ndarray) -> Interpolant:
    """Polynomial through all ``nodes`` (second barycentric form, stable for small n)."""
    x = nodes
    diff = x[:, None] - x[None, :]
    np.fill_diagonal(diff, 1.0)
    w = 1.0 / np.prod(diff, axis=1)
    xs = x.tolist()

    def at(t: float) -> np.ndarray:
        if t in xs:
            return vals[xs.index(t)].copy()
        d = t - x
        c = w * (np.abs(d).min() / d)  # scaled: w / d overflows when t is within rounding of a node
        return (c @ vals) / c.sum()

    return at


def _lagrange(times: np.ndarray, values: np.ndarray) -> Interpolant:
    return _barycentric(times, values)


def _cubic(times: np.ndarray, values: np.ndarray) -> Interpolant:
    """Piecewise cubic through the four samples around t (degree n-1 when n < 4)."""
    n = times.size
    if n <= 4:
        return _barycentric(times, values)
    grid = times.tolist()
    pieces = [_barycentric(times[s : s + 4], values[s : s + 4]) for s in range(n - 3)]

    def at(t: float) -> np.ndarray:
        i = min(max(bisect.bisect_right(grid, t) - 1, 0), n - 2)
        return pieces[min(max(i - 1, 0), n - 4)](t)

    return at


_BUILDERS: dict[str, Callable[[np.ndarray, np.ndarray], Interpolant]] = {
    "linear": _linear,
    "cubic": _cubic,
    "lagrange": _lagrange,
}
