"""Stage-0 inputs of an interval (the signals not yet known when the interval starts).

- ``zero``: the paper's choice (its general form drops the system input ``vv``).
- ``hold``: the last committed value of each input, held over the interval.
- ``extrapolate``: the previous interval's converged input, continued over the new interval by
  the coupling's interpolation scheme (its end piece).
The first interval of a run has no previous one: every policy starts it with zeros.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from cosim.signals import interpolant

POLICIES = ("zero", "hold", "extrapolate")


def first_guess(
    policy: str,
    times: np.ndarray,
    sizes: Mapping[str, int],
    previous: Mapping[str, tuple[np.ndarray, np.ndarray]] | None,
    interp: str = "linear",
) -> dict[str, np.ndarray]:
    """``{signal: (n, size)}`` for every signal in ``sizes``; ``previous`` maps signal -> (times, values)."""
    if policy not in POLICIES:
        raise ValueError(f"unknown first-guess policy {policy!r}; known: {', '.join(POLICIES)}")
    guess = {}
    for name, size in sizes.items():
        if policy == "zero" or not previous or name not in previous:
            guess[name] = np.zeros((times.size, size))
        elif policy == "hold":
            guess[name] = np.tile(previous[name][1][-1], (times.size, 1))
        else:
            t_prev, v_prev = previous[name]
            if interp == "cubic":  # beyond its end the piecewise cubic is its last piece: the last 4 samples
                t_prev, v_prev = t_prev[-4:], v_prev[-4:]
            # the previous interval's converged input: checked data already; all times in one call
            guess[name] = interpolant(t_prev, v_prev, interp)(times)
    return guess
