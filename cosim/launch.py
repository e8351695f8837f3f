"""Start subsim processes, on this machine or through a launcher on another, and stop them reliably.

Used by ``cosim run`` and by the pytest fixtures in :mod:`cosim.testing`.
"""

from __future__ import annotations

import fcntl
import os
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import zenoh

from cosim.console import StderrRelay
from cosim.contract import SubsimError
from cosim.importing import MODULE_PATH_ENV, SEARCH_PATH
from cosim.protocol.keys import check_name, coordinator_alive_key, new_run_id, rpc_key
from cosim.protocol.messages import encode_request, next_seq, seal_request
from cosim.protocol.security import (
    SECRET_ENV,
    ZENOH_AUTH_ENV,
    Security,
    new_master_secret,
    read_dictionary,
    subsim_key,
    zenoh_login,
)
from cosim.protocol.transport.client import EVERY_QUERYABLE, RemoteHandle
from cosim.protocol.transport.session import UNIX_SOCKET, open_router, split_endpoint, zenoh_mismatch


def subsim_command(
    module: str,
    endpoint: str,
    run: str,
    name: str,
    model: str | None = None,
    python: str = sys.executable,
    tls_ca: Path | None = None,
    tls_client: tuple[Path, Path] | None = None,
    lease: float | None = None,
) -> list[str]:
    """``python -m module`` for a subsim package, or ``python -m cosim.serve model`` for any class. Its
    key and login go in the environment (:meth:`Bus.subsim_env`), never here: ``ps`` shows arguments.
    ``tls_ca``: the CA to verify the router with; ``tls_client``: (certificate, key) for mutual TLS."""
    head = [python, "-m", "cosim.serve", model] if model else [python, "-m", module]
    tls = ["--tls-ca", str(tls_ca)] if tls_ca is not None else []
    if tls_client is not None:
        tls += ["--tls-cert", str(tls_client[0]), "--tls-key", str(tls_client[1])]
    lease_arg = ["--lease", f"{lease:g}"] if lease else []
    return [*head, "--connect", endpoint, "--run", run, "--name", name, *tls, *lease_arg]


@dataclass(frozen=True)
class Elsewhere:
    """How to start a subsim on another machine: ``launcher`` (e.g. ``("ssh", "lab-2")``) followed by one shell
    line that goes to ``workdir``, reads the subsim's two secrets from standard input (arguments would show in
    ``ps`` there) and runs ``python``'s subsim process, connecting to ``connect`` (None: the bus's endpoint)."""

    launcher: tuple[str, ...]
    workdir: str | None = None
    python: str = "python3"
    connect: str | None = None

    @property
    def shown(self) -> str:
        """The launcher as a user would type it."""
        return shlex.join(self.launcher)


UNSPECIFIED_HOSTS = ("0.0.0.0", "[::]", "::")


def endpoint_for(elsewhere: Elsewhere, listen: str, endpoint: str) -> str:
    """The endpoint a subsim started elsewhere connects to: its ``connect``, else ``endpoint``, where the router
    listening on ``listen`` is reached; ValueError if ``listen`` names no address that machine could be given (an
    unspecified host, a Unix socket)."""
    if elsewhere.connect is not None:
        return elsewhere.connect
    try:
        host = split_endpoint(listen)[0]
    except ValueError:  # a Unix socket
        host = ""
    if listen.partition("/")[0] not in ("tcp", "tls", "quic", "udp") or host in UNSPECIFIED_HOSTS:
        raise ValueError(f"the coordinator listens on {listen}, an address another machine cannot be told: listen "
                         "on an address of this machine it reaches (--listen tcp/<address>:<port>), or set connect")
    return endpoint


