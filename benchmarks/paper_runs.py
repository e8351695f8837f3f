"""The paper's nine runs: cases 1-3 x RF-C / RF-D (over Zenoh, real processes) / RK-U (spec §9, §10).

    python benchmarks/paper_runs.py                      # all nine, 60,000 s each (hours over Zenoh)
    python benchmarks/paper_runs.py --stop 2000          # shortened
    python benchmarks/paper_runs.py --cases 3 --stop 60000
    python benchmarks/paper_runs.py --analyze-only       # re-read the result files in --out

Runs go one after the other (so wall times compare) in the order unified, distributed, centralized for
each case; results stream to ``<out>/case<N>-<method>.csv`` (+ ``.csv.diag.csv``) and the timings to
``<out>/timings.json``, so an interrupted benchmark can still be analysed (over the rows every run of a
case has). Prints, per case:

* wall and CPU time of each run (CPU = this process + its reaped subsim processes) and the speed ratios
  distributed/unified and centralized/unified (paper, CPU: RF-D ~800 s, RF-C ~1,200 s, RK-U ~200 s, so
  at most 4x and 6x);
* the stages-per-interval histogram (stage 0 included; the listings' nit is stages-1 for RF-D and
  stages-2 for RF-C, see tests/satellite/test_paper_claims.py);
* the largest deviation from the unified reference in each 1,000 s window: Euler angles (deg, the
  range-limited output angles as plotted in the paper, differences wrapped to +-180) and position (m);
* the time at which the deviation first exceeds 1 deg (the paper: case 3 at about 45,000 s);
* lower bounds under each coupled run's ratio, as multiples of RK-U's wall time per interval:
  - transport: the round trips one interval waits for in sequence (RF-D: every subsim of every stage;
    RF-C: one per stage, the subsims of a stage answering concurrently) times the median ``status``
    round trip to a subsim process, measured in the same benchmark;
  - physics alone: the models' own integration for that many stages, with no framework, transport or
    output (RF-C counts only the slowest subsim of a stage, as if all ran in parallel);
  - one process: the same coupled run with every subsim in this process (no transport), timed over
    the first 400 s. For RF-D, where one request runs at a time, transport + one process bounds the
    ratio. For RF-C, whose subsims compute concurrently, the CPU bound does: the one-process time plus
    each request's Zenoh and codec CPU (measured on ``status``), spread over the machine's cores.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import resource
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.launch import PRIVATE, Bus  # noqa: E402
from cosim.results import diag_path, read_results  # noqa: E402
from cosim.runner import run_scenario  # noqa: E402
from cosim.scenario import Scenario, load  # noqa: E402
from cosim.unified import run_unified  # noqa: E402
from subsims.satellite.transforms import limit_angles  # noqa: E402

METHODS = ("unified", "distributed", "centralized")
SHORT = {"unified": "RK-U", "distributed": "RF-D", "centralized": "RF-C"}
BARS = {"distributed": 4.0, "centralized": 6.0}  # the paper's CPU ratios to RK-U on one processor
ONE_PROCESS_SPAN = 400.0  # s of problem time over which the one-process floor is measured


def cpu_seconds() -> float:
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def case_scenario(case: int) -> Scenario:
    return load(ROOT / "scenarios" / "satellite" / f"case{case}.toml")


def run_one(case: int, method: str, stop: float, out: Path, inprocess: bool, progress: bool = True) -> dict:
    scenario = case_scenario(case)
    output = out / f"case{case}-{method}.csv"
    wall, cpu = time.perf_counter(), cpu_seconds()
    if method == "unified":
        report = run_unified(scenario, stop=stop, output=output)
    else:
        report = run_scenario(scenario, method=method, stop=stop, output=output, inprocess=inprocess,
                              progress=progress, log=lambda m: None)
    wall, cpu = time.perf_counter() - wall, cpu_seconds() - cpu
    return {"wall_s": wall, "cpu_s": cpu, "stop": stop, "t_end": report.summary.t_end,
            "intervals": report.summary.intervals, "stages": dict(report.summary.stages),
            "round_trips": getattr(report.summary, "round_trips", 0),
            "requests": getattr(report.summary, "requests", 0),
            "transport": "in-process" if inprocess or method == "unified" else "zenoh"}


def process_cpu_seconds(pid: int) -> float:
    """CPU time (user + system) of another process so far, from /proc (Linux; clock-tick resolution)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def status_round_trip(calls: int = 500, cpu_calls: int = 3000) -> dict[str, float]:
    """``status`` to an aero subsim process (no model work): the median round trip (s), and the CPU (s)
    one request costs both processes together (Zenoh, codec, dispatch); the coordinator blocks while it
    waits, so its waiting is not counted as work."""
    with Bus.open(PRIVATE) as bus:  # where the runs' routers listen (cosim run's default for launched subsims)
        process = bus.spawn("subsims.aero", name="aero", quiet=True)
        handle = process.handle
        for _ in range(50):
            handle.status()
        times = []
        for _ in range(calls):
            start = time.perf_counter()
            handle.status()
            times.append(time.perf_counter() - start)
        own, theirs = time.process_time(), process_cpu_seconds(process.popen.pid)
        for _ in range(cpu_calls):
            handle.status()
        cpu = time.process_time() - own + process_cpu_seconds(process.popen.pid) - theirs
    return {"rtt_s": float(np.median(times)), "cpu_s": cpu / cpu_calls}


