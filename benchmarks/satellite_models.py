"""Model-side cost of the paper's satellite: one ``advance`` of each subsim, and whole in-process runs.

    PYTHONPATH=. python benchmarks/satellite_models.py                 # both parts, case 1, 400 s, 3 repetitions
    PYTHONPATH=. python benchmarks/satellite_models.py --runs 0        # advance timings only
    PYTHONPATH=/path/to/other/tree python benchmarks/satellite_models.py --root /path/to/other/tree   # compare
    PYTHONPATH=. python benchmarks/satellite_models.py --auto --stop 2000   # caseN-auto.toml, marginal 200 -> 2000 s

Times are CPU seconds of this process (``time.process_time``): on a shared machine they are far less noisy than
wall time. Part 1 times ``advance`` of orbit, attitude and aero (case 1 parameters, 5 samples over 0.4 s, the
runtime's own input function, linear interpolation), best of many. Part 2 runs ``cosim run case1 --inprocess`` for
unified (RK-U), distributed (RF-D) and centralized (RF-C), interleaved and repeated, and reports per method the
CPU time, the share of it spent inside the subsims' ``advance``, and the ratios to RK-U (medians). With ``--auto`` the
coupled runs use ``caseN-auto.toml`` (automatic intervals; RK-U stays at 0.1 s) and every figure is the marginal cost
from ``--short`` to ``--stop`` seconds, so that the controller's first intervals and the set-up cancel.

At the paper's settings (without ``--auto``) each repetition also runs RF-D and RF-C as **bare loops**: the same
subsims' ``advance``, the runtime's interpolant, the scenario's coupling transforms and the convergence check, called
directly in a few lines of Python (RF-D in the scenario's order with its stage-2 speculation left out, RF-C skipping
a run whose input repeats, as the coupler does), with no handles, runtime checks, coupler bookkeeping or results
file. Their end states must equal, bit for bit, the coupled runs' last results; their CPU time is the floor under
any framework that runs these models in Python, and it is printed beside the coupled runs' ratios.

Measured 2026-11-25 (``--auto --stop 2000``, case 1, 3 repeats): RF-D 1.63x RK-U's CPU (in advance 1.21x, rest
0.42x; 129 samples an interval), RF-C 2.12x (1.61x, 0.51x). Paper settings (default, 400 s): RF-D 5.18x (2.53x,
2.65x), RF-C 8.01x (4.07x, 3.95x).
2026-11-26, 3 repetitions: RF-D 5.05x (advance 2.46x), RF-C 7.13x (3.68x); as bare loops 3.27x and 5.47x, so
the framework above the floor is 1.77x and 1.66x RK-U (the bare loops write no results file; RK-U writes its CSV).
2026-11-25, later, a slower sitting, three interleaved pairs of trees at the same machine speed: paper settings
RF-D 4.98x-5.74x and RF-C 7.21x-8.68x after the per-call cuts of the couplings, convergence check and interpolation,
6.26x-6.30x and 9.18x-9.25x before them (7-13 % less CPU per coupled run; results byte-identical).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--root", type=Path,
                    default=Path(os.environ.get("PYTHONPATH", "").split(os.pathsep)[0] or Path(__file__).parents[1]),
                    help="the tree whose scenarios are run (default: the first PYTHONPATH entry, else this one)")
parser.add_argument("--stop", type=float, default=400.0, help="problem time of each run, s")
parser.add_argument("--runs", type=int, default=3, help="repetitions of the three runs (0: none)")
parser.add_argument("--case", type=int, default=1)
parser.add_argument("--auto", action="store_true", help="RF-D and RF-C on caseN-auto.toml, marginal cost from --short")
parser.add_argument("--short", type=float, default=200.0, help="with --auto: the short run subtracted, s")
args = parser.parse_args()

from cosim.coupler.convergence import check  # noqa: E402
from cosim.coupler.relaxation import interval_end, sample_times  # noqa: E402
from cosim.results import read_results  # noqa: E402
from cosim.runner import run_scenario  # noqa: E402
from cosim.runtime import Runtime  # noqa: E402
from cosim.scenario import Scenario, load  # noqa: E402
from cosim.unified import run_unified  # noqa: E402
from subsims.aero.subsim import Aero  # noqa: E402
from subsims.attitude.subsim import Attitude  # noqa: E402
from subsims.orbit.subsim import Orbit  # noqa: E402
from subsims.satellite.cases import CASES  # noqa: E402


def cpu_per_call(fn, calls: int = 200, repeats: int = 15) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.process_time()
        for _ in range(calls):
            fn()
        best = min(best, time.process_time() - t0)
    return best / calls


def advance_costs() -> dict[str, float]:
    times = np.linspace(0.0, 0.4, 5)
    rng = np.random.default_rng(1)
    params = CASES[f"case{args.case}"]
    out = {}
    for cls, key, sizes in ((Orbit, "orbit", {"f_aero": 3}), (Attitude, "attitude", {"R": 3, "torque": 3}),
                            (Aero, "aero", {"R_body": 3, "V_body": 3})):
        rt = Runtime(cls)
        rt.configure(params[key])
        scale = {"f_aero": 1e-3, "torque": 1e-4, "R": 7e6, "R_body": 7e6, "V_body": 7.7e3}
        inputs = {k: rng.normal(size=(5, n)) * scale[k] for k, n in sizes.items()}
        u = rt._input_function(times, inputs, "linear")
        state, model = rt.state, rt.model
        out[key] = cpu_per_call(lambda model=model, state=state, u=u: model.advance(state, times, u))
    return out


spent = {"cpu": 0.0, "calls": 0}


def bare_loop(scenario: Scenario, method: str, stop: float) -> tuple[dict[str, np.ndarray], int]:
    """RF-D or RF-C on the satellite as a bare loop (module docstring): the end state of each subsim, and the runs."""
    s = scenario.settings_for(method)
    rt = {}
    for name in ("orbit", "attitude", "aero"):
        rt[name] = Runtime(scenario.subsims[name].model_class())
        rt[name].configure(scenario.subsims[name].params)
    state = {name: r.state for name, r in rt.items()}
    into = {str(c.target): c for c in scenario.couplings}

    def coupled(target: str, outputs: dict) -> np.ndarray:
        c = into[target]
        return c.transform(*(outputs[src.subsim][src.port] for src in c.sources), **c.params)

    def run(name: str, times: np.ndarray, inputs: dict) -> tuple[dict, np.ndarray]:
        return rt[name].model.advance(state[name], times, rt[name]._input_function(times, inputs, s.interp))

    t, runs = scenario.start, 0
    while t < stop - 1e-9 * s.interval:
        times = sample_times(t, interval_end(scenario.start, t, s.interval), s.samples)
        zero = np.zeros((times.size, 3))  # the zero first guess of every coupled input (all are 3-vectors here)
        if method == "distributed":
            fed_back = {"orbit.f_aero": zero, "attitude.torque": zero}
            for stage in range(s.max_stages):
                out: dict = {}
                out["orbit"], end_o = run("orbit", times, {"f_aero": fed_back["orbit.f_aero"]})
                out["attitude"], end_a = run("attitude", times, {"R": coupled("attitude.R", out),
                                                                 "torque": fed_back["attitude.torque"]})
                out["aero"], end_e = run("aero", times, {"R_body": coupled("aero.R_body", out),
                                                         "V_body": coupled("aero.V_body", out)})
                runs += 3
                new = {k: coupled(k, out) for k in fed_back}
                if stage > 0 and check(new, fed_back, s.tol).converged:
                    break
                fed_back = new
        else:
            inputs = {k: zero for k in into}
            last_f_aero, previous = None, None
            for _ in range(s.max_stages):
                if last_f_aero is None or inputs["orbit.f_aero"].tobytes() != last_f_aero.tobytes():
                    orbit = run("orbit", times, {"f_aero": inputs["orbit.f_aero"]})
                    last_f_aero, runs = inputs["orbit.f_aero"], runs + 1
                out = {"orbit": orbit[0]}
                out["attitude"], end_a = run("attitude", times, {"R": inputs["attitude.R"],
                                                                 "torque": inputs["attitude.torque"]})
                out["aero"], end_e = run("aero", times, {"R_body": inputs["aero.R_body"],
                                                         "V_body": inputs["aero.V_body"]})
                runs += 2
                flat = {f"{n}.{p}": v for n, ports in out.items() for p, v in ports.items()}
                if previous is not None and check(flat, previous, s.tol).converged:
                    break
                previous, inputs = flat, {k: coupled(k, out) for k in into}
            end_o = orbit[1]
        state = {"orbit": end_o, "attitude": end_a, "aero": end_e}
        t = float(times[-1])
    return state, runs


def same_end(state: dict[str, np.ndarray], results: Path) -> bool:
    """Whether the bare loop ended where the coupled run's results end: orbit R, V and attitude phi, omega."""
    columns, data = read_results(results)
    last = dict(zip(columns, data[-1]))
    got = [*state["orbit"][:6], *state["attitude"][:6]]
    want = [last[f"{sig}[{i}]"] for sig in ("orbit.R", "orbit.V", "attitude.phi", "attitude.omega") for i in range(3)]
    return np.array(got).tobytes() == np.array(want).tobytes()


