"""Mutation testing of the coupler and the physics modules: how many small wrong versions do the fast tests catch?

    pip install -e '.[mutation]'                                   # mutmut 2.x (its CLI takes paths as arguments)
    python benchmarks/mutation.py cosim/coupler/convergence.py cosim/coupler/first_guess.py
    python benchmarks/mutation.py subsims/lagrange_pair/model.py --tests tests/lagrange_pair/test_pair_model.py
    python benchmarks/mutation.py subsims/flexbody/model.py --mutmut /path/to/venv/bin/mutmut

For each module given, mutmut makes one mutant at a time (an operator, comparison, number, keyword, string or
assignment changed) and runs the module's fast tests (``-m "not slow and not zenoh"`` unless ``--markers``
says otherwise, stopping at the first failure); a
mutant is *killed* when a test fails. The modules are mutated in a private copy of the git-tracked tree (a
temporary directory), never in the working tree, and the tests import that copy (PYTHONPATH), also in the
subsim processes they spawn. Prints, per module, killed / survived / timed out and the share killed, and the
diff of every surviving mutant, to be judged: a survivor is either a gap in the tests or an *equivalent*
mutant (same behaviour, e.g. ``x < 0`` -> ``x <= 0`` where x is never 0); list the equivalent ones beside the
share when reporting it.

Without ``--tests``, the tests are chosen by module (``TESTS`` below); a module not listed there needs
``--tests``. The test run is ``<python> -m pytest -x -q -p no:cacheprovider -m <markers> <tests>``.
Not part of the test suite: it runs the tests hundreds of times (minutes to tens of minutes per module).
"""

from __future__ import annotations

import argparse
import os
import shlex
import shutil
import sqlite3
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# module -> its fast tests (relative to the repository root)
TESTS: dict[str, list[str]] = {
    "cosim/coupler/convergence.py": ["tests/test_coupler_units.py"],
    "cosim/coupler/first_guess.py": ["tests/test_coupler_units.py", "tests/test_coupler_exact.py"],
    "cosim/coupler/couplings.py": ["tests/test_coupler_units.py", "tests/test_scenario.py"],
    "cosim/coupler/order.py": ["tests/test_coupler_order.py"],
    "cosim/coupler/plan.py": ["tests/test_coupler_machine.py", "tests/test_coupler_order.py",
                              "tests/test_coupler_units.py"],
    "cosim/coupler/relaxation.py": ["tests/test_coupler_machine.py", "tests/test_coupler_units.py",
                                    "tests/test_coupler_exact.py",
                                    "tests/test_oscillator.py"],
    "subsims/lagrange_pair/model.py": ["tests/lagrange_pair/test_pair_model.py",
                                       "tests/lagrange_pair/test_pair_drift.py"],
    "subsims/lagrange_pair/aero.py": ["tests/lagrange_pair/test_pair_model.py",
                                      "tests/lagrange_pair/test_pair_adapter.py"],
    "subsims/flexbody/model.py": ["tests/flexbody/test_flex_equations.py", "tests/flexbody/test_flex_deflected_run.py",
                                  "tests/flexbody/test_flex_conservation.py", "tests/flexbody/test_flex_limits.py"],
    "subsims/orbit/model.py": ["tests/satellite/test_orbit_model.py"],
    "subsims/attitude/model.py": ["tests/satellite/test_attitude_model.py"],
    "subsims/aero/model.py": ["tests/satellite/test_aero_model.py"],
}

# mutmut 2's statuses; "suspicious" means killed, but the tests took much longer than unmutated
STATUS = {"ok_killed": "killed", "ok_suspicious": "killed", "bad_survived": "survived", "bad_timeout": "timeout",
          "skipped": "skipped", "untested": "untested"}


def tracked_copy(dest: Path) -> None:
    """Copy the git-tracked files (as they are in the working tree) to ``dest``."""
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    for name in filter(None, files.decode().split("\0")):
        src = ROOT / name
        if src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)


def find_mutmut(given: str | None) -> str:
    """A mutmut 2.x executable: ``given``, or next to this Python, or on PATH (mutmut 3 takes no paths)."""
    candidates = [given] if given else [str(Path(sys.executable).parent / "mutmut"), shutil.which("mutmut")]
    for c in candidates:
        if c and Path(c).exists():
            out = subprocess.run([c, "version"], capture_output=True, text=True, cwd=tempfile.gettempdir()).stdout
            if "version 2." in out:
                return c
            print(f"{c} is not mutmut 2.x ({out.strip() or 'no version'}); skipped", file=sys.stderr)
    sys.exit("mutmut 2.x not found: pip install -e '.[mutation]' (in a venv) or pass --mutmut PATH")