def one_process_per_interval(case: int, method: str, stop: float) -> float:
    """Wall seconds per interval of the same coupled run with every subsim in this process (no transport)."""
    with tempfile.TemporaryDirectory() as tmp:
        run = run_one(case, method, stop, Path(tmp), inprocess=True, progress=False)
    return run["wall_s"] / run["intervals"]


def physics_per_stage(case: int, repeats: int = 2000) -> dict[str, float]:
    """Seconds one stage of each subsim spends in its physics alone (constant inputs, plain calls)."""
    from subsims.aero.model import AeroParams, aero_loads
    from subsims.attitude.model import AttitudeParams
    from subsims.attitude.model import integrate as attitude_integrate
    from subsims.orbit.model import OrbitParams
    from subsims.orbit.model import integrate as orbit_integrate

    params = {name: spec.params for name, spec in case_scenario(case).subsims.items()}
    orbit, attitude = OrbitParams.from_mapping(params["orbit"]), AttitudeParams.from_mapping(params["attitude"])
    aero = AeroParams.from_mapping(params["aero"])
    x_orbit, x_attitude = orbit.initial_state().tolist(), attitude.initial_state().tolist()
    force, radius, torque, velocity = (0.01, 0.02, 0.03), x_orbit[:3], (0.0, 1e-4, 0.0), (10.0, 7600.0, 5.0)
    times = [0.1 * j for j in range(5)]
    work = {
        "orbit": lambda: orbit_integrate(orbit, x_orbit, times, lambda ts: force),
        "attitude": lambda: attitude_integrate(attitude, x_attitude, times, lambda ts: [(radius, torque)] * ts.size),
        "aero": lambda: [aero_loads(velocity, aero, aero.facets) for _ in times],
    }
    seconds = {}
    for name, fn in work.items():
        start = time.perf_counter()
        for _ in range(repeats):
            fn()
        seconds[name] = (time.perf_counter() - start) / repeats
    return seconds


def sequential_round_trips(method: str, stages: float, subsims: int = 3) -> float:
    """Round trips an interval of ``stages`` stages waits for one after the other (commits ride on runs)."""
    return stages * (subsims if method == "distributed" else 1)


def stages_histogram(diag: Path) -> Counter:
    with diag.open() as f:
        return Counter(int(row["stages"]) for row in csv.DictReader(f))


def load_case(out: Path, case: int) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """{method: (t, limited Euler angles deg (n, 3), R m (n, 3))} of the result files that exist."""
    runs = {}
    for method in METHODS:
        path = out / f"case{case}-{method}.csv"
        if not path.exists() or path.stat().st_size == 0:
            continue
        columns, data = read_results(path)
        if data.shape[0] == 0:
            continue
        phi = data[:, [columns.index(f"attitude.phi[{i}]") for i in range(3)]]
        r = data[:, [columns.index(f"orbit.R[{i}]") for i in range(3)]]
        runs[method] = (data[:, 0], np.degrees(limit_angles(phi)), r)
    return runs


def angle_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Largest component difference of limited Euler angles (deg), wrapped to [-180, 180): (n,)."""
    return np.max(np.abs((a - b + 180.0) % 360.0 - 180.0), axis=1)


def deviations(runs: dict, a: str, b: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, angle deviation deg, position deviation m) over the rows both runs have."""
    n = min(runs[a][0].size, runs[b][0].size)
    ta, tb = runs[a][0][:n], runs[b][0][:n]
    if not np.allclose(ta, tb, rtol=0, atol=1e-6):
        raise SystemExit(f"time columns of {a} and {b} differ: not the same run length or grid")
    return ta, angle_diff(runs[a][1][:n], runs[b][1][:n]), np.max(np.abs(runs[a][2][:n] - runs[b][2][:n]), axis=1)


