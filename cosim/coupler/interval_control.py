"""Automatic convergence-interval control (the paper's §9 future work), sans-IO: pure functions.

An interval's samples are ``n`` equally spaced times (``samples``, fixed), so its length ``H`` sets the
sample spacing ``h = H / (n - 1)``: the spacing at which every coupled signal is interpolated for the
subsims that read it (and, for the shipped models, their own integration step).

The error estimate. Once an interval has converged, each coupled input signal is known only at its
samples; between them the receiving subsim sees the coupling's interpolant (``interp``). For an
interpolant of polynomial degree ``p`` through ``p + 1`` equally spaced samples the remainder is

    f(t) - P(t) = f^(p+1)(xi) / (p+1)! * prod_j (t - t_j),

and the ``(p+1)``-th finite difference of the samples is ``Delta^(p+1) f = h^(p+1) f^(p+1)(xi')``. So

    |f - P| <= C_p * max |Delta^(p+1) f|,   C_p = max_{s in [0, p]} |prod_{j=0..p} (s - j)| / (p+1)!

(C_1 = 1/8 for linear, C_3 = 1/24 for the end pieces of the piecewise cubic) is the leading term of the
interpolation error, read from the converged samples alone: no extra run, no clock. It is the
classical finite-difference estimate of the Newton remainder, sound while the signal's
``(p+1)``-th derivative varies little over ``p + 2`` samples; that is also when the interval is
resolved at all. For ``lagrange`` (one polynomial through all ``n`` samples) an interval has too few
samples for ``Delta^n``: the estimate is then that of the degree ``n - 2`` interpolant (``Delta^(n-1)``),
an upper bound for smooth signals, so the controller is conservative there.

Per scalar channel the estimate is compared with ``interval_tol`` times the channel's largest
magnitude so far in the run (this interval included: a signal crossing zero keeps its scale), or with
the convergence check's absolute tolerance ``res`` when that is larger (the samples are settled only to
it: asking the interpolation to be finer would shrink intervals for nothing); the interval's *error
ratio* is the largest such quotient over all coupled inputs. An interval is accepted when its ratio
is <= 1.

The controller (what :class:`~cosim.coupler.relaxation.Relaxation` does with it):

- ratio > 1: the interval is rolled back and retried with ``H * max(0.2, 0.8 ratio^(-1/q))``, where
  ``q = p + 1`` is the estimate's order in ``H`` (n fixed);
- not converged in ``max_stages``, or diverging (a residual grown past 100 times its first ones), or stalled
  (a signal's residuals neither falling nor growing over 16 stages without a pass), or a run overflowed on the
  iterates: rolled back and retried on half the length; for the next 16 intervals the
  length then stays below 3/4 of the failed one (no growing straight back into it);
- accepted: the next interval is ``H`` times the smaller of the error factor (at most 2) and a stage
  factor: 2 while intervals converge in fewer than ``interval_stages`` stages, 1 at that many, and
  ``interval_stages / stages`` (at least 1/2) above it. Within ``[interval_min, interval_max]``.
An interval already at ``interval_min`` that still fails the estimate is accepted (its ratio is
in the diagnostics); one that does not converge there raises ``NotConverged``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

GROW = 2.0  # largest growth from one interval to the next
SHRINK = 0.2  # largest shrink of a rejected interval
SAFETY = 0.8  # aim below the tolerance


@dataclass(frozen=True)
class IntervalControl:
    """The automatic interval's settings (``interval = "auto"``)."""

    tol: float = 1e-8  # interval_tol: accepted interpolation error / channel magnitude
    initial: float = 0.1  # interval_initial, s
    minimum: float = 1e-3  # interval_min, s
    maximum: float = 100.0  # interval_max, s
    stages: int = 3  # interval_stages: grow below it, hold at it, shrink above it

    def __post_init__(self) -> None:
        for name, key in (("tol", "interval_tol"), ("initial", "interval_initial"), ("minimum", "interval_min"),
                          ("maximum", "interval_max")):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise ValueError(f"{key} must be a positive number, got {v!r}")
        if not self.minimum <= self.initial <= self.maximum:
            raise ValueError(f"need interval_min <= interval_initial <= interval_max, got "
                             f"{self.minimum!r}, {self.initial!r}, {self.maximum!r}")
        if isinstance(self.stages, bool) or not isinstance(self.stages, int) or self.stages < 2:
            raise ValueError(f"interval_stages must be an integer >= 2, got {self.stages!r}")

    def clip(self, H: float) -> float:
        return min(max(H, self.minimum), self.maximum)


