"""The paper's convergence check ``convrg`` (spec §3.5), per scalar signal, with per-signal tolerances.

A scalar signal has converged when, over the interval's samples,

    max |new - old| <= rel * (max(new) - min(new))   or   max |new - old| <= abs

(the span is that of the newest stage). Every checked signal must pass.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Tolerance:
    rel: float  # the paper's tol (span-normalised)
    abs: float  # the paper's res

    def __post_init__(self) -> None:
        for name in ("rel", "abs"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not np.isfinite(v) or v < 0:
                raise ValueError(f"tolerance {name} must be a finite number >= 0, got {v!r}")


@dataclass(frozen=True)
class Check:
    """Residuals of one stage: per signal name, the per-channel max |new - old|, and pass flags."""

    residuals: dict[str, np.ndarray]
    passed: dict[str, np.ndarray]

    @property
    def converged(self) -> bool:
        return all(bool(p.all()) for p in self.passed.values())

    @property
    def failing(self) -> list[str]:
        return [name for name, p in self.passed.items() if not p.all()]

    @property
    def largest(self) -> float:
        return max((float(r.max()) for r in self.residuals.values() if r.size), default=0.0)


def convrg(new: np.ndarray, old: np.ndarray, tol: Tolerance) -> tuple[np.ndarray, np.ndarray]:
    """Per channel of (n, m) samples: (max |new - old|, converged?)."""
    check1 = np.abs(new - old).max(axis=0)
    span = np.abs(new.max(axis=0) - new.min(axis=0))
    return check1, (check1 <= tol.rel * span) | (check1 <= tol.abs)


def check(
    new: Mapping[str, np.ndarray],
    old: Mapping[str, np.ndarray],
    default: Tolerance,
    per_signal: Mapping[str, Tolerance] | None = None,
) -> Check:
    per_signal = per_signal or {}
    residuals, passed = {}, {}
    for name, value in new.items():
        residuals[name], passed[name] = convrg(value, old[name], per_signal.get(name, default))
    return Check(residuals, passed)
