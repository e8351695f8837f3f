"""A centralized (Jacobi) stage takes about as long as its slowest subsim, not the sum.

Three integrator processes, each sleeping ``--delay`` seconds per run_interval (a stand-in for
a model that computes for that long), coupled in a ring a -> b -> c -> a. Prints the wall time
per stage for RF-C (concurrent) and RF-D (in order) over Zenoh, and for RF-C in-process.

    python benchmarks/parallel_stage.py [--delay 0.02] [--intervals 10]
"""

from __future__ import annotations

import argparse
import time

from cosim.coupler.convergence import Tolerance
from cosim.coupler.couplings import Coupling
from cosim.coupler.relaxation import Settings
from cosim.driver import Coordinator
from cosim.handles import InProcessHandle
from cosim.launch import Bus
from subsims.integrator.subsim import Integrator

NAMES = ("a", "b", "c")
RING = [Coupling.make("a.u", "c.y", "gain", {"k": -0.5}), Coupling.make("b.u", "a.y"), Coupling.make("c.u", "b.y")]


def per_stage(handles: dict, method: str, intervals: int) -> tuple[float, float]:
    settings = Settings(method=method, interval=0.1, samples=5, tol=Tolerance(1e-9, 1e-12), first_guess="zero")
    coordinator = Coordinator(handles, RING, settings)
    started = time.perf_counter()
    summary = coordinator.run(0.0, 0.1 * intervals)
    wall = time.perf_counter() - started
    stages = sum(k * v for k, v in summary.stages.items())
    return wall / stages, stages / summary.intervals


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--delay", type=float, default=0.02, help="seconds each subsim computes per run")
    p.add_argument("--intervals", type=int, default=10)
    args = p.parse_args()
    params = {"compute_delay": args.delay, "y0": [1.0]}
    rows = []
    with Bus.open() as bus:
        handles = {n: bus.spawn("subsims.integrator", n, quiet=True).handle for n in NAMES}
        for method in ("centralized", "distributed"):
            for h in handles.values():
                h.configure(params)
            rows.append((f"{method}, 3 processes over Zenoh", *per_stage(handles, method, args.intervals)))
    local = {n: InProcessHandle(Integrator(), n) for n in NAMES}
    for h in local.values():
        h.configure(params)
    rows.append(("centralized, in-process (sequential)", *per_stage(local, "centralized", args.intervals)))
    print(f"3 subsims x {args.delay * 1e3:.0f} ms of compute each; slowest = {args.delay * 1e3:.0f} ms, "
          f"sum = {3 * args.delay * 1e3:.0f} ms")
    print(f"{'run':40s} {'ms per stage':>13s} {'stages/interval':>16s}")
    for name, stage, stages in rows:
        print(f"{name:40s} {stage * 1e3:13.1f} {stages:16.2f}")


if __name__ == "__main__":
    main()
