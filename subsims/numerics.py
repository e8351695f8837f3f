"""Numerics shared by every shipped model: the fixed-step RK4 with its input evaluation, 3-vectors, the 3-2-1 DCM.

Physics modules import this and NumPy/SciPy only (never ``cosim``); the thin adapters (``*/subsim.py``) turn
:class:`PhysicsError` into the runtime's ``ModelError``.

**RK4.** :func:`rk4` integrates over sample times with ``steps`` equal sub-steps per sample interval, in the
operation order of the satellite listings' RKSYS (spec recursive-feedback-satellite §3.3: YTEMP accumulates
F*H6, F*H3, F*H3, F*H6). Before the first step it asks for the inputs at every time it will need, the
sub-step starts t, the midpoints t + h/2 and the ends, in ONE call (:func:`rk4_times`), so a model's input
function ``u(ts)`` interpolates once per interval. The derivative at a sub-step's start is the one at the
previous sub-step's end (same time, state and input), so it is evaluated once.

A state is either a ``list`` of floats or a NumPy array: for 6 or 12 states plain Python floats are faster
than NumPy (the paper's 60,000 s runs make millions of derivative calls), for larger ones arrays are.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

Vec = Sequence[float]
Mat = Sequence[Sequence[float]]
State = Any  # list[float] | np.ndarray
Derivative = Callable[[float, State, Any], State]  # f(t, y, input row at t) -> dy/dt
Node = Callable[[float, State, Any], tuple[State, Any]]  # (dy/dt, what to keep at a sample)


class PhysicsError(RuntimeError):
    """A model cannot go on (a singularity, a blow-up); its adapter reports it as the runtime's ModelError."""


# --- fixed-step RK4 ------------------------------------------------------------------------------------------

MAX_STEPS = 1_000_000  # sub-steps one rk4 call may take: seconds of Python for these models


def substeps(times: np.ndarray, h_max: float) -> np.ndarray:
    """Per sample interval, the number of equal sub-steps of at most ``h_max`` (1e-9 slack: 0.1 / 0.01 is 10)."""
    dt = np.diff(np.asarray(times, dtype=np.float64))
    return np.maximum(1, np.ceil(dt / h_max - 1e-9)).astype(np.intp)