def launcher_line(argv: Sequence[str], workdir: str | None) -> str:
    """The shell line a launcher runs: the two secrets come on standard input, one a line. A ``workdir`` of ``~``
    or ``~/...`` is the home directory there (the rest quoted: spaces and quotes are the path's own)."""
    if not workdir:
        where = None
    elif workdir == "~":
        where = "~"
    elif workdir.startswith("~/"):
        where = "~/" + shlex.quote(workdir[2:])
    else:
        where = shlex.quote(workdir)
    cd = f"cd -- {where} && " if where else ""
    return (f"{cd}IFS= read -r {SECRET_ENV} && IFS= read -r {ZENOH_AUTH_ENV} && "
            f"export {SECRET_ENV} {ZENOH_AUTH_ENV} PYTHONUNBUFFERED=1 && exec {shlex.join(argv)}")


def exit_status(popen: subprocess.Popen, elsewhere: Elsewhere | None = None, wait: float = 0.0,
                relay: StderrRelay | None = None) -> str | None:
    """How a subsim's process ended ("its process was killed by SIGSEGV"), waiting up to ``wait`` seconds for it
    to be reaped; None while it runs. Started ``elsewhere``, the process here is its launcher. With the ``relay``
    of its stderr, an exit with an error says the last line it wrote (why a model failed to start)."""
    try:
        code = popen.wait(wait)
    except subprocess.TimeoutExpired:
        return None
    what = "process" if elsewhere is None else f"launcher {elsewhere.shown!r}"
    if code >= 0:
        status = f"its {what} exited with code {code}"
    else:
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = f"signal {-code}"
        status = f"its {what} was killed by {name}"
    last = None if relay is None or code in (0, -signal.SIGKILL, -signal.SIGTERM) else relay.last_line()
    return status if last is None else f"{status}; the last line it wrote: {last}"


def terminate(popen: subprocess.Popen, grace: float = 3.0) -> int:
    """SIGTERM, then SIGKILL if the process is still there after ``grace`` seconds; always reaps it. Its exit code."""
    if popen.poll() is None:
        popen.terminate()
    try:
        return popen.wait(grace)
    except subprocess.TimeoutExpired:
        popen.kill()
        return popen.wait()


@dataclass
class SubsimProcess:
    """A local subsim process and its handle."""

    name: str
    popen: subprocess.Popen
    handle: RemoteHandle
    module: str = ""
    model: str | None = None
    lease: float | None = None
    elsewhere: Elsewhere | None = None  # started through a launcher: popen is the launcher
    relay: StderrRelay | None = None  # its stderr, copied to ours

    def reaped(self, code: int) -> int:
        """``code``, once what the process wrote on stderr is all copied."""
        if self.relay is not None:
            self.relay.finish()
        return code

    def stop(self, grace: float = 3.0) -> int:
        """Ask for ``shutdown``, then SIGTERM, then SIGKILL; always reaps the process. One known to be hung
        (it missed a deadline) or found stopped (SIGSTOP, Ctrl-Z) is killed at once: it would let every grace run
        out (a red team's Ctrl-C took 8-9 s with one subsim stopped)."""
        if self.popen.poll() is None and (getattr(self.handle, "hung", False) or _stopped(self.popen.pid)):
            self.popen.kill()
            self.handle.close()
            return self.reaped(self.popen.wait())
        if self.popen.poll() is None and self.handle.alive:
            try:
                self.handle.timeout = min(self.handle.timeout, grace)  # the handle is closed below anyway
                self.handle.shutdown()
            except Exception:
                pass
        try:
            return self.reaped(self.popen.wait(grace))
        except subprocess.TimeoutExpired:
            return self.reaped(terminate(self.popen, grace))
        finally:
            self.handle.close()