def degree(scheme: str, samples: int) -> int:
    """Polynomial degree ``p`` whose remainder the estimate uses (see the module docstring)."""
    if scheme == "linear":
        return 1
    if scheme == "cubic":
        return min(3, samples - 2)
    if scheme == "lagrange":
        return samples - 2
    raise ValueError(f"no interval error estimate for interpolation scheme {scheme!r}")


@functools.cache
def remainder_constant(p: int) -> float:
    """C_p = max over s in [0, p] of |prod_{j=0..p} (s - j)| / (p+1)!  (C_1 = 1/8, C_3 = 1/24)."""
    s = np.linspace(0.0, p, 2001 * p)
    w = np.prod(s[:, None] - np.arange(p + 1)[None, :], axis=1)
    return float(np.abs(w).max()) / math.factorial(p + 1)


def interpolation_error(values: np.ndarray, p: int) -> np.ndarray:
    """Per channel of equally spaced samples ``values`` (n, m): the estimated largest error of the
    degree-``p`` interpolant between them, ``C_p max |Delta^(p+1) values|`` (zeros when n < p + 2)."""
    v = np.asarray(values, dtype=np.float64)
    if v.shape[0] < p + 2:
        return np.zeros(v.shape[1])
    return remainder_constant(p) * np.abs(np.diff(v, n=p + 1, axis=0)).max(axis=0)


def magnitudes(
    inputs: Mapping[str, np.ndarray], seen: Mapping[str, np.ndarray] | None = None
) -> dict[str, np.ndarray]:
    """Per signal and channel, the largest magnitude in ``inputs`` and in ``seen`` (earlier intervals)."""
    seen = seen or {}
    out = {}
    for signal, values in inputs.items():
        m = np.abs(np.asarray(values, dtype=np.float64)).max(axis=0)
        out[signal] = np.maximum(m, seen[signal]) if signal in seen else m
    return out


def error_ratio(
    inputs: Mapping[str, np.ndarray], scheme: str, tol: float, seen: Mapping[str, np.ndarray] | None = None,
    floor: float = 0.0,
) -> tuple[float, str]:
    """The interval's error ratio (<= 1: accepted) over the coupled input signals, and the worst signal.

    Each channel's estimate over ``tol`` times its largest magnitude so far (this interval and ``seen``,
    the earlier intervals' largest: a signal crossing zero keeps its scale), or over ``floor`` when that
    is larger: the convergence check's absolute tolerance, below which the samples themselves are not
    settled, so no interval length could bring the estimate lower. A channel that has been zero
    throughout has no interpolation error."""
    worst, name = 0.0, ""
    scales = magnitudes(inputs, seen)
    for signal, values in inputs.items():
        v = np.asarray(values, dtype=np.float64)
        if v.shape[0] < 3:
            continue
        est = interpolation_error(v, degree(scheme, v.shape[0]))
        scale = np.maximum(tol * scales[signal], floor)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(est > 0, est / np.where(scale > 0, scale, np.inf), 0.0)
        r = float(ratio.max(initial=0.0))
        if r > worst or not name:
            worst, name = r, signal
    return worst, name


def order(scheme: str, samples: int) -> int:
    """The estimate's order in H at a fixed number of samples: p + 1."""
    return degree(scheme, samples) + 1


def error_factor(ratio: float, q: int) -> float:
    """Length factor that brings the error ratio to ``SAFETY`` (the estimate scales as H^q)."""
    if ratio <= 0:
        return GROW
    return min(GROW, max(SHRINK, SAFETY * ratio ** (-1.0 / q)))


def stage_factor(stages: int, target: int) -> float:
    if stages < target:
        return GROW
    if stages == target:
        return 1.0
    return max(0.5, target / stages)


def retry_length(H: float, ratio: float, q: int, control: IntervalControl) -> float:
    """The length to retry a rejected interval with (ratio > 1: the error; ratio = inf: not converged)."""
    factor = 0.5 if math.isinf(ratio) else min(0.9, error_factor(ratio, q))
    return control.clip(H * factor)


def next_length(H: float, ratio: float, stages: int, q: int, control: IntervalControl) -> float:
    """The next interval's length after an accepted interval of length ``H``."""
    return control.clip(H * min(error_factor(ratio, q), stage_factor(stages, control.stages)))
