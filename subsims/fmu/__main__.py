"""``python -m subsims.fmu path/to/model.fmu --connect EP --run RUN [--name N]``: serve one FMU.

``python -m subsims.fmu path/to/model.fmu --describe`` prints what the subsim reads from the FMU (FMI
version, interfaces, whether it can save its state, ports with units, settable variables) and exits.
A bad FMU is one line on stderr and exit code 2.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence

USAGE = "usage: python -m subsims.fmu MODEL.fmu (--describe | --connect ENDPOINT --run RUN [--name NAME] ...)"


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0].startswith("-"):
        print(USAGE, file=sys.stderr)
        return 2
    path, rest = argv[0], argv[1:]
    from subsims.fmu.fmu import FmuError, check_binaries, read_fmu
    from subsims.fmu.subsim import FmuSubsim

    if "--describe" in rest and rest != ["--describe"]:
        print(f"subsims.fmu: --describe takes no other options, got {' '.join(rest)}\n{USAGE}", file=sys.stderr)
        return 2
    try:
        if rest == ["--describe"]:
            info = read_fmu(path)
            check_binaries(info)
            print(json.dumps(info.summary(), indent=2))
            return 0
        prototype = FmuSubsim(path)
    except FmuError as exc:
        print(f"subsims.fmu: {exc}", file=sys.stderr)
        return 2
    from cosim.process import main as serve

    return serve(prototype, rest)


if __name__ == "__main__":
    raise SystemExit(main())
