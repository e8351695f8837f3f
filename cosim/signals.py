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
from typing import NamedTuple

import numpy as np

# scheme name -> polynomial degree it reproduces exactly (None: n-1 for n samples)
SCHEMES: dict[str, int | None] = {"linear": 1, "cubic": 3, "lagrange": None}
LAGRANGE_MAX_SAMPLES = 64  # one polynomial through all samples: past ~450 its weights leave float64's range


def check_scheme(scheme: str, samples: int) -> None:
    """ValueError in one line unless ``scheme`` can interpolate ``samples`` samples."""
    if scheme not in SCHEMES:
        raise ValueError(f"unknown interpolation scheme {scheme!r}; known: {', '.join(SCHEMES)}")
    if scheme == "lagrange" and samples > LAGRANGE_MAX_SAMPLES:
        raise ValueError(f"'lagrange' puts one polynomial of degree n - 1 through all n = {samples} samples; at most "
                         f"{LAGRANGE_MAX_SAMPLES} (higher degrees oscillate, and their weights leave float64's range): "
                         "use 'cubic'")

Interpolant = Callable[[float | np.ndarray], np.ndarray]  # t -> (m,); times (k,) -> (k, m)

FEW_FLOATS = 16  # a vector of up to this many is looked at on Python floats (a NumPy call costs ~1 us)
_ALL = np.logical_and.reduce


def all_finite(a: np.ndarray) -> bool:
    """Whether an array of real numbers holds no NaN or inf: ``np.isfinite(a).all()``, in one reduction without
    ``all()``'s Python wrapper, and for a short vector on Python floats (every request checks a few)."""
    if a.ndim == 1 and a.size <= FEW_FLOATS:
        return all(map(math.isfinite, a.tolist()))
    return bool(_ALL(np.isfinite(a), axis=None))


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
        if not all_finite(v):
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


class _Weights(NamedTuple):
    """What interpolating at a batch of times ``ts`` (k,) needs of a grid, whatever the sample values: row r is
    ``(sum_j coef[j, r] values[nodes[j, r]]) / den[r]``, summed in order of j, except the rows ``exact_rows``,
    which are the samples ``exact_nodes`` themselves."""

    nodes: np.ndarray  # (terms, k): per term j, the sample index of every row
    coef: np.ndarray  # (terms, k, 1): per term j, its weight
    den: np.ndarray | None  # (k, 1); None when the weights sum to one by construction (linear)
    exact_rows: np.ndarray
    exact_nodes: np.ndarray
    # kept weights: by channel count m, coef (terms, k, m) and den (k, m), repeated over the channels (on arrays
    # this small, a product broadcast over the last axis costs twice a plain one); None: not kept, not repeated
    wide: dict[int, tuple[np.ndarray, np.ndarray | None]] | None = None


def _apply(weights: _Weights, values: np.ndarray) -> np.ndarray:
    coef, den = weights.coef, weights.den
    m = values.shape[1]
    if weights.wide is not None and 1 < m and coef.size * m <= WIDE_MAX:  # (one channel: coef is that shape already)
        wide = weights.wide.get(m)
        if wide is None:  # (two threads may both make them: equal arrays, either is right)
            wide = weights.wide[m] = (np.repeat(coef, m, axis=2), None if den is None else np.repeat(den, m, axis=1))
        coef, den = wide
    # (terms, k, m), each product as the scalar forms compute it; take() gathers the same rows as values[nodes]
    # in a third of the time
    terms = coef * values.take(weights.nodes, axis=0)
    out = terms[0] + terms[1] if len(terms) > 1 else terms[0]  # (a view of the fresh ``terms``: ours to change)
    for term in terms[2:]:
        out += term
    if den is not None:
        out /= den
    if weights.exact_rows.size:
        out[weights.exact_rows] = values.take(weights.exact_nodes, axis=0)
    return out


