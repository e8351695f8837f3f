"""Run a subsim model as its own process: ``python -m subsims.<name> --connect EP --run RUN``.

The environment must hold the subsim's key (``COSIM_SECRET``) and its router login, ``COSIM_ZENOH_AUTH`` (or
``--auth-file``); ``cosim run`` sets both for the subsims it launches and prints them for external ones. Secrets
never go on the command line, which ``ps`` shows.

Exit codes: 0 after ``shutdown``, SIGTERM, SIGINT or the coordinator's leaving (its liveliness token deleted); 3 when
its router has been unreachable for 2 s (a cut link, or the coordinator killed: a supervisor may start it again); 2
when the coordinator cannot be reached in time or the arguments are bad. Every path closes the Zenoh
session (an open session keeps the process alive forever).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

import zenoh

from cosim.console import prefixed_stream, say
from cosim.contract import PROTOCOL_VERSION, VERSION, CosimError
from cosim.protocol.keys import check_name
from cosim.protocol.security import SECRET_ENV, ZENOH_AUTH_ENV, ClientSecurity
from cosim.protocol.transport.reach import tls_cause, unreachable
from cosim.protocol.transport.server import CommandServer
from cosim.protocol.transport.session import client_config, error_text, zenoh_mismatch
from cosim.runtime import DEFAULT_HISTORY, Runtime
from cosim.subsim import Subsim


class _Stop(BaseException):
    """Raised in the main thread by SIGTERM/SIGINT (delivered while ``recv`` waits)."""


_why_stopping: list[str] = []  # why this process sent itself SIGTERM, when it did


def _raise_stop(signum: int, frame: object) -> None:
    raise _Stop(_why_stopping[0] if _why_stopping else f"on {signal.Signals(signum).name}")


_router_lost = threading.Event()  # nothing to close politely: Zenoh's close would wait for it about 8 s
EXIT_LINK_LOST = 3  # the router was lost (a cut link, or the coordinator's end): for a supervisor to start it again


def _stop_self(why: str) -> None:
    _why_stopping.append(why)
    os.kill(os.getpid(), signal.SIGTERM)


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number of seconds, got {text!r}") from None
    if not 0 < value <= 86400:  # also refuses NaN; an endless wait could not be interrupted
        raise argparse.ArgumentTypeError(f"must be a number of seconds > 0 and at most a day, got {text}")
    return value


def _count(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 0, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 0, got {value}")
    return value


def parse_args(model_cls: type[Subsim] | Subsim, argv: Sequence[str] | None,
               prog: str | None = None) -> argparse.Namespace:
    """``prog``: how the process was started, for usage and error lines (default: ``python -m <package>``)."""
    model_cls = model_cls if isinstance(model_cls, type) else type(model_cls)  # a class or a prototype instance
    p = argparse.ArgumentParser(
        prog=prog or f"python -m {model_cls.__module__.rsplit('.', 1)[0]}",
        description=f"Serve the {model_cls.__name__} subsim over Zenoh.",
    )
    p.add_argument("--version", action="version", version=f"cosim {VERSION} (protocol {PROTOCOL_VERSION})")
    p.add_argument("--connect", required=True, help="coordinator endpoint, e.g. tcp/127.0.0.1:7447")
    p.add_argument("--run", required=True, help="run id (namespaces every key)")
    p.add_argument("--name", default=model_cls.name, help=f"instance name on the bus (default: {model_cls.name})")
    p.add_argument("--connect-timeout", type=_seconds, default=10.0,
                   help="seconds to wait for the coordinator's router to answer; an address where nothing listens "
                        "or that does not resolve is said at once (the coordinator is always up first: it prints "
                        "this command's secrets); a signal during the wait ends the process after it")
    p.add_argument("--history", type=_count, default=DEFAULT_HISTORY, help="committed states kept for rollback")
    p.add_argument("--lease", type=_seconds, default=10.0, help="seconds a silent link to the coordinator lives")
    p.add_argument("--quiet-start", action="store_true",
                   help="do not announce the start ('serving run ...'): cosim run --quiet passes it")
    p.add_argument("--quiet-stop", action="store_true",
                   help="say nothing when the coordinator ends the run (cosim run passes it to the subsims it "
                        "starts: it reports the stop itself, in one line)")
    p.add_argument("--max-request", type=int, metavar="BYTES",
                   help="refuse larger requests before decoding them (default: sized from the input ports)")
    p.add_argument("--queue", type=int, default=64, metavar="N", help="requests waiting beyond N get a 'busy' reply")
    p.add_argument("--auth-file", type=Path, help=f"file with one 'user:password' line (else ${ZENOH_AUTH_ENV})")
    p.add_argument("--tls-ca", type=Path, help="CA certificate (PEM) that signed the coordinator's TLS certificate")
    p.add_argument("--tls-cert", type=Path, help="this subsim's certificate, for mutual TLS")
    p.add_argument("--tls-key", type=Path, help="this subsim's private key, for mutual TLS")
    args = p.parse_args(argv)
    try:
        check_name(args.run, "--run")
        check_name(args.name, "--name")
        for option, path in (("--tls-ca", args.tls_ca), ("--tls-cert", args.tls_cert), ("--tls-key", args.tls_key),
                             ("--auth-file", args.auth_file)):
            if path is not None and not path.is_file():  # Zenoh would say only that it cannot connect
                raise ValueError(f"{option} {path}: no such file (in {os.getcwd()})")
        args.security = ClientSecurity.from_env(None, args.auth_file, args.tls_ca, args.tls_cert, args.tls_key)
        for name in (SECRET_ENV, ZENOH_AUTH_ENV):  # read once; processes this one starts do not inherit them
            os.environ.pop(name, None)
        _check_login_names(args.security.login, args.run, args.name)
    except ValueError as exc:
        _refuse(p, str(exc))
    if args.max_request is not None and args.max_request < 1:
        _refuse(p, "--max-request must be a positive number of bytes")
    if args.queue < 1:
        _refuse(p, "--queue must be at least 1")
    return args


def _refuse(parser: argparse.ArgumentParser, message: str) -> NoReturn:
    """A value the options parsed but that cannot serve: one line, without the usage text argparse puts above its
    own errors (15 lines before the one that says what to change: a multi-host probe)."""
    parser.exit(2, f"{parser.prog}: error: {message}\n")


def _check_login_names(login: tuple[str, str] | None, run: str, name: str) -> None:
    """A run's own logins are ``cosim-<run>`` and ``cosim-<run>.<name>``: one made for another run or subsim would
    connect and then be refused its keys in silence (the router's access control), so say it here."""
    if login is None or not login[0].startswith("cosim-") or login[0] in (f"cosim-{run}", f"cosim-{run}.{name}"):
        return  # a site login (--auth-file), or this run's
    raise ValueError(f"${ZENOH_AUTH_ENV} is the login {login[0]!r}, made for another run or subsim than --run {run} "
                     f"--name {name}: start it with the run id and name the coordinator printed with it")


ROUTER_GRACE = 2.0  # s without a router before a subsim stops
LINK_LOST = (f"as the coordinator's router has been unreachable for {ROUTER_GRACE:g} s; if the coordinator still runs "
             "(a cut link), start this same command again: the run restores this subsim")


def _watch_router(session: zenoh.Session, grace: float = ROUTER_GRACE) -> None:
    """SIGTERM ourselves when the coordinator's router has been unreachable for ``grace`` seconds.

    A client whose router vanished gets no liveliness DELETE (its only link is gone), so poll.
    """
    lost_since = None
    while True:
        time.sleep(0.25)
        try:
            connected = any(True for _ in session.info.routers_zid())
        except Exception:  # session closed: we are exiting anyway
            return
        now = time.monotonic()
        lost_since = None if connected else (lost_since or now)
        if lost_since is not None and now - lost_since >= grace:
            _router_lost.set()
            _stop_self(LINK_LOST)
            return


def main(model_cls: type[Subsim] | Subsim, argv: Sequence[str] | None = None, prog: str | None = None) -> int:
    args = parse_args(model_cls, argv, prog)
    if args.quiet_stop:  # launched by cosim run, whose standard output is its results summary: a model's print()
        os.dup2(2, 1)  # goes to stderr, and (from Python) with the subsim's name before each line
        sys.stdout = prefixed_stream(2, f"{args.name}: ")
        sys.stderr = prefixed_stream(2, f"{args.name}: ", once=True)  # warnings, print(file=sys.stderr): a probe
    signal.signal(signal.SIGTERM, _raise_stop)
    signal.signal(signal.SIGINT, _raise_stop)
    try:
        try:  # zenoh.open holds the signals until it returns (within --connect-timeout)
            try:
                runtime = Runtime(model_cls, name=args.name, history_limit=args.history)
            except CosimError as exc:  # its model cannot be built: what the coordinator quotes as its last line
                say(f"{args.name}: cannot start: {exc.message}")
                return 1
            if not args.quiet_stop:  # started by hand (not launched by cosim run): its owner watches this terminal
                runtime.on_model_error = lambda cmd, exc: say(
                    f"{args.name}: {cmd} failed: [{exc.code}] {exc.message}"
                    + (f"\n{exc.traceback.rstrip()}" if exc.traceback else ""))
            mismatch = zenoh_mismatch()
            if mismatch is not None:  # (an older zenoh serves, then fails every request with a TypeError)
                say(f"{args.name}: {mismatch}")
                return 2
            why, connected = unreachable(args.connect, min(2.0, args.connect_timeout))
            if why is not None:  # said at once: zenoh would retry until --connect-timeout, then say less
                say(f"{args.name}: cannot reach the coordinator at {args.connect}: {why}")
                return 2
            session = zenoh.open(client_config(args.connect, args.connect_timeout, int(args.lease * 1000),
                                              security=args.security))
        except zenoh.ZError as exc:
            cause = (tls_cause(args.connect, args.security) if connected else
                     "no answer from that address: a firewall, no route, or the wrong address?")
            gone = unreachable(args.connect, 0.5)[0] if connected else None
            if gone is not None:  # it was there a moment ago: its coordinator stopped (or was killed) meanwhile
                cause = f"it went away while this subsim connected: {gone}"
            say(f"{args.name}: cannot reach the coordinator at {args.connect} within {args.connect_timeout:g} s "
                f"({cause}) ({error_text(exc)})")
            return 2
    except _Stop as why:  # also one that arrived while zenoh.open held it, raised in the handler above
        if not args.quiet_stop:
            say(f"{args.name}: stopping {why}")
        return 0
    server: CommandServer | None = None
    try:
        try:  # a signal may come at any point from here on, even before serving starts (it is ready to be seen)
            server = CommandServer(
                session, args.run, runtime, on_coordinator_lost=lambda: _stop_self("as the coordinator left"),
                key=args.security.key, max_request=args.max_request, queue_size=args.queue,
                on_never_sealed=lambda: say(f"{args.name}: requests arrive, but none is sealed with our key: is "
                                            f"{SECRET_ENV} the one the coordinator printed for run {args.run}?"),
            )
            threading.Thread(target=_watch_router, args=(session,), daemon=True, name="router-watch").start()
            if not args.quiet_start:
                say(f"{args.name}: serving run {args.run} via {args.connect} as Zenoh id {session.zid()} "
                    f"(pid {os.getpid()})")  # (the id a coordinator's [duplicate] error names)
            server.serve()
            if not args.quiet_stop:
                say(f"{args.name}: shutdown requested by the coordinator")
        except _Stop as why:
            if not args.quiet_stop:
                say(f"{args.name}: stopping {why}")
        finally:
            # leaving anyway: a SIGTERM now (e.g. the coordinator's token deleted right after our shutdown
            # reply) must not interrupt the clean-up and turn exit code 0 into a traceback
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            if server is not None and not _router_lost.is_set():
                server.close()
    finally:
        if _router_lost.is_set():  # the router is gone: leave now (the system closes our sockets)
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(EXIT_LINK_LOST if _why_stopping[:1] == [LINK_LOST] else 0)  # not if it was stopping anyway
        session.close()
    return 0