def windowed(t: np.ndarray, dev: np.ndarray, width: float) -> list[tuple[float, float]]:
    k = np.floor((t - 1e-9) / width).clip(min=0).astype(int)
    return [(w * width, float(dev[k == w].max())) for w in np.unique(k)]


def first_exceeding(t: np.ndarray, dev: np.ndarray, level: float) -> float | None:
    above = np.flatnonzero(dev > level)
    return float(t[above[0]]) if above.size else None


def print_floors(method: str, stages: float, rk_u: float, rtt: float, request_cpu: float | None,
                 physics: dict[str, float], one_process: float | None, trips: float | None = None,
                 requests: float | None = None) -> None:
    """Lower bounds under a coupled run's wall time per interval, as multiples of RK-U's (``rk_u`` s).

    Two of each: the models' physics and the bus alone, and this framework's work (the same run timed in
    one process) with the bus. RF-D runs one request at a time, so transport and work add up; RF-C's
    subsims compute concurrently, so its bound is also the CPU all processes need, over the cores.
    """
    if not trips:  # the runs' own count (speculate = true runs fewer); else every subsim of every stage in turn
        trips = sequential_round_trips(method, stages)
    transport = trips * rtt / rk_u
    every_model = stages * sum(physics.values()) / rk_u
    slowest_model = stages * max(physics.values()) / rk_u
    if not requests:  # the runs' own count (a subsim whose inputs repeat is not run again); else every subsim
        requests = stages * len(physics)
    cores = os.cpu_count() or 1
    print(f"    floors, as multiples of RK-U: transport {trips:.1f} sequential round trips x {rtt * 1e6:.0f} us = "
          f"{transport:.1f}x; physics alone {every_model if method == 'distributed' else slowest_model:.1f}x"
          + (f"; each request's Zenoh and codec CPU {request_cpu * 1e6:.0f} us" if request_cpu else ""))

    def bound(work: float) -> str:
        if method == "distributed":
            return f"transport + work = {transport + work:.1f}x"
        if not request_cpu:
            return "(no request CPU measured)"
        cpu = work + requests * request_cpu / rk_u
        return f"CPU of the work and {requests:.1f} requests over {cores} cores = {cpu / cores:.1f}x"

    models_only = bound(every_model)
    if method == "centralized":
        models_only = f"transport + slowest model = {transport + slowest_model:.1f}x; " + models_only
    print(f"      the models and the bus only: {models_only}   (bar {BARS[method]:g}x)")
    if one_process is not None:
        alone = one_process / rk_u
        print(f"      this framework (the same run in one process, no transport: {alone:.1f}x): {bound(alone)}")


