"""The paper's convergence check ``convrg`` (spec §3.5), per scalar signal, with per-signal tolerances.

A scalar signal has converged when, over the interval's samples,

    max |new - old| <= rel * (max(new) - min(new))   or   max |new - old| <= abs

(the span is that of the newest stage). Every checked signal must pass.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from itertools import accumulate
from typing import Any

import numpy as np

_max, _min = np.maximum.reduce, np.minimum.reduce


@dataclass(frozen=True)
class Tolerance:
    rel: float  # the paper's tol (span-normalised)
    abs: float  # the paper's res

    def __post_init__(self) -> None:
        for name in ("rel", "abs"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not np.isfinite(v) or v < 0:
                key = "tol" if name == "rel" else "res"  # (as a scenario names them)
                raise ValueError(f"{key} (Tolerance.{name}) must be a finite number >= 0, got {v!r}")


@dataclass(frozen=True)
class Check:
    """Residuals of one stage: per signal name, the per-channel max |new - old|, and pass flags."""

    residuals: dict[str, np.ndarray]
    passed: dict[str, np.ndarray]
    converged: bool  # every channel of every signal passed
    largest_each: dict[str, float]  # per signal, its largest residual (0 if it has no channel)

    @property
    def failing(self) -> list[str]:
        return [name for name, p in self.passed.items() if not p.all()]

    @property
    def largest(self) -> float:
        return max(self.largest_each.values(), default=0.0)


def convrg(new: np.ndarray, old: np.ndarray, tol: Tolerance | tuple[Any, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Per channel of (n, m) samples: (max |new - old|, converged?). ``tol``: a Tolerance, or (rel, abs) as
    numbers or per-channel arrays."""
    rel, ab = (tol.rel, tol.abs) if isinstance(tol, Tolerance) else tol
    check1 = _max(np.abs(new - old), 0)  # ndarray.max without its Python wrapper: a stage's check is a hot path
    span = np.abs(_max(new, 0) - _min(new, 0))
    # check1 <= rel * span or check1 <= ab, in two operations instead of three: fmax takes the one bound that is
    # not NaN (a NaN bound passes nothing either way)
    return check1, check1 <= np.fmax(rel * span, ab)


def check(
    new: Mapping[str, np.ndarray],
    old: Mapping[str, np.ndarray],
    default: Tolerance,
    per_signal: Mapping[str, Tolerance] | None = None,
) -> Check:
    """``convrg`` of every signal, done once over all their channels side by side (per channel, the same
    operations as signal by signal, so the same bits; a stage's check costs a few array operations, not a
    few per signal)."""
    names = list(new)
    if not names:
        return Check({}, {}, True, {})
    widths = [new[k].shape[1] for k in names]
    # channels side by side, (samples, channels): the reductions over samples are exact (max and min give the same
    # bits in any order or layout)
    a = np.concatenate([new[k] for k in names], 1)
    b = np.concatenate([old[k] for k in names], 1)
    tol: tuple[Any, Any] = (default.rel, default.abs)
    if per_signal and any(k in per_signal for k in names):
        each = [per_signal.get(k, default) for k in names]
        tol = (np.repeat([t.rel for t in each], widths), np.repeat([t.abs for t in each], widths))
    residual, ok = convrg(a, b, tol)
    ends = list(accumulate(widths))
    starts = [e - w for e, w in zip(ends, widths)]
    residuals = {k: residual[i:j] for k, i, j in zip(names, starts, ends)}
    passed = {k: ok[i:j] for k, i, j in zip(names, starts, ends)}
    if all(widths):
        largest = dict(zip(names, np.maximum.reduceat(residual, starts).tolist()))
    else:
        largest = {k: float(r.max(initial=0.0)) for k, r in residuals.items()}
    return Check(residuals, passed, bool(np.count_nonzero(ok) == ok.size), largest)
