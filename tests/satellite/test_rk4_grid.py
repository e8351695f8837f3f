"""The RK4 grid that ``rk4`` steps through, against the same grid built with array operations."""

from __future__ import annotations

import numpy as np
import pytest

from subsims.numerics import rk4_times


def grid_by_arrays(times: np.ndarray, steps: int | list[int], h: float | None) -> tuple[np.ndarray, np.ndarray]:
    """Sub-step starts t_k + j h_k, midpoints start + h_k / 2, and the last time; h_k = (t_k+1 - t_k) / count_k."""
    t = np.asarray(times, dtype=np.float64)
    count = np.broadcast_to(np.asarray(steps, dtype=np.intp), (t.size - 1,))
    interval = np.repeat(np.arange(t.size - 1), count)
    j = np.arange(interval.size) - np.repeat(np.cumsum(count) - count, count)
    hs = (t[1:] - t[:-1])[interval] / count[interval] if h is None else np.full(interval.size, float(h))
    starts = t[interval] + j * hs
    ts = np.empty(2 * hs.size + 1)
    ts[0:-1:2], ts[1::2], ts[-1] = starts, starts + hs / 2.0, t[-1]
    return ts, hs


@pytest.mark.parametrize(("steps", "h"), [(1, None), (3, None), ([1, 0, 2, 5], None), (2, 0.013), ([2, 1, 1, 3], 0.01)])
def test_the_grid_is_the_array_forms_bit_for_bit(steps: int | list[int], h: float | None) -> None:
    rng = np.random.default_rng(7)
    for _ in range(200):
        times = np.cumsum(rng.uniform(1e-3, 1.0, 5)) + rng.uniform(-1e3, 1e3)
        ts, hs = rk4_times(times, np.asarray(steps) if isinstance(steps, list) else steps, h)
        want_ts, want_hs = grid_by_arrays(times, steps, h)
        assert ts.tobytes() == want_ts.tobytes() and hs.tobytes() == want_hs.tobytes()


def test_a_negative_step_count_is_refused() -> None:
    # (a loop over the counts would skip it, and the total would then be under the cap by it)
    with pytest.raises(ValueError, match="steps per sample must be >= 0, got -1000000"):
        rk4_times(np.array([0.0, 1.0, 2.0]), np.array([-10**6, 10**6 + 1]))
