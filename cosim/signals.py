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

Interpolant = Callable[[float | np.ndarray], np.ndarray]  # t -> (m,); times (k,) -> (k, m)


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
        """A function t -> values at t, shape (m,); given an array of times (k,) it returns (k, m)."""
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


def _times_array(t: float | np.ndarray) -> np.ndarray | None:
    """``t`` as a float64 array when it is an array of times; None for one time (a number or a 0-d array)."""
    if isinstance(t, (float, int)):
        return None
    ts = np.asarray(t, dtype=np.float64)
    return ts if ts.ndim else None


def _vectorized(scalar: Callable[[float], np.ndarray], batch: Callable[[np.ndarray], np.ndarray]) -> Interpolant:
    """One interpolant: a time gives (m,) by ``scalar``; an array of times (k,) gives (k, m) by ``batch``, whose
    every row is bit-identical to ``scalar`` at that time (same operations in the same order, per row)."""

    def at(t: float | np.ndarray) -> np.ndarray:
        ts = _times_array(t)
        if ts is None:
            return scalar(float(t))
        if ts.ndim == 1:
            return batch(ts)
        out = batch(ts.reshape(-1))
        return out.reshape(ts.shape + out.shape[1:])

    return at


def _linear(times: np.ndarray, values: np.ndarray) -> Interpolant:
    grid = times.tolist()
    n = len(grid)
    if n == 1:
        return _vectorized(lambda t: values[0].copy(), lambda ts: np.repeat(values[:1], ts.size, axis=0))

    def at(t: float) -> np.ndarray:
        i = min(max(bisect.bisect_right(grid, t) - 1, 0), n - 2)
        w = (t - grid[i]) / (grid[i + 1] - grid[i])
        # exact at both ends of the step (w = 0 or 1), and no overflow of values[i + 1] - values[i]
        return (1.0 - w) * values[i] + w * values[i + 1]

    inner, step = times[1:-1], times[1:] - times[:-1]  # step[i] is the scalar's grid[i + 1] - grid[i]
    left, right = values[:-1], values[1:]

    def batch(ts: np.ndarray) -> np.ndarray:
        i = np.searchsorted(inner, ts, side="right")  # = the scalar's clipped bisect_right(grid, t) - 1
        w = ((ts - times[i]) / step[i])[:, None]
        return (1.0 - w) * left[i] + w * right[i]

    return _vectorized(at, batch)


def _barycentric_weights(x: np.ndarray) -> np.ndarray:
    """Weights 1 / prod_{j != k} (x_k - x_j) of the nodes ``x`` (..., k): of every row at once."""
    diff = x[..., :, None] - x[..., None, :]
    k = x.shape[-1]
    diff[..., range(k), range(k)] = 1.0
    return 1.0 / np.prod(diff, axis=-1)


def _barycentric_sum(c: np.ndarray, vals: np.ndarray) -> np.ndarray:
    """(sum_j c_j v_j) / (sum_j c_j), summed node by node in order (no BLAS: the same rounding for one time and
    for many). ``c`` (..., k) weights, ``vals`` (..., k, m) the node values."""
    num = c[..., 0, None] * vals[..., 0, :]
    den = c[..., 0]
    for j in range(1, c.shape[-1]):
        num = num + c[..., j, None] * vals[..., j, :]
        den = den + c[..., j]
    return num / den[..., None]


def _barycentric(nodes: np.ndarray, vals: np.ndarray) -> Interpolant:
    """Polynomial through all ``nodes`` (second barycentric form, stable for small n)."""
    x = nodes
    w = _barycentric_weights(x)
    xs = x.tolist()

    def at(t: float) -> np.ndarray:
        if t in xs:
            return vals[xs.index(t)].copy()
        d = t - x
        c = w * (np.abs(d).min() / d)  # scaled: w / d overflows when t is within rounding of a node
        return _barycentric_sum(c, vals)

    def batch(ts: np.ndarray) -> np.ndarray:
        return _barycentric_batch(ts, x[None, :], w[None, :], vals[None, :, :], np.zeros(ts.size, dtype=np.intp))

    return _vectorized(at, batch)


def _barycentric_batch(ts: np.ndarray, x: np.ndarray, w: np.ndarray, vals: np.ndarray, piece: np.ndarray) -> np.ndarray:
    """Per time ``ts[r]``, the polynomial of piece ``piece[r]`` (nodes ``x[p]``, weights ``w[p]``, values
    ``vals[p]``), as ``_barycentric``'s scalar form computes it; a time on a node gives that node's value."""
    xp = x[piece]
    d = ts[:, None] - xp
    hit = d == 0.0
    on_node = hit.any(axis=1)
    d[hit] = 1.0  # rows with a hit are replaced below; keeps the others free of 0/0
    c = w[piece] * (np.abs(d).min(axis=1)[:, None] / d)
    out = _barycentric_sum(c, vals[piece])
    if on_node.any():
        r = np.flatnonzero(on_node)
        out[r] = vals[piece[r], np.argmax(hit[r], axis=1)]
    return out


def _lagrange(times: np.ndarray, values: np.ndarray) -> Interpolant:
    return _barycentric(times, values)


def _cubic(times: np.ndarray, values: np.ndarray) -> Interpolant:
    """Piecewise cubic through the four samples around t (degree n-1 when n < 4)."""
    n = times.size
    if n <= 4:
        return _barycentric(times, values)
    node = np.arange(n - 3)[:, None] + np.arange(4)
    x, vals = times[node], values[node]  # (n-3, 4) nodes and (n-3, 4, m) values of each piece
    w = _barycentric_weights(x)  # each piece's own weights, all pieces in one go
    inner = times[2:-2]

    def batch(ts: np.ndarray) -> np.ndarray:  # piece min(max(i - 1, 0), n - 4) of step i
        return _barycentric_batch(ts, x, w, vals, np.searchsorted(inner, ts, side="right"))

    # one time is a batch of one: the same operations, so the same bits
    return _vectorized(lambda t: batch(np.array([t]))[0], batch)


_BUILDERS: dict[str, Callable[[np.ndarray, np.ndarray], Interpolant]] = {
    "linear": _linear,
    "cubic": _cubic,
    "lagrange": _lagrange,
}
