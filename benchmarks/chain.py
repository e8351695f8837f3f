"""Cost against the number of subsims: a chain of N oscillator masses, each its own process.

Mass i feels its neighbours through coupling springs, F_i = k_c (u_{i-1} + u_{i+1}) (the built-in
``linear`` transform; each mass carries its own -k_c u_i terms in its ground stiffness), and mass 0
starts displaced. Distributed coupling (RF-D) over Zenoh. For each N it prints the order's feedback
signals, the time to derive the order, the stages per interval, and the marginal wall time per
interval (the run to ``--stop`` minus the run to ``--stop / 10``, so start-up cancels), then the
growth from the smallest to the largest N. The sizes run interleaved, ``--repeats`` times, and the growth is
taken per repeat (median and range), so a load drift hits every N alike. Asserts nothing.

    python benchmarks/chain.py [--sizes 4 8 16] [--stop 5.0] [--repeats 3] [--method distributed]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from cosim.coupler.order import derive_order, feedback_weight
from cosim.runner import run_scenario
from cosim.scenario import Scenario, parse

K_GROUND, K_COUPLE = 4.0, 2.0


def chain_scenario(n: int, method: str, stop: float) -> Scenario:
    subsims, couplings = {}, []
    for i in range(n):
        neighbours = [j for j in (i - 1, i + 1) if 0 <= j < n]
        subsims[f"m{i}"] = {"model": "subsims.oscillator.subsim:Mass",
                            "params": {"m": 1.0, "k": K_GROUND + K_COUPLE * len(neighbours),
                                       "u0": 1.0 if i == 0 else 0.0}}
        couplings.append({"to": f"m{i}.F", "from": [f"m{j}.u" for j in neighbours], "transform": "linear",
                          "params": {"gains": [K_COUPLE] * len(neighbours)}})
    raw = {"name": f"chain{n}", "stop": stop, "subsims": subsims, "couplings": couplings,
           "coupling": {"method": method, "interval": 0.05, "samples": 5, "interp": "cubic",
                        "first_guess": "extrapolate", "tol": 1e-10, "res": 1e-12, "max_stages": 60}}
    return parse(raw, Path(f"chain{n}.toml"))


def timed_run(scenario: Scenario, method: str, stop: float, out: Path) -> tuple[float, int, int, int]:
    started = time.perf_counter()
    report = run_scenario(scenario, method=method, stop=stop, output=out, progress=False, log=lambda _m: None)
    wall = time.perf_counter() - started
    s = report.summary
    return wall, s.intervals, sum(k * v for k, v in s.stages.items()), s.round_trips


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[4, 8, 16])
    p.add_argument("--stop", type=float, default=5.0)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--method", default="distributed", choices=["distributed", "centralized"])
    a = p.parse_args()
    if a.repeats < 1:
        p.error(f"--repeats must be at least 1, got {a.repeats}")
    if a.stop < 0.5:  # H = 0.05 s: the short run (stop / 10) must end intervals before the full one
        p.error(f"--stop must be at least 0.5 s (ten intervals of 0.05 s; the short run goes to stop / 10), "
                f"got {a.stop}")
    scenarios = {n: chain_scenario(n, a.method, a.stop) for n in a.sizes}
    order_info = {}
    for n, sc in scenarios.items():
        sizes = {c.target: 1 for c in sc.couplings}
        t0 = time.perf_counter()
        order = derive_order(list(sc.subsims), sc.couplings, sizes)
        order_info[n] = (feedback_weight(order, sc.couplings, sizes), time.perf_counter() - t0)
    marginal: dict[int, list[float]] = {n: [] for n in a.sizes}
    stages: dict[int, float] = {}
    trips: dict[int, float] = {}  # sequential round trips (Run actions) per interval
    with tempfile.TemporaryDirectory() as tmp:
        for rep in range(a.repeats):
            for n, sc in scenarios.items():
                short = timed_run(sc, a.method, a.stop / 10, Path(tmp) / f"s{n}.csv")
                full = timed_run(sc, a.method, a.stop, Path(tmp) / f"f{n}.csv")
                marginal[n].append((full[0] - short[0]) / (full[1] - short[1]))
                stages[n] = full[2] / full[1]
                trips[n] = full[3] / full[1]
                print(f"  repeat {rep + 1}: N = {n:2d}: {marginal[n][-1] * 1e3:.2f} ms per interval", flush=True)
    print(f"chain of N masses, {a.method} over Zenoh, H = 0.05 s, 5 samples, cubic, to t = {a.stop:g} s, "
          f"{a.repeats} interleaved repeats")
    print("|  N | feedback signals | order derived in | stages/interval | round trips/interval "
          "| marginal ms/interval, median (range) |")
    print("|---:|-----------------:|-----------------:|----------------:|---------------------:"
          "|-------------------------------------:|")
    for n in a.sizes:
        fb, d = order_info[n]
        m = marginal[n]
        print(f"| {n:2d} | {fb:16d} | {d * 1e3:13.1f} ms | {stages[n]:15.2f} | {trips[n]:20.2f} | "
              f"{statistics.median(m) * 1e3:14.2f} ({min(m) * 1e3:.2f}-{max(m) * 1e3:.2f}) |")
    first, last = a.sizes[0], a.sizes[-1]
    growth = [b / f for f, b in zip(marginal[first], marginal[last])]
    print(f"\nN {first} -> {last}: marginal cost per interval grows {statistics.median(growth):.2f}x "
          f"(per repeat {', '.join(f'{g:.2f}' for g in growth)}; N grew {last / first:.1f}x; target <= 4.6x from 4 "
          f"to 16), stages/interval {stages[first]:.2f} -> {stages[last]:.2f}")


if __name__ == "__main__":
    main()
