"""docs/protocol.md section 6.5: the interpolation schemes are the polynomials it defines, within the
tolerance it states, on the equally spaced grids a coordinator sends.

The expected values are the Lagrange polynomials evaluated in exact rational arithmetic
(``fractions``), with none of the code under test.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from cosim.coupler.relaxation import sample_times
from cosim.signals import interpolant

EPS = float(np.finfo(np.float64).eps)
BOUND = 64  # docs/protocol.md: |u(x) - p(x)| <= 64 eps sum_j |l_j(x) U_j|


def exact(nodes: np.ndarray, values: np.ndarray, x: float) -> tuple[Fraction, float]:
    """p(x) through (nodes, values), exactly, and the condition sum_j |l_j(x) U_j|."""
    t, fx = [Fraction(v) for v in nodes], Fraction(x)
    total, cond = Fraction(0), Fraction(0)
    for j, tj in enumerate(t):
        lj = Fraction(1)
        for k, tk in enumerate(t):
            if k != j:
                lj *= (fx - tk) / (tj - tk)
        total += Fraction(values[j]) * lj
        cond += abs(Fraction(values[j]) * lj)
    return total, float(cond)


def piece(scheme: str, times: np.ndarray, x: float) -> slice:
    """The samples section 6.5 says the value at x is made from."""
    n = times.size
    if scheme == "lagrange" or (scheme == "cubic" and n <= 4):
        return slice(0, n)
    i = min(max(int(np.searchsorted(times, x, side="right")) - 1, 0), n - 2)
    if scheme == "linear":
        return slice(i, i + 2)
    s = min(max(i - 1, 0), n - 4)
    return slice(s, s + 4)


@pytest.mark.parametrize("scheme", ["linear", "cubic", "lagrange"])
def test_schemes_are_the_documented_polynomials_within_the_stated_tolerance(scheme: str) -> None:
    rng = np.random.default_rng(65)
    for _ in range(150):
        n = int(rng.integers(2, 11))
        t0 = float(rng.uniform(-1e3, 1e5))
        times = sample_times(t0, t0 + 10 ** rng.uniform(-3, 2), n)
        values = rng.normal(size=(n, 1)) * 10 ** rng.uniform(-6, 6)
        at = interpolant(times, values, scheme)
        for i in range(n):  # the samples themselves, exactly
            assert at(float(times[i]))[0] == values[i, 0]
        span = times[-1] - times[0]
        for x in times[0] + span * rng.uniform(-0.05, 1.05, 12):  # inside, and the end pieces extended by 5 %
            s = piece(scheme, times, x)
            p, cond = exact(times[s], values[s, 0], float(x))
            err = abs(Fraction(float(at(float(x))[0])) - p)
            assert err <= BOUND * EPS * cond, (scheme, n, x, float(err), cond)
