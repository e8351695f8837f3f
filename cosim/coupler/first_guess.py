"""Stage-0 inputs of an interval (the signals not yet known when the interval starts).

- ``zero``: the paper's choice (its general form drops the system input ``vv``).
- ``hold``: the last committed value of each input, held over the interval.
- ``extrapolate``: the previous interval's converged input, continued over the new interval by
  the coupling's interpolation scheme (its end piece).
The first interval of a run has no previous one: every policy starts it with zeros, or with the values a scenario
gives in ``[subsims.<name>.guess]`` (a quaternion or a unit vector cannot be zero), which stand in for the zeros of
``zero`` too.
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
    start: Mapping[str, tuple[float, ...]] | None = None,
) -> dict[str, np.ndarray]:
    """``{signal: (n, size)}`` for every signal in ``sizes``; ``previous`` maps signal -> (times, values); ``start``
    maps a signal to its value where no value is known (the zeros otherwise)."""
    if policy not in POLICIES:
        raise ValueError(f"unknown first-guess policy {policy!r}; known: {', '.join(POLICIES)}")
    guess = {}
    for name, size in sizes.items():
        if policy == "zero" or not previous or name not in previous:
            known = None if start is None else start.get(name)
            guess[name] = np.zeros((times.size, size)) if known is None else np.tile(
                np.asarray(known, dtype=np.float64), (times.size, 1))
        elif policy == "hold":
            guess[name] = np.tile(previous[name][1][-1], (times.size, 1))
        else:
            t_prev, v_prev = previous[name]
            if interp == "cubic":  # beyond its end the piecewise cubic is its last piece: the last 4 samples
                t_prev, v_prev = t_prev[-4:], v_prev[-4:]
            # the previous interval's converged input: checked data already; all times in one call
            guess[name] = interpolant(t_prev, v_prev, interp)(times)
    return guess