def mutate(module: str, tests: list[str], work: Path, mutmut: str, python: str, timeout_factor: float,
           markers: str) -> dict:
    cache = work / ".mutmut-cache"
    if cache.exists():
        cache.unlink()
    pytest = " ".join([shlex.quote(python), "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "-m",
                       shlex.quote(markers), *map(shlex.quote, tests)])
    # mutmut 2.5 counts only exit code 1 as killed; a mutant that breaks the import (pytest exit 2) or the
    # session would pass for a survivor, so any failure becomes 1
    runner = "sh -c " + shlex.quote(pytest + " || exit 1")
    env = {**os.environ, "PYTHONPATH": str(work), "PYTHONDONTWRITEBYTECODE": "1"}
    print(f"\n=== {module}\n    tests: {' '.join(tests)}", flush=True)
    cmd = [mutmut, "run", "--paths-to-mutate", module, "--runner", runner, "--tests-dir", "tests", "--no-progress",
           "--simple-output"]
    if timeout_factor:
        cmd += ["--test-time-multiplier", str(timeout_factor)]
    done = subprocess.run(cmd, cwd=work, env=env, capture_output=True, text=True)
    if not cache.exists():
        print(done.stdout[-3000:], done.stderr[-3000:], sep="\n")
        raise SystemExit(f"mutmut did not run on {module} (exit {done.returncode})")
    with sqlite3.connect(cache) as db:
        rows = db.execute("SELECT Mutant.id, Mutant.status FROM Mutant").fetchall()
    counts: dict[str, int] = {}
    for _, status in rows:
        counts[STATUS.get(status, status)] = counts.get(STATUS.get(status, status), 0) + 1
    survivors = [mid for mid, status in rows if status in ("bad_survived", "bad_timeout")]
    for mid in survivors:
        diff = subprocess.run([mutmut, "show", str(mid)], cwd=work, env=env, capture_output=True, text=True).stdout
        lines = [ln for ln in diff.splitlines() if ln.startswith(("-", "+", "@")) and not ln.startswith(("---", "+++"))]
        print(f"--- {STATUS[dict(rows)[mid]]} mutant {mid}:\n" + "\n".join(lines or diff.splitlines()))
    killed, total = counts.get("killed", 0), sum(v for k, v in counts.items() if k != "skipped")
    share = killed / total if total else float("nan")
    print(f"    {module}: {killed} of {total} mutants killed ({share:.1%}); " + ", ".join(
        f"{k} {v}" for k, v in sorted(counts.items())), flush=True)
    return {"module": module, "killed": killed, "total": total, **counts}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("modules", nargs="+", help="module paths relative to the repository root")
    ap.add_argument("--tests", nargs="+", help="test files/ids to run (default: TESTS[module])")
    ap.add_argument("--mutmut", help="mutmut 2.x executable (default: next to this Python, or on PATH)")
    ap.add_argument("--python", default=sys.executable, help="Python that runs the tests (default: this one)")
    ap.add_argument("--markers", default="not slow and not zenoh",
                    help='pytest -m expression (default: "not slow and not zenoh")')
    ap.add_argument("--timeout-factor", type=float, default=0.0, help="mutmut --test-time-multiplier")
    args = ap.parse_args(argv)
    mutmut = find_mutmut(args.mutmut)
    results = []
    with tempfile.TemporaryDirectory(prefix="cosim-mutation-") as tmp:
        work = Path(tmp)
        tracked_copy(work)
        for module in args.modules:
            module = str(Path(module))
            if not (work / module).is_file():
                ap.error(f"{module} is not a tracked file of {ROOT}")
            tests = args.tests or TESTS.get(module)
            if not tests:
                ap.error(f"no tests known for {module}: pass --tests")
            results.append(mutate(module, tests, work, mutmut, args.python, args.timeout_factor, args.markers))
    killed, total = sum(r["killed"] for r in results), sum(r["total"] for r in results)
    print("\nmodule".ljust(44) + "killed / mutants")
    for r in results:
        print(f"{r['module']:<43} {r['killed']:>6} / {r['total']:<6} {r['killed'] / max(r['total'], 1):.1%}")
    print(f"{'all':<43} {killed:>6} / {total:<6} {killed / max(total, 1):.1%}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
