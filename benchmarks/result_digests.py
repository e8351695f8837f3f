"""Digests of the satellite's result files, to tell whether a change to the request path moved a single bit.

    PYTHONPATH=. python benchmarks/result_digests.py                     # in one process, 400 s
    PYTHONPATH=. python benchmarks/result_digests.py --remote            # over Zenoh, subsim processes, 40 s
    PYTHONPATH=/other/tree python benchmarks/result_digests.py --root /other/tree > other.txt   # then diff

Runs case 1, case 3 and case1-auto with RF-D and RF-C (and RK-U for the fixed cases) and prints one line per
result CSV: case, method, the first 16 hex digits of its SHA-256. A speed-up that claims "same results" must
print the same lines before and after (the CSVs hold every sample as its shortest round-trip repr, so equal
digests mean equal floats). The diagnostics files hold wall times and are left out. Asserts nothing.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import tempfile
from pathlib import Path

CASES = ("case1", "case3", "case1-auto")
METHODS = ("distributed", "centralized", "unified")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=Path(__file__).resolve().parents[1], help="the tree to run")
    parser.add_argument("--remote", action="store_true", help="subsims as processes over Zenoh (to --stop 40)")
    parser.add_argument("--stop", type=float, help="stop time (default: 400 s in one process, 40 s remote)")
    args = parser.parse_args()
    sys.path.insert(0, str(args.root))
    from cosim.runner import run_scenario
    from cosim.scenario import load
    from cosim.unified import run_unified

    stop = args.stop if args.stop is not None else 40.0 if args.remote else 400.0
    with tempfile.TemporaryDirectory() as tmp:
        for case in CASES:
            scenario = load(args.root / "scenarios" / "satellite" / f"{case}.toml")
            for method in METHODS:
                if method == "unified" and case.endswith("-auto"):  # (RK-U has no automatic interval)
                    continue
                out = Path(tmp) / f"{case}-{method}.csv"
                if method == "unified":
                    run_unified(scenario, stop=stop, output=out)
                else:
                    run_scenario(scenario, method=method, stop=stop, output=out, inprocess=not args.remote,
                                 progress=False, log=lambda _: None)
                print(case, method, hashlib.sha256(out.read_bytes()).hexdigest()[:16], flush=True)


if __name__ == "__main__":
    main()
