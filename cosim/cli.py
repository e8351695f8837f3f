"""The ``cosim`` command line (subcommands are added as the coupler lands)."""

from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    print("cosim: no subcommands yet", file=sys.stderr)
    return 2