# Every stage of an interval, and every subsim of a stage, interpolates on the same grid at the same times (the
# integrators' RK times): the weights are computed once per (scheme, grid, times) and kept for the next calls.
_KEPT_WEIGHTS: dict[bytes, _Weights] = {}
KEPT_WEIGHTS_MAX = 32  # entries (a few KB each, and up to 32 KB per channel count repeated): memory stays flat
WIDE_MAX = 4096  # values of coef repeated over the channels kept per entry and channel count (a few; larger: broadcast)
_NO_ROWS = np.zeros(0, dtype=np.intp)


def _weights(scheme: str, times: np.ndarray, ts: np.ndarray, compute: Callable[[np.ndarray, np.ndarray], _Weights]
             ) -> _Weights:
    if ts.size < 4:  # one time (the scalar form of a batch): not worth keeping
        return compute(times, ts)
    key = b"".join((scheme.encode(), times.size.to_bytes(4, "little"), times.tobytes(), ts.tobytes()))
    found = _KEPT_WEIGHTS.get(key)
    if found is None:
        found = compute(times, ts)._replace(wide={})
        if len(_KEPT_WEIGHTS) >= KEPT_WEIGHTS_MAX:
            _KEPT_WEIGHTS.clear()  # (one call: safe against another thread's insert; old grids are not reused)
        _KEPT_WEIGHTS[key] = found
    return found


def _linear_weights(times: np.ndarray, ts: np.ndarray) -> _Weights:
    i = np.searchsorted(times[1:-1], ts, side="right")  # = the scalar's clipped bisect_right(grid, t) - 1
    w = ((ts - times[i]) / (times[1:] - times[:-1])[i])[:, None]  # exact at both ends of the step
    return _Weights(np.stack((i, i + 1)), np.stack((1.0 - w, w)), None, _NO_ROWS, _NO_ROWS)


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

    return _vectorized(at, lambda ts: _apply(_weights("linear", times, ts, _linear_weights), values))


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


FEW_CHANNELS = 16  # up to this many, one time is interpolated on Python floats (a few NumPy calls cost more)


def _barycentric_at(t: float, x: list[float], w: list[float], rows: list[list[float]]) -> np.ndarray:
    """:func:`_barycentric_sum` of the scaled weights at ``t`` (not on a node) on Python floats, operation for
    operation as the array forms (so the same bits): for one time of a few channels, a fifth of their cost."""
    d = [t - xj for xj in x]
    least = min(abs(dj) for dj in d)
    c = [wj * (least / dj) for wj, dj in zip(w, d)]
    num = [c[0] * a + c[1] * b for a, b in zip(rows[0], rows[1])]
    den = c[0] + c[1]
    for cj, row in zip(c[2:], rows[2:]):
        num = [n + cj * v for n, v in zip(num, row)]
        den = den + cj
    if den == 0.0:  # (far outside the grid) NumPy's inf or nan, as the array forms give, not ZeroDivisionError
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.array(num) / den
    return np.array([n / den for n in num])


class _Piece(NamedTuple):
    """What one time on the polynomial through some samples needs: their times (a list and an array), weights and
    sample rows, and the last two as Python lists when there are few channels (else None)."""

    xs: list[float]
    x: np.ndarray
    w: np.ndarray
    vals: np.ndarray
    lists: tuple[list[float], list[list[float]]] | None


def _piece(x: np.ndarray, w: np.ndarray, vals: np.ndarray) -> _Piece:
    few = x.size >= 2 and vals.shape[1] <= FEW_CHANNELS
    return _Piece(x.tolist(), x, w, vals, (w.tolist(), vals.tolist()) if few else None)


def _at_one(p: _Piece, t: float) -> np.ndarray:
    """The polynomial of piece ``p`` at one time: a sample itself on a node, else the scaled barycentric form."""
    if t in p.xs:
        return p.vals[p.xs.index(t)].copy()
    if p.lists is not None:
        return _barycentric_at(t, p.xs, *p.lists)
    d = t - p.x
    c = p.w * (np.abs(d).min() / d)  # scaled: w / d overflows when t is within rounding of a node
    return _barycentric_sum(c, p.vals)


