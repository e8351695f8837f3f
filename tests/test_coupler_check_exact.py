"""convergence.check (all signals' channels at once, laid out for fast reductions) gives, bit for bit, what
convrg gives signal by signal on each signal's own (n, size) samples: residuals, pass flags, the largest
residuals and the converged flag; on random data of every scale with ties, zeros of both signs and NaN."""

from __future__ import annotations

import numpy as np
import pytest

from cosim.coupler.convergence import Tolerance, check

VALUES = [0.0, -0.0, 1.0, -1.0, 1e-300, 5e-324, 1e300, 3.0, np.nan]


def _reference(new: dict, old: dict, default: Tolerance, per_signal: dict) -> tuple[dict, dict, dict]:
    """Signal by signal, as the paper's convrg: max |new - old| and the span of new, per channel."""
    residuals, passed, largest = {}, {}, {}
    for k in new:
        t = per_signal.get(k, default)
        r = np.abs(new[k] - old[k]).max(axis=0)
        span = np.abs(new[k].max(axis=0) - new[k].min(axis=0))
        residuals[k], passed[k] = r, (r <= t.rel * span) | (r <= t.abs)
        largest[k] = float(r.max(initial=0.0)) if r.size else 0.0
    return residuals, passed, largest


def _bits(x: np.ndarray) -> bytes:
    return np.where(np.isnan(x), np.nan, x).tobytes()  # any NaN as the same NaN: NaN is compared as NaN


@pytest.mark.parametrize("n", [2, 5, 65])
@pytest.mark.parametrize("per_signal", [False, True])
def test_check_equals_convrg_signal_by_signal(n: int, per_signal: bool) -> None:
    rng = np.random.default_rng(n + per_signal)
    for _ in range(40):
        widths = rng.integers(1, 5, size=rng.integers(1, 6))
        new, old = {}, {}
        for i, w in enumerate(widths):
            v = rng.normal(size=(n, w)) * 10.0 ** rng.integers(-20, 20)
            v.flat[rng.integers(0, v.size, size=2)] = rng.choice(VALUES, 2, p=[0.2, 0.2, 0.1, 0.1, 0.1, 0.1, 0.1, 0.09,
                                                                              0.01])
            d = np.where(rng.random(v.shape) < 0.5, 0.0, rng.normal(size=v.shape) * 10.0 ** rng.integers(-16, 0))
            new[f"s{i}.y"], old[f"s{i}.y"] = v, v + d * np.abs(v)
        tolerances = {"s0.y": Tolerance(1e-3, 0.0), "s2.y": Tolerance(0.0, 1e-9)} if per_signal else {}
        default = Tolerance(1e-12, 1e-14)
        with np.errstate(invalid="ignore", over="ignore"):
            result = check(new, old, default, tolerances)
            residuals, passed, largest = _reference(new, old, default, tolerances)
        assert list(result.residuals) == list(new)
        for k in new:
            assert _bits(result.residuals[k]) == _bits(residuals[k])
            np.testing.assert_array_equal(result.passed[k], passed[k])
        assert _bits(np.array(list(result.largest_each.values()))) == _bits(np.array(list(largest.values())))
        assert result.converged is all(p.all() for p in passed.values())
