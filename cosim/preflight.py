"""Checks of ``cosim run``'s arguments before anything is launched; each failure is one actionable line."""

from __future__ import annotations

import argparse
import errno
import math
import numbers
import re
import socket
from pathlib import Path
from typing import Any

from cosim.protocol.transport.session import error_text


class UsageError(ValueError):
    """A command-line argument that cannot work; the message names it and what to do."""


def check_stop(stop: float | None, start: float) -> None:
    """``--stop`` must be a finite time after the scenario's start."""
    check_run_arguments(start, stop=stop)


def check_run_options(args: argparse.Namespace) -> None:
    """``cosim run``'s numbers and output file, as the scenario's ``[run]`` table checks its own: one line each."""
    check_run_arguments(0.0, timeout=args.timeout, attach_wait=args.attach_wait, restarts=args.restarts,
                        output=args.output)
    if args.inprocess and args.timeout is not None:  # a model hanging in this process waited forever with it given
        raise UsageError("--timeout is for subsim processes: with --inprocess every model runs in this one, which "
                         "nothing times out (Ctrl-C stops a model in Python code; one stuck in native code, an FMU, "
                         "only kill -9 does)")


def check_run_arguments(start: float, stop: Any = None, timeout: Any = None, attach_wait: Any = None,
                        restarts: Any = None, output: Any = None, *, options: bool = True) -> None:
    """A run's stop time, timeout, attach wait, restarts and output file (None: not given), named as the command's
    options (``--stop``, values as numbers) or, with ``options=False``, as ``cosim.run``'s arguments (``stop``,
    values as Python shows them: they may be of any type there). UsageError in one line."""
    def name(argument: str) -> str:
        return "--" + argument.replace("_", "-") if options else argument

    def shown(value: Any) -> str:
        return f"{value:g}" if options else repr(value)

    def number(value: Any) -> bool:  # numpy's scalars too (a stop from np.arange)
        return isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)

    if stop is not None and not (number(stop) and stop > start):
        raise UsageError(f"{name('stop')} must be a finite time after the scenario's start ({start:g} s), "
                         f"got {shown(stop)}")
    for argument, value in (("timeout", timeout), ("attach_wait", attach_wait)):
        if value is not None and not (number(value) and value > 0):
            raise UsageError(f"{name(argument)} must be a finite number of seconds > 0, got {shown(value)}")
    if restarts is not None and (isinstance(restarts, bool) or not isinstance(restarts, numbers.Integral)
                                 or restarts < 0):
        raise UsageError(f"{name('restarts')} must be a whole number >= 0, got {restarts!r}")
    if output is not None and not Path(output).is_dir() and Path(output).suffix not in (".csv", ".npz"):
        raise UsageError(f"{name('output')} {output if options else repr(str(output))}: a result file ends in .csv "
                         "or .npz (lower case)")


_TCP = re.compile(r"^(?P<proto>tcp|udp)/(?:\[(?P<v6>[^\]]+)\]|(?P<host>[^:/\[\]]+)):(?P<port>\d+)(?:#.*)?$")


def check_listen(endpoint: str) -> None:
    """For ``tcp/HOST:PORT`` with a fixed port: the port must be free to listen on (port 0 is always)."""
    m = _TCP.match(endpoint)
    if m is None or m["proto"] != "tcp" or int(m["port"]) == 0:
        return  # other locators: Zenoh says what is wrong with them
    host, port = m["v6"] or m["host"], int(m["port"])
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except socket.gaierror as exc:
        raise UsageError(f"--listen {endpoint}: cannot resolve {host!r} ({exc.strerror}): "
                         "give an address of this machine, e.g. tcp/127.0.0.1:7447") from None
    family, _, _, _, address = infos[0]
    with socket.socket(family, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as a listener would: TIME_WAIT is no conflict
        try:
            s.bind(address)
            s.listen(1)
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                raise UsageError(f"--listen {endpoint}: port {port} is already in use: stop what holds it "
                                 f"(ss -ltnp 'sport = :{port}') or pick another port (port 0: any free one)") from None
            raise UsageError(f"--listen {endpoint}: cannot listen there ({exc.strerror}): "
                             "give an address of this machine and a free port") from None


def zenoh_error_line(exc: BaseException, endpoint: str) -> str:
    """A Zenoh error (a multi-line Rust report with source paths) as one line."""
    text = error_text(exc)
    if "Address already in use" in text:
        port = endpoint.rsplit(":", 1)[-1]
        return f"--listen {endpoint}: port {port} is already in use: stop what holds it or pick another port"
    return f"Zenoh: {text}"