def _barycentric(nodes: np.ndarray, vals: np.ndarray) -> Interpolant:
    """Polynomial through all ``nodes`` (second barycentric form, stable for small n)."""
    x = nodes
    w = _barycentric_weights(x)
    made: list[_Piece] = []  # made at the first call for one time (an interpolant of a batch alone never needs it)

    def at(t: float) -> np.ndarray:
        if not made:
            made.append(_piece(x, w, vals))
        return _at_one(made[0], t)

    def compute(times: np.ndarray, ts: np.ndarray) -> _Weights:
        return _piece_weights(ts, times[None, :], w[None, :], np.zeros(ts.size, dtype=np.intp),
                              np.arange(times.size)[None, :])

    return _vectorized(at, lambda ts: _apply(_weights("lagrange", x, ts, compute), vals))


def _piece_weights(ts: np.ndarray, x: np.ndarray, w: np.ndarray, piece: np.ndarray, node: np.ndarray) -> _Weights:
    """Per time ``ts[r]``, the weights of the polynomial of piece ``piece[r]`` (nodes ``x[p]`` = the samples
    ``node[p]``, barycentric weights ``w[p]``), as ``_barycentric``'s scalar form computes them; a time on a
    node gives that node's value."""
    xp = x[piece]
    d = ts[:, None] - xp
    hit = d == 0.0
    on_node = hit.any(axis=1)
    d[hit] = 1.0  # rows with a hit are replaced; keeps the others free of 0/0
    c = w[piece] * (np.abs(d).min(axis=1)[:, None] / d)  # scaled: w / d overflows within rounding of a node
    den = c[:, 0]
    for j in range(1, c.shape[1]):
        den = den + c[:, j]
    rows = np.flatnonzero(on_node)
    nodes = node[piece]
    return _Weights(np.ascontiguousarray(nodes.T), np.ascontiguousarray(c.T)[:, :, None], den[:, None], rows,
                    nodes[rows, np.argmax(hit[rows], axis=1)])


def _lagrange(times: np.ndarray, values: np.ndarray) -> Interpolant:
    return _barycentric(times, values)


def _cubic_weights(times: np.ndarray, ts: np.ndarray) -> _Weights:
    node = np.arange(times.size - 3)[:, None] + np.arange(4)  # the four samples of each piece
    x = times[node]
    piece = np.searchsorted(times[2:-2], ts, side="right")  # piece min(max(i - 1, 0), n - 4) of step i
    return _piece_weights(ts, x, _barycentric_weights(x), piece, node)


def _cubic(times: np.ndarray, values: np.ndarray) -> Interpolant:
    """Piecewise cubic through the four samples around t (degree n-1 when n < 4)."""
    if times.size <= 4:
        return _barycentric(times, values)

    def batch(ts: np.ndarray) -> np.ndarray:
        return _apply(_weights("cubic", times, ts, _cubic_weights), values)

    inner = times[2:-2].tolist()
    pieces: list[_Piece] = []  # each piece's, made at the first call for one time

    def at(t: float) -> np.ndarray:
        # a model asking for one time at each RK stage: the batch form for one time rebuilt every piece's weights
        # (12 times linear's cost). The same operations as a batch's row (the same weight rows), so the same bits.
        if not pieces:  # (two threads may both build them: equal pieces, either is right)
            node = np.arange(times.size - 3)[:, None] + np.arange(4)
            x = times[node]
            pieces[:] = map(_piece, x, _barycentric_weights(x), values[node])
        return _at_one(pieces[bisect.bisect_right(inner, t)], t)

    return _vectorized(at, batch)


_BUILDERS: dict[str, Callable[[np.ndarray, np.ndarray], Interpolant]] = {
    "linear": _linear,
    "cubic": _cubic,
    "lagrange": _lagrange,
}
