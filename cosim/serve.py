"""Serve any subsim class as a process: ``python -m cosim.serve package.module:Class --connect EP --run RUN``.

This is what ``cosim run`` launches, and what it tells you to start on another machine for an
external subsim. (Shipped subsims also have their own ``python -m subsims.<name>`` form.)
"""

from __future__ import annotations

import os
import sys

from cosim.contract import PROTOCOL_VERSION, VERSION
from cosim.importing import MODULE_PATH_ENV, load_model, use_search_path
from cosim.process import main as serve_model


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--version"]:
        print(f"cosim {VERSION} (protocol {PROTOCOL_VERSION})")
        return 0
    if not argv or argv[0].startswith("-"):
        asked = bool(argv) and argv[0] in ("-h", "--help")
        print("usage: python -m cosim.serve package.module:Class --connect ENDPOINT --run RUN [--name NAME]"
              + ("\n(python -m cosim.serve package.module:Class --help lists every option)" if asked else ""),
              file=sys.stdout if asked else sys.stderr)
        return 0 if asked else 2
    directories = [d for d in os.environ.pop(MODULE_PATH_ENV, "").split(os.pathsep) if d]
    if directories:  # launched by cosim run for a scenario: its modules, found as the coordinator finds them
        use_search_path(directories)
    try:
        cls = load_model(argv[0], directories)
    except ValueError as exc:
        print(f"cosim.serve: {exc}", file=sys.stderr)
        return 2
    return serve_model(cls, argv[1:], prog=f"python -m cosim.serve {argv[0]}")


if __name__ == "__main__":
    raise SystemExit(main())