def _stopped(pid: int) -> bool:
    """Whether process ``pid`` is stopped by a signal (its state in Linux's /proc is T); False where not known."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rpartition(b")")[2].split()[0] == b"T"  # (the name may hold spaces; t, a debugger's: not)
    except (OSError, IndexError):
        return False


DEATH_REAPED = 0.5  # s a dead subsim's process is given to be reaped, so that its error can say how it ended
PRIVATE = "private"  # Bus.open(PRIVATE): a router only this user's processes on this machine can reach
PRIVATE_PREFIX = "cosim-bus-"


def _sweep_private_dirs(min_age: float = 60.0) -> None:
    """Remove the private bus directories of this user's coordinators that were killed (SIGKILL leaves them): Zenoh
    holds a lock on ``router.sock.lock`` while it listens, so a directory whose lock is free or gone (its router closed
    but the coordinator died before removing it), and that is older than ``min_age`` seconds (not one being set up
    now), belongs to no live router."""
    root = Path(tempfile.gettempdir())
    for directory in root.glob(PRIVATE_PREFIX + "*"):
        lock = directory / "router.sock.lock"
        try:
            st = directory.stat()
            if st.st_uid != os.getuid() or time.time() - st.st_mtime < min_age:
                continue
            fd = os.open(lock, os.O_RDWR)
        except FileNotFoundError:  # no lock: no router listens there
            shutil.rmtree(directory, ignore_errors=True)
            continue
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # held: a router listens there
            continue
        finally:
            os.close(fd)
        shutil.rmtree(directory, ignore_errors=True)


@dataclass
class Bus:
    """The coordinator's router session, its endpoint and the run id that namespaces every key.

    Every run has an unguessable id and a master secret; each subsim signs with a key derived from it
    (:meth:`key`), and the router admits only the run's own logins (one per subsim when the names are given,
    plus the users of ``security.auth_file``) under access control (docs/reliability.md, "Security model")."""

    session: zenoh.Session
    endpoint: str
    run: str
    secret: bytes = field(default_factory=new_master_secret, repr=False)
    security: Security = field(default_factory=Security)
    processes: list[SubsimProcess] = field(default_factory=list)
    attached: list[str] = field(default_factory=list)  # names of external subsims: sent shutdown on close
    private_dir: str | None = None  # the 0700 directory of a PRIVATE endpoint's socket, removed on close
    names: tuple[str, ...] | None = None  # the subsims this run may have, each with its own login (None: shared)
    search_path: tuple[str, ...] | None = None  # its scenario's module directories (None: every one loaded so far)
    announce: bool = True  # the subsims it starts say "serving run ... (pid N)" (cosim run --quiet: they do not)
    _spawned_as: dict[str, tuple[str, str | None, float | None, Elsewhere | None]] = field(default_factory=dict,
                                                                                         repr=False)
    _generation: dict[str, int] = field(default_factory=dict, repr=False)  # replacements respawn started, by name
    # the Zenoh ids of the processes that have served each name in this run: a handle to its replacement ignores one
    # that wakes up and answers again (it holds none of the run's state now)
    _served: dict[str, set] = field(default_factory=dict, repr=False)
    closed: bool = field(default=False, init=False)

    @classmethod
    def open(cls, listen: str = "tcp/127.0.0.1:0", run: str | None = None, security: Security | None = None,
             names: Sequence[str] | None = None, site_serves: Sequence[str] | None = None) -> Bus:
        """``listen``: a Zenoh endpoint, or :data:`PRIVATE`: a Unix socket in a fresh directory only this user can
        enter, for runs whose subsims are all started here (other users cannot even connect, let alone flood).

        ``names``: the subsims of the run. Each then logs in with its own login, which may serve only that
        subsim's keys, so no subsim can read or answer another's requests. ``site_serves``: the named subsims that
        ``--auth-file`` users may serve too (and so read the requests of): the ones started by hand on their
        sites (None: every one). Without names, every subsim shares the run's login and may serve any subsim key."""
        mismatch = zenoh_mismatch()
        if mismatch is not None:
            raise ValueError(mismatch)
        security = (security or Security()).check()
        run, secret = new_run_id() if run is None else check_name(run, "run id"), new_master_secret()
        site = read_dictionary(security.auth_file) if security.auth_file else {}
        if names is None:
            user, password = zenoh_login(secret, run)
            logins, servers = {**site, user: password}, None
        elif not names:  # no login at all would open the router to anyone
            raise ValueError("Bus.open(names=...): name at least one subsim (or pass None for one shared login)")
        else:
            names = tuple(dict.fromkeys(check_name(n, "subsim name") for n in names))
            own = {name: zenoh_login(secret, run, name) for name in names}
            logins = {**site, **dict(own.values())}
            served = set(names if site_serves is None else site_serves)
            servers = {name: [user, *(site if name in served else ())] for name, (user, _) in own.items()}
        private_dir = None
        if listen == PRIVATE:
            _sweep_private_dirs()
            private_dir = tempfile.mkdtemp(prefix=PRIVATE_PREFIX)  # mode 0700
            listen = f"{UNIX_SOCKET}{private_dir}/router.sock"
        try:
            session, endpoint = open_router(listen, run=run, logins=logins, security=security, servers=servers)
        except BaseException:
            if private_dir is not None:
                shutil.rmtree(private_dir, ignore_errors=True)
            raise
        bus = cls(session, endpoint, run, secret, security, private_dir=private_dir, names=names)
        bus._token = session.liveliness().declare_token(coordinator_alive_key(bus.run))
        return bus

    def key(self, name: str) -> bytes:
        """The key subsim ``name`` signs with (only that subsim gets it); each replacement :meth:`respawn` starts
        gets a key of its own."""
        return subsim_key(self.secret, self.run, name, self._generation.get(name, 0))

    def subsim_env(self, name: str) -> dict[str, str]:
        """What a subsim process of this run needs in its environment: its key and its login to the router."""
        self._check_named(name)
        user, password = zenoh_login(self.secret, self.run, None if self.names is None else name)
        return {SECRET_ENV: self.key(name).hex(), ZENOH_AUTH_ENV: f"{user}:{password}"}

    def _check_named(self, name: str) -> None:
        if self.names is not None and name not in self.names:
            raise ValueError(f"subsim {name!r} is not one of this run's subsims ({', '.join(self.names)}): the bus "
                             "gives logins only to the names it opened with")

    def command(self, module: str, name: str, model: str | None = None, lease: float | None = None,
                endpoint: str | None = None, python: str = sys.executable,
                client: tuple[str, str] | None = None) -> list[str]:
        """The command line of a subsim of this run, connecting to ``endpoint`` (default: the router's) with
        ``python``. Under mutual TLS it shows ``client`` (certificate, key), by default the router's own: a subsim
        this machine launches (or one started elsewhere through a launcher, where the same paths must hold the
        same files); an operator's command names a certificate of their machine instead."""
        sec = self.security
        client = client or ((sec.tls_cert, sec.tls_key) if sec.mutual and sec.tls_cert and sec.tls_key else None)
        return subsim_command(module, endpoint or self.endpoint, self.run, name, model, python=python,
                              tls_ca=sec.tls_ca, tls_client=client, lease=lease)

    def _remote_handle(self, name: str, timeout: float) -> RemoteHandle:
        """A handle to subsim ``name`` of this run, with its key and the processes that served the name before."""
        return RemoteHandle(self.session, self.run, name, timeout=timeout, key=self.key(name),
                            served=self._served.setdefault(name, set()))

    def attach(self, name: str, timeout: float = 60.0, wait: float = 10.0) -> RemoteHandle:
        """Handle to a subsim that is (or soon will be) serving ``name`` in this run."""
        self._check_named(name)
        handle = self._remote_handle(name, timeout)
        try:
            handle.wait_ready(wait)
        except Exception:
            handle.close()
            raise
        self.attached.append(name)
        return handle

    def spawn(
        self,
        module: str,
        name: str,
        timeout: float = 60.0,
        wait: float = 20.0,
        quiet: bool = False,
        model: str | None = None,
        lease: float | None = None,
        elsewhere: Elsewhere | None = None,
    ) -> SubsimProcess:
        """Start ``python -m module`` (or ``cosim.serve model``) as subsim ``name``, here or ``elsewhere`` through
        its launcher; wait until it answers."""
        if self.closed:  # (it started the process, then failed on the closed session: a zombie; an API probe)
            raise RuntimeError(f"cannot start subsim {name!r}: this bus is closed (open another: Bus.open)")
        secrets = self.subsim_env(name)
        serving = [p.popen.pid for p in self.processes if p.name == name and p.popen.poll() is None]
        if serving:  # a second process would share its key: requests to either would reach the first
            raise ValueError(f"subsim {name!r} is served by process {serving[0]} of this bus already: give the "
                             "other one its own name (or respawn it)")
        self._spawned_as[name] = (module, model, lease, elsewhere)  # for respawn, even if this start fails
        there = {} if elsewhere is None else {"endpoint": elsewhere.connect, "python": elsewhere.python}
        argv = [*self.command(module, name, model, lease=lease, **there), "--quiet-stop",
                *([] if self.announce or elsewhere else ["--quiet-start"])]  # (a cosim over there may predate it)
        if elsewhere is None:
            env = {**os.environ, **secrets}
            env.setdefault("PYTHONUNBUFFERED", "1")
            search = SEARCH_PATH if self.search_path is None else self.search_path
            if search:  # the scenario's directory and the working directory (cosim.importing), in that order
                env["PYTHONPATH"] = os.pathsep.join([*filter(None, [env.get("PYTHONPATH")]), *search])
                env[MODULE_PATH_ENV] = os.pathsep.join(search)  # cosim.serve puts them after the installed ones
        else:  # the launcher gets neither the secrets (they go on its standard input) nor this machine's paths
            env, argv = dict(os.environ), [*elsewhere.launcher, launcher_line(argv, elsewhere.workdir)]
        try:
            popen = subprocess.Popen(
                argv,
                env=env,
                stdin=None if elsewhere is None else subprocess.PIPE,
                stdout=subprocess.DEVNULL if quiet else None,
                stderr=subprocess.DEVNULL if quiet else subprocess.PIPE,  # copied to ours by a StderrRelay
                # its own process group: a Ctrl-C at the terminal reaches the coordinator only, which stops its
                # subsims in order (they would otherwise each print their own stop line)
                process_group=0,
            )
        except OSError as exc:  # e.g. out of file descriptors or processes, or no such launcher
            how = "its process" if elsewhere is None else f"its launcher {elsewhere.shown!r}"
            raise SubsimError("no_responder", f"cannot start {how}: {exc}", name, "spawn") from None
        try:  # until it is in self.processes, nothing else would stop it (a Ctrl-C here left it running: an API probe)
            if popen.stdin is not None:
                try:
                    popen.stdin.write(f"{secrets[SECRET_ENV]}\n{secrets[ZENOH_AUTH_ENV]}\n".encode())
                    popen.stdin.close()
                except OSError:  # the launcher is gone already: its exit is reported below
                    pass
            relay = StderrRelay(popen.stderr)
            handle = self._remote_handle(name, timeout)
        except BaseException:
            popen.kill()
            popen.wait()
            raise
        handle.exit_status = partial(exit_status, popen, elsewhere, DEATH_REAPED, relay)
        if lease:
            handle.lease = lease
        proc = SubsimProcess(name, popen, handle, module, model, lease, elsewhere, relay)
        self.processes.append(proc)
        try:
            _wait_ready_or_exit(handle, popen, wait, elsewhere, relay)
        except BaseException:
            proc.stop(grace=1.0)
            raise
        return proc

    def respawn(self, name: str, **spawn_args: object) -> SubsimProcess:
        """Kill the process serving ``name`` (it died or hung: no grace) and start a new one the same way."""
        if name not in self._spawned_as:
            raise KeyError(f"no process of this bus serves {name!r}")
        for old in [p for p in self.processes if p.name == name]:  # none if its last start failed to make one
            if old.popen.poll() is None:
                old.popen.kill()
            old.reaped(old.popen.wait())
            old.handle.close()
            self.processes.remove(old)
        module, model, lease, elsewhere = self._spawned_as[name]
        # a new key: the old process, if it was only stopped (a launcher cannot kill it over there), stays deaf
        self._generation[name] = self._generation.get(name, 0) + 1
        return self.spawn(module, name, model=model, lease=lease, elsewhere=elsewhere,
                          **spawn_args)  # type: ignore[arg-type]

    def query(self, key: str, payload: bytes, timeout: float) -> list[bytes]:
        """The payloads of every reply (not Zenoh error replies) to one query on ``key``, as they came: for checks
        of what a subsim answers at all (``cosim.conformance``)."""
        replies = self.session.get(key, payload=payload, timeout=timeout, target=EVERY_QUERYABLE,
                                   consolidation=zenoh.ConsolidationMode.NONE)
        return [r.ok.payload.to_bytes() for r in replies if r.ok is not None]

    def withdraw_token(self) -> None:
        """Withdraw the coordinator's liveliness token (as a coordinator that leaves does): every subsim of the run
        stops serving. ``close`` still stops the processes and closes the session."""
        try:
            self._token.undeclare()
        except zenoh.ZError:  # withdrawn already
            pass

    def close(self) -> None:
        """Send ``shutdown`` to attached subsims, stop every spawned process, undeclare the coordinator's
        token, then close the session (the order matters: see zenoh-notes P1)."""
        if self.closed:
            return
        pending = [self.session.get(rpc_key(self.run, name), timeout=3.0, consolidation=zenoh.ConsolidationMode.NONE,
                                    target=EVERY_QUERYABLE,
                                    payload=seal_request(self.key(name), next_seq(), encode_request("shutdown")))
                   for name in self.attached]  # a subsim gone or busy is ended by the token's DELETE below
        for replies in pending:
            list(replies)
        self.attached.clear()
        failed: list[BaseException] = []

        def stop(proc: SubsimProcess) -> None:
            try:
                proc.stop()
            except BaseException as exc:  # raised here once all are stopped, as it was when one stopped after another
                failed.append(exc)

        stopping = [threading.Thread(target=stop, args=(proc,), daemon=True) for proc in reversed(self.processes)]
        for thread in stopping:  # side by side: each may wait out its graces (a hung one), the run's end only once
            thread.start()
        for thread in stopping:
            thread.join()
        self.processes.clear()
        for step in (self._token.undeclare, self.session.close):
            try:  # the run is over: a router too busy to close in time (a connection flood) must not fail it
                step()
            except zenoh.ZError:
                pass
        self.closed = True  # (only now: a close cut short, by a Ctrl-C say, may be done again)
        if self.private_dir is not None:
            shutil.rmtree(self.private_dir, ignore_errors=True)
        if failed:  # (after the session and the directory: a failed stop left both behind)
            raise failed[0]

    def __enter__(self) -> Bus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


NOT_UP = "did not come up within"  # a started process that never answered: cosim.runner starts it again when it
STOPPED = "its process is stopped"  # was found stopped (a slow start or a hang in its model would come again)


def _wait_ready_or_exit(handle: RemoteHandle, popen: subprocess.Popen, wait: float,
                        elsewhere: Elsewhere | None = None, relay: StderrRelay | None = None) -> None:
    deadline = time.monotonic() + wait
    while time.monotonic() < deadline:
        status = exit_status(popen, elsewhere, relay=relay)
        if status is not None:
            raise SubsimError("no_responder", status, handle.name, "spawn")
        if handle.wait_alive(0.05):
            handle.wait_ready(max(deadline - time.monotonic(), 0.1))
            return
    how = "" if elsewhere is None else (f" (its launcher {elsewhere.shown!r} still runs: does it "
                                        "wait for a password or a host key?)")
    if elsewhere is None and _stopped(popen.pid):  # (a slow start would be as slow again: only this is retried)
        how = f" ({STOPPED})"
    raise SubsimError("no_responder", f"{NOT_UP} {wait:g} s{how}", handle.name, "spawn")
