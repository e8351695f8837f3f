"""How fast faults are found and healed: a subsim SIGKILLed or SIGSTOPped mid-run, over Zenoh.

Three integrator processes in a ring, RF-C, default deadline (the largest of 1.5 s, 50x the median and 3x the
slowest of the recent runs, each run timed from its requests going out to its last reply). For each
fault, repeated ``--repeat`` times: the time from the signal to the moment the coordinator asks for a
replacement (detection), and to the moment the replacement is restored and the run goes on (healed).
Prints medians and maxima; asserts nothing.

    python benchmarks/faults.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import time

from cosim.coupler.convergence import Tolerance
from cosim.coupler.couplings import Coupling
from cosim.coupler.relaxation import Settings
from cosim.driver import Coordinator, Recovery
from cosim.launch import Bus

RING = [Coupling.make("a.u", "c.y", "gain", {"k": -0.8}), Coupling.make("b.u", "a.y"), Coupling.make("c.u", "b.y")]
PARAMS = {"a": {"y0": [1.0]}, "b": {"y0": [0.5]}, "c": {"y0": [-0.25]}}


def one(sig: int) -> tuple[float, float]:
    with Bus.open() as bus:
        handles = {n: bus.spawn("subsims.integrator", n, quiet=True).handle for n in PARAMS}
        for n, h in handles.items():
            h.configure(PARAMS[n])
        marks: dict[str, float] = {}

        def revive(name: str, why: str):
            marks.setdefault("detected", time.monotonic())
            handle = bus.respawn(name, quiet=True).handle
            handle.configure(PARAMS[name])
            return handle

        recovery = Recovery(revive, restarts=1, log=lambda m: marks.setdefault("healed", time.monotonic()))
        settings = Settings(method="centralized", interval=0.1, samples=4, tol=Tolerance(1e-12, 1e-14))
        coordinator = Coordinator(handles, RING, settings, recovery=recovery)
        victim = next(p.popen.pid for p in bus.processes if p.name == "b")

        def on_interval(iv) -> None:
            if "signal" not in marks and iv.t[-1] >= 2.0:  # after 20 intervals: the deadline has adapted
                marks["signal"] = time.monotonic()
                os.kill(victim, sig)

        try:
            coordinator.run(0.0, 4.0, on_interval)
        finally:
            try:
                os.kill(victim, signal.SIGKILL)
            except ProcessLookupError:
                pass
        return marks["detected"] - marks["signal"], marks["healed"] - marks["signal"]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--repeat", type=int, default=5)
    a = p.parse_args()
    if a.repeat < 1:
        p.error(f"--repeat must be at least 1, got {a.repeat}")
    print("| fault | detected after: median, max (s) | run going again after: median, max (s) |")
    print("|---|---|---|")
    for name, sig in (("SIGKILL of a subsim", signal.SIGKILL), ("SIGSTOP of a subsim", signal.SIGSTOP)):
        runs = [one(sig) for _ in range(a.repeat)]
        det, heal = [r[0] for r in runs], [r[1] for r in runs]
        print(f"| {name} | {statistics.median(det):.3f}, {max(det):.3f} | "
              f"{statistics.median(heal):.3f}, {max(heal):.3f} |")


if __name__ == "__main__":
    main()