def report_case(case: int, out: Path, timings: dict, window: float, level: float) -> None:
    print(f"\n=== case {case} ===")
    for method in METHODS:
        tm = timings.get(f"case{case}-{method}")
        diag = diag_path(out / f"case{case}-{method}.csv")
        if tm is None and not diag.exists():
            continue
        hist = stages_histogram(diag) if diag.exists() else Counter()
        line = f"  {SHORT[method]:5s}"
        if tm:
            line += (f" wall {tm['wall_s']:9.1f} s  cpu {tm['cpu_s']:9.1f} s  to t = {tm['t_end']:g} s "
                     f"({tm['transport']})")
        else:
            line += " (no timing: interrupted?)"
        if method != "unified":
            line += "  stages/interval: " + ", ".join(f"{k}: {v}" for k, v in sorted(hist.items()))
        print(line)
    u = timings.get(f"case{case}-unified")
    rtt = timings.get("status_rtt_s", timings.get("status_round_trip_s"))  # older files: the round trip only
    request_cpu = timings.get("status_cpu_s")
    for method in ("distributed", "centralized"):
        tm = timings.get(f"case{case}-{method}")
        if u and tm and tm["stop"] == u["stop"]:
            print(f"  speed {SHORT[method]}/RK-U: wall {tm['wall_s'] / u['wall_s']:.1f}x, "
                  f"cpu {tm['cpu_s'] / u['cpu_s']:.1f}x   (paper, CPU: {BARS[method]:g}x)")
            diag = diag_path(out / f"case{case}-{method}.csv")
            physics = timings.get(f"case{case}-physics_per_stage_s")
            if rtt and physics and tm["transport"] == "zenoh" and diag.exists() and tm["intervals"]:
                hist = stages_histogram(diag)
                stages = sum(k * v for k, v in hist.items()) / sum(hist.values())
                one_process = timings.get(f"case{case}-{method}-one_process_s")
                trips = tm.get("round_trips", 0) / tm["intervals"]
                requests = tm.get("requests", 0) / tm["intervals"]
                print_floors(method, stages, u["wall_s"] / tm["intervals"], rtt, request_cpu, physics, one_process,
                             trips, requests)

    runs = load_case(out, case)
    pairs = [(m, "unified") for m in ("distributed", "centralized") if m in runs and "unified" in runs]
    if "distributed" in runs and "centralized" in runs:
        pairs.append(("centralized", "distributed"))
    if not pairs:
        return
    devs = {p: deviations(runs, *p) for p in pairs}
    names = [f"{SHORT[a]}-{SHORT[b]}" for a, b in pairs]
    print(f"  largest deviation per {window:g} s window: Euler angles (deg) | position (m)")
    print("  " + f"{'window s':>15s}" + "".join(f"  {n + ' deg':>13s} {n + ' m':>11s}" for n in names))
    tables = {p: (windowed(d[0], d[1], window), windowed(d[0], d[2], window)) for p, d in devs.items()}
    for i in range(max(len(v[0]) for v in tables.values())):
        row = ""
        for p in pairs:
            ang, pos = tables[p]
            row += f"  {ang[i][1]:13.3e} {pos[i][1]:11.3e}" if i < len(ang) else " " * 27
        start = next(v[0][i][0] for v in tables.values() if i < len(v[0]))
        print(f"  {start:7g}-{start + window:<7g}" + row)
    for p, (t, ang, pos) in devs.items():
        first = first_exceeding(t, ang, level)
        name = f"{SHORT[p[0]]} vs {SHORT[p[1]]}"
        when = f"first exceeds {level:g} deg at t = {first:.1f} s" if first is not None else \
            f"never exceeds {level:g} deg up to t = {t[-1]:g} s"
        print(f"  {name}: {when}; overall max {ang.max():.3e} deg, {pos.max():.3e} m")
    if case == 3:
        print("  (paper: RF-C and RF-D agree with RK-U for about 45,000 s, then diverge from it while still "
              "agreeing with each other)")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--stop", type=float, default=60000.0, help="problem time of every run, s (paper: 60000)")
    p.add_argument("--cases", type=int, nargs="+", default=[1, 2, 3], choices=[1, 2, 3])
    p.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    p.add_argument("--out", type=Path, default=ROOT / "results" / "paper", help="result directory")
    p.add_argument("--inprocess", action="store_true", help="coupled runs in this process (no Zenoh)")
    p.add_argument("--analyze-only", action="store_true", help="only analyse the result files in --out")
    p.add_argument("--window", type=float, default=1000.0, help="deviation window, s")
    p.add_argument("--level", type=float, default=1.0, help="deviation of interest, deg")
    args = p.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    timing_file = args.out / "timings.json"
    timings = json.loads(timing_file.read_text()) if timing_file.exists() else {}
    if not args.analyze_only:
        if not args.inprocess and set(args.methods) - {"unified"}:
            status = status_round_trip()
            timings.pop("status_round_trip_s", None)
            timings["status_rtt_s"], timings["status_cpu_s"] = status["rtt_s"], status["cpu_s"]
            print(f"status to a subsim process: round trip {status['rtt_s'] * 1e6:.0f} us (median), "
                  f"CPU {status['cpu_s'] * 1e6:.0f} us per request", file=sys.stderr, flush=True)
        for case in args.cases:
            timings[f"case{case}-physics_per_stage_s"] = physics_per_stage(case)
            if not args.inprocess:
                for method in (m for m in METHODS if m in args.methods and m != "unified"):
                    timings[f"case{case}-{method}-one_process_s"] = one_process_per_interval(
                        case, method, min(args.stop, ONE_PROCESS_SPAN))
            for method in (m for m in METHODS if m in args.methods):
                key = f"case{case}-{method}"
                timings.pop(key, None)
                timing_file.write_text(json.dumps(timings, indent=1))
                print(f"running case {case} {method} to t = {args.stop:g} s ...", file=sys.stderr, flush=True)
                timings[key] = run_one(case, method, args.stop, args.out, args.inprocess)
                timing_file.write_text(json.dumps(timings, indent=1))
                tm = timings[key]
                print(f"  case {case} {SHORT[method]}: {tm['wall_s']:.1f} s wall, {tm['cpu_s']:.1f} s cpu",
                      file=sys.stderr, flush=True)
    for case in args.cases:
        report_case(case, args.out, timings, args.window, args.level)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