def rk4_times(times: np.ndarray, steps: int | np.ndarray = 1, h: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Every time RK4 needs over ``times`` (n,), and the sub-step lengths.

    ``steps``: sub-steps per interval (an int or (n-1,)); ``h``: a fixed sub-step (default: each interval's
    length / its steps). Sub-step j of interval k starts at t_k + j h (the sample t_k itself for j = 0) and
    ends where the next starts, on t_{k+1} exactly for the last. Returns ``ts`` (2S + 1,) = start, midpoint,
    start, midpoint, ..., end of the last (S sub-steps in all) and ``hs`` (S,).
    """
    ts, hs, _ = _grid(times, steps, h)
    return np.array(ts, dtype=np.float64), np.array(hs, dtype=np.float64)


def _grid(times: Sequence[float] | np.ndarray, steps: int | np.ndarray,
          h: float | None) -> tuple[list[float], list[float], list[int]]:
    """:func:`rk4_times` as Python floats, and the sub-steps of each interval: what :func:`rk4` steps through.

    Built in a Python loop: a coupled interval has a few samples, for which the dozen array operations of the NumPy
    form cost several times the loop (and rk4 reads the floats back one by one). The same operations as that form:
    interval length / its steps, start + j h (the sample t_k itself with one step and no ``h``), start + h / 2.
    """
    t = np.asarray(times, dtype=np.float64).tolist()
    if isinstance(steps, (int, np.integer)):
        counts = [int(steps)] * (len(t) - 1)
    else:
        counts = np.broadcast_to(np.asarray(steps, dtype=np.intp), (len(t) - 1,)).tolist()
    if min(counts, default=0) < 0:  # (the array form refused them in np.repeat; a loop would skip them)
        raise ValueError(f"steps per sample must be >= 0, got {min(counts)}")
    total = sum(counts)
    if total > MAX_STEPS:  # one request must not hold its process for minutes (or ask for gigabytes of times)
        raise PhysicsError(f"{total} RK4 steps asked for in one call ({len(t)} samples); at most {MAX_STEPS}: "
                           "fewer samples or steps per sample (idiv)")
    ts: list[float] = []
    hs: list[float] = []
    if h is None and isinstance(steps, int) and steps == 1:  # the common case: one sub-step per sample interval
        start = t[0]
        for end in t[1:]:
            hk = end - start
            ts.append(start)
            ts.append(start + hk / 2.0)
            hs.append(hk)
            start = end
    else:
        for k, count in enumerate(counts):
            if count > 0:
                hk = (t[k + 1] - t[k]) / count if h is None else float(h)
                for j in range(count):
                    start = t[k] + j * hk
                    ts.append(start)
                    ts.append(start + hk / 2.0)
                    hs.append(hk)
    ts.append(t[-1])  # (a sample time t_k + 0 h is t_k itself)
    return ts, hs, counts


def _axpy_array(y: np.ndarray, f: np.ndarray, c: float) -> np.ndarray:
    return y + f * c


def _rksys_array(y: np.ndarray, k1: np.ndarray, k2: np.ndarray, k3: np.ndarray, k4: np.ndarray, h3: float,
                 h6: float) -> np.ndarray:
    return y + k1 * h6 + k2 * h3 + k3 * h3 + k4 * h6


@functools.lru_cache(maxsize=32)
def _list_steps(n: int) -> tuple[Callable[..., list[float]], Callable[..., list[float]]]:
    """(y + f c, the RKSYS sum) for lists of ``n`` floats, written out element by element: for the 6 or 12 states
    of the satellite models a comprehension over zip costs 2-3 times the plain expressions. Each element is the
    expression of the array form, ``y + f * c`` and ``y + k1 * h6 + k2 * h3 + k3 * h3 + k4 * h6``."""
    axpy = ", ".join(f"y[{i}] + f[{i}] * c" for i in range(n))
    rksys = ", ".join(f"y[{i}] + k1[{i}] * h6 + k2[{i}] * h3 + k3[{i}] * h3 + k4[{i}] * h6" for i in range(n))
    return eval(f"lambda y, f, c: [{axpy}]"), eval(f"lambda y, k1, k2, k3, k4, h3, h6: [{rksys}]")


def rk4(f: Derivative, y0: State, times: Sequence[float] | np.ndarray, steps: int | np.ndarray = 1,
        inputs: Callable[[np.ndarray], Sequence[Any]] | None = None, *, h: float | None = None,
        node: Node | None = None, finish: Callable[[State], State] | None = None,
        end_node: bool = False, euler: bool = False) -> tuple[list[State], list[Any], State]:
    """Classical RK4 (RKSYS operation order) from ``y0`` at ``times[0]`` over the sample ``times``.

    ``f(t, y, row)``: the derivative, ``row`` the input at t (``None`` without ``inputs``). ``inputs(ts)`` is
    called once with :func:`rk4_times` and returns one row per time (``rows[i]`` at ``ts[i]``).
    ``node(t, y, row) -> (dy/dt, keep)``: the evaluation at sub-step starts (default ``f``, keeping dy/dt);
    ``keep`` is collected at the sample times (at the last one too with ``end_node``). ``finish(y)``: applied
    to the state after every sub-step (e.g. renormalising a quaternion). ``y0`` a list of floats or an array:
    the states keep its kind. ``euler``: forward Euler steps instead (y + h f at the sub-step starts; for
    comparisons). Returns (states at the samples, the kept values, the state at ``times[-1]``).
    """
    tl, hl, counts = _grid(times, steps, h)
    rows = inputs(np.array(tl, dtype=np.float64)) if inputs is not None else [None] * len(tl)
    lists = isinstance(y0, list)
    axpy, rksys = _list_steps(len(y0)) if lists else (_axpy_array, _rksys_array)
    y = list(y0) if lists else np.array(y0, dtype=np.float64)
    k1, kept = node(tl[0], y, rows[0]) if node is not None else (f(tl[0], y, rows[0]),) * 2
    states, keeps = [y], [kept]
    i, last = 0, 2 * len(hl)
    for count in counts:
        for _ in range(count):
            hj = hl[i // 2]
            if euler:
                i += 2
                y = axpy(y, k1, hj)
            else:
                h2 = hj / 2.0
                tm, rm = tl[i + 1], rows[i + 1]
                k2 = f(tm, axpy(y, k1, h2), rm)  # RKSYS: Y = YSTART + F*H2, ..., + F*H
                k3 = f(tm, axpy(y, k2, h2), rm)
                i += 2
                k4 = f(tl[i], axpy(y, k3, hj), rows[i])
                y = rksys(y, k1, k2, k3, k4, hj / 3.0, hj / 6.0)  # YTEMP: YSTART + F1*H6 + F2*H3 + F3*H3 + F4*H6
            if finish is not None:
                y = finish(y)
            if i < last or end_node:
                if node is None:
                    k1 = kept = f(tl[i], y, rows[i])
                else:
                    k1, kept = node(tl[i], y, rows[i])
        states.append(y)
        if i < last or end_node:
            keeps.append(kept)
    return states, keeps, y


def as_table(value: Any, k: int, size: int, name: str = "") -> np.ndarray:
    """``value`` as a (k, size) float array; a (size,) value is a constant and stands for all k times."""
    v = np.asarray(value, dtype=np.float64)
    if v.shape == (k, size):
        return v
    if v.shape != (size,):
        raise ValueError(f"input {name!r}: {k} times gave shape {v.shape}, expected ({k}, {size}) "
                         f"(or ({size},) if constant)")
    return np.broadcast_to(v, (k, size))


def input_rows(u: Callable[[np.ndarray], Any], ts: np.ndarray, ports: Mapping[str, Any],
               lists: bool = False) -> list[tuple[Any, ...]]:
    """``u(ts)`` (one call) row by row: per time of ``ts`` a tuple with the value of each input of ``ports``
    (name -> size, or anything with a ``size``), a (size,) array or, with ``lists``, a list of floats (for
    models computing on Python floats)."""
    values = u(ts)
    tables = [as_table(values[name], ts.size, getattr(size, "size", size), name) for name, size in ports.items()]
    return list(zip(*(tab.tolist() for tab in tables))) if lists else list(zip(*tables))


# --- 3-vectors as Python floats (the per-stage hot paths) --------------------------------------------------


def vecnorm(x: Vec) -> tuple[tuple[float, float, float], float]:
    """VECNORM: (unit vector, magnitude); the zero vector gives ((0, 0, 0), 0) (guard needed by RF-C stage 0)."""
    x0, x1, x2 = x
    mag = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    if mag <= 0.0:
        return (0.0, 0.0, 0.0), 0.0
    return (x0 / mag, x1 / mag, x2 / mag), mag


def cross3(a: Vec, b: Vec) -> tuple[Any, Any, Any]:
    """vcross: a x b by components; each component a float, or an array (then a whole column of vectors)."""
    a0, a1, a2 = a
    b0, b1, b2 = b
    return (a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)


def matvec(m: Mat, v: Vec) -> tuple[float, float, float]:
    """MATVEC: m v for a 3x3 matrix given as rows."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = m
    v0, v1, v2 = v
    return (m00 * v0 + m01 * v1 + m02 * v2,
            m10 * v0 + m11 * v1 + m12 * v2,
            m20 * v0 + m21 * v1 + m22 * v2)


def matTvec(m: Mat, v: Vec) -> tuple[float, float, float]:  # noqa: N802 - m^T v
    """TRAN3 then MATVEC: m^T v."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = m
    v0, v1, v2 = v
    return (m00 * v0 + m10 * v1 + m20 * v2,
            m01 * v0 + m11 * v1 + m21 * v2,
            m02 * v0 + m12 * v1 + m22 * v2)


# --- 3-vectors as NumPy arrays ------------------------------------------------------------------------------


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b along the last axis, broadcasting (a lean np.cross: the inner loop of the array models)."""
    if a.ndim == 1 and b.ndim == 1:
        a0, a1, a2 = float(a[0]), float(a[1]), float(a[2])
        b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
        return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])
    if a.shape == b.shape or a.ndim < b.ndim:
        shape = b.shape if a.ndim < b.ndim or a.shape == b.shape else a.shape
    elif b.ndim < a.ndim:
        shape = a.shape
    else:
        shape = np.broadcast_shapes(a.shape, b.shape)
    out = np.empty(shape)
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def skew(a: Vec) -> np.ndarray:
    """a~ with a~ b = a x b."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


# --- the 3-2-1 direction cosine matrix -----------------------------------------------------------------------


def rotation321(s: Vec, c: Vec) -> tuple[tuple[Any, Any, Any], ...]:
    """A = R1(x) R2(y) R3(z) (passive: inertial -> body, v_b = A v_i; Nixon eq. 15) from the sines ``s`` and
    cosines ``c`` of the three angles, as rows. Components may be floats or equal-shape arrays."""
    s1, s2, s3 = s
    c1, c2, c3 = c
    return ((c2 * c3, c2 * s3, -s2),
            (s1 * s2 * c3 - c1 * s3, s1 * s2 * s3 + c1 * c3, s1 * c2),
            (c1 * s2 * c3 + s1 * s3, c1 * s2 * s3 - s1 * c3, c1 * c2))


def dcm321(phi: Vec) -> tuple[tuple[float, float, float], ...]:
    """Eq. 15 for one set of angles (phi_x, phi_y, phi_z) as rows of floats (math trig: the per-stage path)."""
    return rotation321((math.sin(phi[0]), math.sin(phi[1]), math.sin(phi[2])),
                       (math.cos(phi[0]), math.cos(phi[1]), math.cos(phi[2])))


DCM_ARRAYS_FROM = 12  # rows from which eq. 15 on columns beats a loop over the rows (5 rows: 10 against 19 us)


def dcm321_batch(phi: np.ndarray) -> np.ndarray:
    """Eq. 15 vectorised: phi (n, 3) -> A (n, 3, 3).

    The sines and cosines by NumPy, then the products on whole columns or, for the few rows of a coupled interval,
    on the rows' floats: the same operations on the same values, so the same bits either way."""
    phi = np.asarray(phi, dtype=np.float64).reshape(-1, 3)
    if phi.shape[0] < DCM_ARRAYS_FROM:
        rows = [rotation321(s, c) for s, c in zip(np.sin(phi).tolist(), np.cos(phi).tolist())]
        return np.array(rows, dtype=np.float64).reshape(-1, 3, 3)
    a = np.empty((phi.shape[0], 3, 3))
    for i, row in enumerate(rotation321(np.sin(phi).T, np.cos(phi).T)):
        for j, column in enumerate(row):
            a[:, i, j] = column
    return a
