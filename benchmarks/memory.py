"""Resident memory of the coordinator and of each subsim process over one run: is it flat in run length?

    python benchmarks/memory.py                                    # case 1, RF-D over Zenoh, 20,000 s
    python benchmarks/memory.py --stop 4000 --method centralized
    python benchmarks/memory.py --inprocess                        # the same run with no transport

Runs the scenario and reads the resident set size (VmRSS in /proc, Linux) of this process and of every
subsim process it started at each tenth of the run, with the number of requests sent so far. Prints the
table, then for each process the RSS at 10 % and at 100 % of the run and their ratio, and the growth per
10,000 requests between the two. Exits 1 if some process's RSS at 100 % differs from its RSS at 10 % by
more than ``--tolerance`` (default 10 %).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.coupler.relaxation import Interval  # noqa: E402
from cosim.protocol.transport.client import RemoteHandle  # noqa: E402
from cosim.runner import run_scenario  # noqa: E402
from cosim.scenario import load  # noqa: E402


def rss_kib(pid: int | str = "self") -> int | None:
    """Resident set size of a process in KiB (None if it is gone)."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def child_pids() -> list[int]:
    """PIDs of this process's children (every thread's list: /proc/<pid>/task/<tid>/children)."""
    pids: set[int] = set()
    for task in Path("/proc/self/task").iterdir():
        try:
            pids.update(int(p) for p in (task / "children").read_text().split())
        except OSError:
            pass
    return sorted(pids)


class RequestCounter:
    """Counts the requests every RemoteHandle sends (wraps ``RemoteHandle._begin`` while in use)."""

    def __init__(self) -> None:
        self.count = 0
        self._original = RemoteHandle._begin

    def __enter__(self) -> RequestCounter:
        original = self._original

        def counted(handle: RemoteHandle, cmd: str, args: dict) -> object:
            self.count += 1
            return original(handle, cmd, args)

        RemoteHandle._begin = counted  # type: ignore[method-assign]
        return self

    def __exit__(self, *exc: object) -> None:
        RemoteHandle._begin = self._original  # type: ignore[method-assign]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenario", type=Path, nargs="?", default=ROOT / "scenarios" / "satellite" / "case1.toml")
    p.add_argument("--stop", type=float, default=20000.0, help="problem time of the run, s")
    p.add_argument("--method", default=None, help="coupling method (default: the scenario's)")
    p.add_argument("--inprocess", action="store_true", help="every subsim in this process (no Zenoh)")
    p.add_argument("--tolerance", type=float, default=0.10, help="allowed relative change from 10 %% to 100 %%")
    args = p.parse_args(argv)

    scenario = load(args.scenario)
    start, span = scenario.start, args.stop - scenario.start
    marks = [start + span * k / 10 for k in range(1, 11)]
    samples: list[dict] = []  # {"t", "requests", "wall", "rss": {label: KiB}}
    subsims: dict[int, str] = {}
    wall0 = time.perf_counter()

    def sample(t: float, requests: int) -> None:
        if not subsims:
            for i, pid in enumerate(child_pids()):
                subsims[pid] = f"subsim pid {pid}"
                try:  # name the process after its --name argument when it has one
                    cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
                    subsims[pid] = cmdline[cmdline.index(b"--name") + 1].decode()
                except (OSError, ValueError, IndexError):
                    subsims[pid] = f"subsim {i}"
        rss = {"coordinator": rss_kib()}
        rss.update({name: rss_kib(pid) for pid, name in subsims.items()})
        samples.append({"t": t, "requests": requests, "wall": time.perf_counter() - wall0, "rss": rss})

    with RequestCounter() as counter, tempfile.TemporaryDirectory() as tmp:

        def on_interval(interval: Interval) -> None:
            t = float(interval.t[-1])
            while marks and t >= marks[0] - 1e-9:
                marks.pop(0)
                sample(t, counter.count)

        report = run_scenario(scenario, method=args.method, stop=args.stop, output=Path(tmp) / "run.csv",
                              inprocess=args.inprocess, progress=False, log=lambda m: None, on_interval=on_interval)

    s = report.summary
    print(f"{scenario.name}, {report.method}, {'in one process' if args.inprocess else 'over Zenoh'}: "
          f"t = {s.t_start:g}..{s.t_end:g} s, {s.intervals} intervals, {counter.count} requests, "
          f"{time.perf_counter() - wall0:.1f} s wall")
    labels = list(samples[-1]["rss"])
    print(f"{'t (s)':>9s} {'requests':>9s} {'wall (s)':>8s}" + "".join(f" {x[:14]:>14s}" for x in labels)
          + "   (RSS, MiB)")
    for row in samples:
        cells = "".join(f" {v / 1024:14.1f}" if (v := row["rss"].get(x)) is not None else f" {'-':>14s}"
                        for x in labels)
        print(f"{row['t']:9g} {row['requests']:9d} {row['wall']:8.1f}{cells}")
    if len(samples) < 2:
        print("fewer than two samples: the run stopped early")
        return 1
    first, last = samples[0], samples[-1]
    requests = last["requests"] - first["requests"]
    ok = True
    print(f"from 10 % to 100 % of the run ({requests} requests):")
    for x in labels:
        a, b = first["rss"].get(x), last["rss"].get(x)
        if a is None or b is None:
            print(f"  {x:12s} gone before the end")
            continue
        change = (b - a) / a
        per = f", {(b - a) / requests * 1e4:+.0f} KiB per 10^4 requests" if requests else ""
        within = abs(change) <= args.tolerance
        ok &= within
        print(f"  {x:12s} {a / 1024:7.1f} -> {b / 1024:7.1f} MiB ({change:+.1%}{per})  "
              f"{'within' if within else 'OUTSIDE'} {args.tolerance:.0%}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