def timed(advance):
    def wrapper(self, *a, **k):
        t0 = time.process_time()
        try:
            return advance(self, *a, **k)
        finally:
            spent["cpu"] += time.process_time() - t0
            spent["calls"] += 1
    return wrapper


def runs() -> None:
    for cls in (Orbit, Attitude, Aero):
        cls.advance = timed(cls.advance)
    scenario = load(args.root / "scenarios" / "satellite" / f"case{args.case}.toml")
    coupled = load(args.root / "scenarios" / "satellite" / f"case{args.case}-auto.toml") if args.auto else scenario
    rows: dict[str, list] = {m: [] for m in ("unified", "distributed", "centralized")}
    floors: dict[str, list[float]] = {m: [] for m in ("distributed", "centralized")} if not args.auto else {}
    with tempfile.TemporaryDirectory() as tmp:
        for rep in range(args.runs):
            for method in rows:
                got = []
                for stop in (args.short, args.stop) if args.auto else (args.stop,):
                    spent["cpu"], spent["calls"] = 0.0, 0
                    wall, cpu = time.perf_counter(), time.process_time()
                    output = Path(tmp) / f"{method}-{stop:g}.csv"
                    if method == "unified":
                        run_unified(scenario, stop=stop, output=output)
                    else:
                        run_scenario(coupled, method=method, stop=stop, output=output, inprocess=True,
                                     progress=False, log=lambda s: None)
                    got.append(np.array([time.process_time() - cpu, spent["cpu"], spent["calls"],
                                         time.perf_counter() - wall]))
                cpu, adv, calls, wall = got[-1] - got[0] if args.auto else got[0]
                rows[method].append((cpu, adv, calls, wall))
                split = (" (one RK4 over all the models: no subsim advance calls)" if method == "unified" else
                         f", in advance {adv:6.3f} s ({calls:.0f} calls)")
                print(f"  rep {rep} {method:11s} cpu {cpu:6.3f} s{split}, wall {wall:6.2f} s", flush=True)
                if method in floors:  # (its advance calls go through the same timing wrapper as the coupled run's)
                    cpu = time.process_time()
                    end, runs_made = bare_loop(scenario, method, args.stop)
                    floors[method].append(time.process_time() - cpu)
                    if not same_end(end, output):
                        raise SystemExit(f"the bare {method} loop did not end where the coupled run did: not the same "
                                         "work, so no floor (has the scenario changed?)")
                    print(f"  rep {rep} {method:11s} as a bare loop: cpu {floors[method][-1]:6.3f} s, "
                          f"{runs_made} runs, the same end state", flush=True)
    med = {m: np.median(np.array(v), axis=0) for m, v in rows.items()}
    rku = med["unified"][0]
    span = f"{args.short:g} -> {args.stop:g} s, caseN-auto.toml" if args.auto else f"{args.stop:g} s"
    print(f"medians over {args.runs} repetitions, case {args.case}, {span} (ratios: CPU time / RK-U's):")
    for m, (cpu, adv, calls, wall) in med.items():
        split = "" if m == "unified" else (
            f" in advance {adv:6.3f} s = {adv / rku:5.2f} x RK-U ({adv / cpu:4.0%} of the run, "
            f"{adv / max(calls, 1) * 1e6:5.1f} us per call); rest {(cpu - adv) / rku:5.2f} x RK-U;")
        print(f"  {m:11s} cpu {cpu:6.3f} s = {cpu / rku:5.2f} x RK-U;{split} wall {wall:6.2f} s")
    for m, cpus in floors.items():
        floor = float(np.median(cpus))
        print(f"  {m:11s} as a bare loop (the floor: the models, interpolant, couplings and check alone, no results "
              f"file): cpu {floor:6.3f} s = {floor / rku:5.2f} x RK-U; the framework above it "
              f"{(med[m][0] - floor) / rku:5.2f} x RK-U")


print(f"tree: {args.root.resolve()}  python {sys.version.split()[0]}")
costs = advance_costs()
print("one advance (5 samples, 0.4 s), CPU, best of 15 x 200:",
      ", ".join(f"{k} {v * 1e6:.1f} us" for k, v in costs.items()), f"(sum {sum(costs.values()) * 1e6:.1f} us)")
if args.runs:
    runs()
