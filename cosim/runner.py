"""Run a scenario: open the bus, launch or attach subsims, configure, couple, write results.

The I/O shell around the coupler: scenario in, processes up, :class:`~cosim.driver.Coordinator` over them, results out.
"""

from __future__ import annotations

import json
import math
import socket
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from types import MappingProxyType

from cosim import interrupt
from cosim.console import say
from cosim.contract import MalformedReply, SubsimError
from cosim.coupler.couplings import CouplingError, SignalRef
from cosim.coupler.plan import Plan
from cosim.coupler.relaxation import Interval, RunSummary, Settings
from cosim.driver import Abandoned, Coordinator, Deadline, Recovery, Restart, plan_for
from cosim.handles import Description, InProcessHandle, SubsimHandle
from cosim.importing import differing_code
from cosim.launch import NOT_UP, PRIVATE, STOPPED, UNSPECIFIED_HOSTS, Bus, Elsewhere, SubsimProcess, endpoint_for
from cosim.outputs import OutputError, OutputWriteError, reserve_output, resume_path
from cosim.progress import Progress
from cosim.protocol.security import Security
from cosim.protocol.transport.client import NOT_APPEARED, NotAppeared, RemoteHandle
from cosim.protocol.transport.session import split_endpoint
from cosim.results import ResultWriter, diag_path, output_units
from cosim.resume import Saved, changed_code, changes, fingerprint, fingerprinted, model_files
from cosim.resume import load as load_resume
from cosim.resume import save as save_resume
from cosim.scenario import RunSpec, Scenario, ScenarioError, SubsimSpec

Log = Callable[[str], None]


@dataclass
class RunReport:
    method: str
    summary: RunSummary
    output: Path | None  # None: a run that wrote no file (record=False)
    diagnostics: Path | None
    order: list[str]
    feedback: list[str]
    extra: dict = field(default_factory=dict)


class Unrecorded:
    """The writer of a run that keeps no result file: every interval counts as written at once."""

    t_last = None

    def write_steps(self, interval: Interval) -> Iterator[None]:
        return iter(())

    def holds(self, interval: Interval) -> bool:
        return True

    def written(self, t: float) -> None:
        return None

    def sync(self) -> None:
        pass

    def close(self, failed_run: bool = False) -> None:
        pass


@dataclass
class Session:
    """Handles to a scenario's subsims, configured, plus the bus they live on (None in-process)."""

    scenario: Scenario
    handles: dict[str, SubsimHandle]
    descriptions: dict[str, Description]
    bus: Bus | None = None
    plans: dict[str, Plan] = field(default_factory=dict)  # per method, checked once
    external_wait: float = 300.0
    timeout: float = 120.0
    log: Log = say
    listen: str | None = None  # the router endpoint asked for (--listen): what external subsims are told
    restarts_left: int = 0  # the run's restarts not used by subsims lost while they started
    started_again: list[Restart] = field(default_factory=list)  # those, for the run's summary

    def revive(self, name: str, why: str = "") -> SubsimHandle:
        """A new process for a subsim that died or hung (``why``: how), configured as at the run's start: a launched
        one is killed and started again; an external one is waited for to attach again under its name, once (one
        that does not come back within the wait stops the run: :class:`Abandoned`)."""
        if self.bus is None:
            raise ScenarioError(f"{self.scenario.path}: {name} failed in-process: nothing to restart")
        spec = self.scenario.subsims[name]
        if spec.external:  # nothing else is printed until it is back: say why, what is awaited, and from whom
            self.log(f"cosim: external subsim {name!r} {why or 'was lost'}; it must attach again: waiting up to "
                     f"{self.external_wait:g} s for it (the old process, should it wake up once a new one has "
                     "attached, is ignored)\n" + attach_lines(self.bus, self.scenario, name, self.listen, first=False))
            # not a first start's '--run and --name': the same command, not started again
            try:
                handle: SubsimHandle = attach(self.bus, self.scenario, name, self.timeout, self.external_wait,
                                              f"it did not attach again within {self.external_wait:g} s (its command "
                                              "is above; --attach-wait sets how long it is waited for)")
            except NotAppeared as exc:  # waited for as long as asked: another wait would only double it
                raise Abandoned(exc.code, exc.message, name, exc.command) from None
        elif spec.launcher:
            handle = self._respawn_elsewhere(name)
        else:
            handle = self.bus.respawn(name, timeout=self.timeout).handle
        self.check_code(name, handle.configure(spec.params, t0=self.scenario.start))
        return handle

    def check_code(self, name: str, description: Description) -> None:
        """Say so when subsim ``name``, served from another machine or started by hand, runs other code than this
        machine has for the same modules: the same scenario run here would compute something else."""
        spec = self.scenario.subsims[name]
        model = spec.model or description.model  # (an external subsim's scenario need not name its model)
        differ = differing_code(description.code, model) if spec.external or spec.launcher else []
        if differ:
            shown = ", ".join(differ[:4]) + (f" and {len(differ) - 4} more" if len(differ) > 4 else "")
            self.log(f"cosim: {name} runs other code than this machine has for {shown} (the files differ): its "
                     "results may differ from the same run here")

    def _respawn_elsewhere(self, name: str) -> SubsimHandle:
        """A subsim on another machine, started again through its launcher. When it cannot start (the network
        between the machines is down, as it may well be when the old one was lost), it is tried again every
        :data:`RETRY_ELSEWHERE` seconds for up to ``external_wait``, as an external subsim is waited for: one
        replacement, not one restart per try."""
        assert self.bus is not None
        started, tries = time.monotonic(), 0
        while True:
            try:
                return self.bus.respawn(name, timeout=self.timeout).handle
            except SubsimError as exc:
                if exc.command not in ("spawn", "connect"):
                    raise
                tries += 1
                if time.monotonic() + RETRY_ELSEWHERE > started + self.external_wait:
                    if tries == 1:  # a wait shorter than one retry: one failed replacement, as any (restarts left)
                        raise
                    raise Abandoned(exc.code, f"{exc.message} ({tries} tries in {time.monotonic() - started:.0f} s, "
                                    "--attach-wait)", name, exc.command) from None
                if tries == 1:
                    self.log(f"cosim: {name} could not be started again over there ({exc.message}); trying again "
                             f"every {RETRY_ELSEWHERE:g} s for up to {self.external_wait:g} s (--attach-wait)")
                time.sleep(RETRY_ELSEWHERE)

    def close(self) -> None:
        for h in self.handles.values():
            h.close()
        if self.bus is not None:
            self.bus.close()


def open_session(
    scenario: Scenario,
    inprocess: bool = False,
    listen: str | None = None,
    external_wait: float = 300.0,
    log: Log = say,
    timeout: float = 120.0,
    security: Security | None = None,
    run_id: str | None = None,
    announce: bool = True,
    restarts: int = 0,
) -> Session:
    """Launch (or attach to) and configure every subsim. The caller must ``close()`` the session.
    ``restarts``: how often a subsim process killed by a signal while it starts or is configured (a crash, the
    OOM killer) is started again.

    ``security``: TLS and login files (else the scenario's ``[security]`` table, else loopback defaults).
    An external subsim is waited for up to ``external_wait`` seconds; for each, ``log`` gets one
    machine-readable line first: ``cosim-attach {"endpoint": ..., "run": ..., "name": ..., "command": [...],
    "env": {...}}``. ``run_id`` fixes the run id (default: a fresh one) so that a launcher knows it in advance.
    ``announce``: each subsim started says "serving run ... (pid N)" on stderr."""
    handles: dict[str, SubsimHandle] = {}
    bus = None
    away: dict[str, Elsewhere] = {}  # the subsims started on other machines, each with the endpoint it is given
    if inprocess:
        for name, spec in scenario.subsims.items():
            if spec.external or spec.model is None or spec.launcher:
                where = "started on another machine (launcher)" if spec.launcher else "external"
                raise ScenarioError(f"{scenario.path}: [subsims.{name}] is {where}: it cannot run in this "
                                    "process (cosim run without --inprocess; cosim describe --launch)")
            try:
                handles[name] = InProcessHandle(spec.model_class(), name)
            except SubsimError as exc:  # its model cannot be built
                raise ScenarioError(f"{scenario.path}: [subsims.{name}] {exc.message}") from None
    else:
        for name, spec in scenario.subsims.items():
            if not spec.external and str(spec.model or "").startswith("__main__:"):  # its process exited, code 2
                raise ScenarioError(f"{scenario.path}: [subsims.{name}.model] {spec.model!r} is a class of the "
                                    "running script, which a subsim process cannot import: put it in a module "
                                    "file beside the scenario, or run in this process (inprocess=True)")
        away = {name: how for name, spec in scenario.subsims.items() if (how := elsewhere(spec)) is not None}
        if away and listen is None:
            raise ScenarioError(f"{scenario.path}: [subsims.{next(iter(away))}] is started on another machine "
                                "(launcher): give --listen tcp/<an address of this machine it reaches>:<port>")
        try:
            security = security or scenario.security
            bus = Bus.open(listen or default_listen(scenario, security), run=run_id, security=security,
                           names=list(scenario.subsims),  # a site's --auth-file login serves only what it starts:
                           site_serves=[n for n, spec in scenario.subsims.items() if spec.external])
        except (ValueError, RuntimeError) as exc:  # bad --listen or security files; port taken
            raise ScenarioError(f"cannot open the bus: {exc}") from None
        bus.search_path = scenario.search_path  # its subsims import its modules, not another scenario's
        bus.announce = announce
        for name, how in away.items():  # each told the endpoint its machine reaches
            try:
                away[name] = replace(how, connect=endpoint_for(how, str(listen), bus.endpoint))
            except ValueError as exc:
                bus.close()
                raise ScenarioError(f"{scenario.path}: [subsims.{name}] {exc}") from None
    session = Session(scenario, handles, {}, bus, external_wait=external_wait, timeout=timeout, log=log, listen=listen,
                      restarts_left=restarts)
    try:
        if bus is not None:
            external = [name for name, spec in scenario.subsims.items() if spec.external]
            for name in external:  # every external subsim's command at once: their operators start them in parallel
                log(attach_lines(bus, scenario, name, listen, first=True))
            if external:
                names = "subsim" + ("s " if len(external) > 1 else " ") + ", ".join(map(repr, external))
                log(f"cosim: waiting up to {external_wait:g} s for external {names}")
            for name, spec in scenario.subsims.items():
                if not spec.external:
                    handles[name] = _started(session, name, lambda spec=spec, name=name: bus.spawn(
                        "", name, timeout=timeout, model=spec.model, lease=scenario.run.lease,
                        elsewhere=away.get(name)), lambda name=name: bus.respawn(name, timeout=timeout))
            waited_until = time.monotonic() + external_wait
            for name in external:  # one wait for all of them (a floor each: to attach one that is up already)
                wait = max(waited_until - time.monotonic(), min(ATTACH_FLOOR, external_wait))
                handles[name] = attach(bus, scenario, name, timeout, wait,  # said with the wait the user set
                                       f"{NOT_APPEARED} {external_wait:g} s (--attach-wait; none serves run "
                                       f"{bus.run!r} as {name!r}: check its --run and --name, and what its "
                                       "terminal says: a login or TLS this router refused is said there)")
        for name, spec in scenario.subsims.items():
            try:
                while True:
                    try:
                        session.descriptions[name] = handles[name].configure(spec.params, t0=scenario.start)
                        session.check_code(name, session.descriptions[name])
                        break
                    except SubsimError as exc:
                        if bus is None or spec.external or not _may_start_again(session, exc, name):
                            raise
                    respawn = partial(bus.respawn, name, timeout=timeout)
                    handles[name] = _started(session, name, respawn, respawn)  # (the session's own dict)
            except SubsimError as exc:
                if exc.code not in PARAMS_REFUSED or isinstance(exc, MalformedReply):  # not about its parameters
                    raise
                if spec.external:  # perhaps another model attached: then it is to blame, not the scenario
                    other_model(scenario, name, handles[name].describe().model, exc.message)
                trace = f"\nthe model's traceback:\n{exc.traceback.rstrip()}" if exc.traceback else ""
                # a ModelError: the model itself cannot run (an FMU that cannot save its state), whatever its params
                table = f"subsims.{name}" if exc.code == "model_error" else f"subsims.{name}.params"
                raise ScenarioError(f"{scenario.path}: [{table}] {exc.message}{trace}") from None
        session.plans = {method: build_plan(scenario, session.descriptions, method) for method in scenario.settings}
        signals = {f"{n}.{p}" for n, d in session.descriptions.items() for p in [*d.inputs, *d.outputs]}
        for name in scenario.settings_for().tolerances:
            if name not in signals:
                raise ScenarioError(f"{scenario.path}: [tolerances.{name!r}] no subsim has a signal {name!r} "
                                    "(tolerances name outputs, checked by centralized runs, or coupled inputs, "
                                    "checked by distributed runs)")
    except BaseException:
        session.close()
        raise
    return session


def unused_settings(settings: Settings, plan: Plan) -> list[str]:
    """A line for each setting that does nothing in this run: a [tolerances] signal its method never checks (one
    table serves both methods: a tolerance meant for the other was dropped without a word when the method was
    switched; a docs probe), speculate in a centralized run, max_halvings with interval = "auto" (a probe)."""
    lines = []
    if settings.speculate and settings.method == "centralized":
        lines.append("speculate does nothing in a centralized run (its subsims run side by side already)")
    if settings.max_halvings and settings.auto is not None:
        lines.append("max_halvings does nothing with interval = \"auto\", which shortens a try that fails itself")
    if settings.method == "centralized":
        checked = {f"{name}.{port}" for name, ports in plan.outputs.items() for port in ports}
        what = "outputs"
    else:
        checked = {str(c.target) for c in plan.feedback}
        what = f"the fed-back inputs: {', '.join(sorted(checked)) or 'none'}"
    return lines + [f"[tolerances.{name!r}] does not apply to this {settings.method} run, which checks {what}"
                    for name in settings.tolerances if name not in checked]


def _may_start_again(session: Session, exc: SubsimError, name: str) -> bool:
    """Whether subsim ``name``'s process, started on this machine, which ``exc`` says was killed by a signal (a
    crash, the OOM killer; not an exit of its own, which would come again) or did not come up while it ran (stopped,
    or hung as it started: a red team's SIGSTOP stopped the run with restarts left), is to be started again: it
    counts as one of the run's restarts (``session.restarts_left``)."""
    lost = "killed by SIG" in exc.message or (exc.message.startswith(NOT_UP) and STOPPED in exc.message)
    if (exc.code != "no_responder" or not lost or session.restarts_left <= 0
            or session.scenario.subsims[name].launcher):  # (over ssh a kill reads as an exit code)
        return False
    session.restarts_left -= 1
    session.started_again.append(Restart(name, math.nan, f"was lost while starting ({exc.message})", 0))
    more = f"{session.restarts_left} more restart{'s' if session.restarts_left != 1 else ''} in this run at most"
    session.log(f"cosim: {name} was lost while starting ({exc.message}); starting it again ({more})")
    return True


def _started(session: Session, name: str, start: Callable[[], SubsimProcess],
             again: Callable[[], SubsimProcess]) -> SubsimHandle:
    """The handle of ``start()``'s process; ``again()`` (a respawn: a new key, so that the killed one's, if it
    lingers, is deaf) while it is killed by a signal before it answers."""
    while True:
        try:
            return start().handle
        except SubsimError as exc:
            if not _may_start_again(session, exc, name):
                raise
            start = again


RESOLVED = 64  # a sample spacing must be at least this many units in the last place of the run's latest time


def check_resolution(scenario: Scenario, settings: Settings, method: str, stop: float) -> None:
    """ScenarioError unless the run's samples are spaced far enough apart for doubles to tell its times apart up to
    ``stop`` (far from t = 0 a double's resolution is coarse: 1.2e-4 s at 1e12 s)."""
    key = "interval_min" if settings.auto is not None else "interval"
    shortest = settings.auto.minimum if settings.auto is not None else settings.interval
    spacing = shortest / (settings.samples - 1)
    latest = max(abs(scenario.start), abs(stop))
    ulp = math.ulp(latest)
    if spacing < RESOLVED * ulp:
        raise ScenarioError(f"{scenario.path}: [coupling.{method}] {key} {shortest:g} s over {settings.samples} "
                            f"samples spaces them {spacing:.3g} s apart, too fine for the times of this run: near t = "
                            f"{latest:.6g} s a double resolves {ulp:.3g} s; keep the spacing above "
                            f"{RESOLVED * ulp:.3g} s, or count time from nearer 0 (start)")


PARAMS_REFUSED = frozenset({"bad_value", "model_error", "model_exception"})  # configure's refusals: the scenario's
ATTACH_FLOOR = 2.0  # s each external subsim is waited for at least, once the run's wait for them all is over
RETRY_ELSEWHERE = 5.0  # s between tries to start a lost subsim on another machine again
AWAY_FLOOR = 10.0  # s: the shortest automatic deadline when a subsim is on another machine (a Zenoh lease: a
# network blip shorter than that is waited out, not taken for a hang that costs a restart)


def other_model(scenario: Scenario, name: str, served: str, refusal: str, what: str = "refused its params") -> None:
    """ScenarioError when an external subsim that refused its parameters (or ``what`` else it refused) serves another
    class than its scenario's ``model`` names (by class name: a package may re-export a class under a shorter path,
    or another name; so this is said only of a subsim that refused): the operator started another model, which the
    refusal would blame on the scenario."""
    model = scenario.subsims[name].model
    if model and served.rpartition(".")[2] != model.rpartition(":")[2].rpartition(".")[2]:
        raise ScenarioError(f"{scenario.path}: [subsims.{name}] model = {model!r}, but the process that attached as "
                            f"{name!r} serves {served}, which {what} ({refusal}): start it with the command printed "
                            "for it")


def attach(bus: Bus, scenario: Scenario, name: str, timeout: float, wait: float, not_appeared: str) -> RemoteHandle:
    """A handle to external subsim ``name`` once it is up (within ``wait`` s, else ``not_appeared`` says so), with
    the lease its printed command gives it."""
    try:
        handle = bus.attach(name, timeout=timeout, wait=wait)
    except NotAppeared as exc:
        raise NotAppeared(exc.code, not_appeared, name, exc.command) from None
    handle.lease = scenario.run.lease
    return handle


def attach_lines(bus: Bus, scenario: Scenario, name: str, listen: str | None, first: bool) -> str:
    """What an external subsim's operator needs to start it: the machine-readable ``cosim-attach`` line (``first``:
    at the run's start only) and the command with its two secrets."""
    endpoint, hint = attach_endpoint(listen, bus.endpoint)
    lease = scenario.run.lease if scenario.run.lease != RunSpec.lease else None  # the process's own default
    mutual = bus.security.mutual  # its machine shows a certificate of its own: the router's key stays here
    cmd = bus.command(PLACEHOLDER_MODULE, name, scenario.subsims[name].model, endpoint=endpoint, python="python",
                      lease=lease, client=SITE_CERTIFICATE if mutual else None)
    env = bus.subsim_env(name)
    shown = " ".join(f"{k}={v}" for k, v in env.items())
    machine = "cosim-attach " + json.dumps({"endpoint": endpoint, "run": bus.run, "name": name, "command": cmd,
                                            "env": env}) + "\n" if first else ""
    site = (f"\n  (mutual TLS: {SITE_CERTIFICATE[0]} and {SITE_CERTIFICATE[1]} stand for a certificate and key of the "
            "subsim's machine, signed by the CA of --tls-ca; never copy the router's key there)") if mutual else ""
    if bus.security.tls_ca is not None:  # a path on this machine (a multi-host probe: it is not there elsewhere)
        site += (f"\n  (--tls-ca {bus.security.tls_ca} is this machine's copy of the CA certificate: from another "
                 "machine, copy it there and give its path there)")
    return (f"{machine}cosim: external subsim {name!r}: start it with:\n  {shown} {' '.join(cmd)}\n"
            "  (the two variables are this subsim's secrets: hand them over privately; they are new at every start, "
            f"--resume included)\n  ({hint}){site}")


PLACEHOLDER_MODULE = "YOUR_SUBSIM_MODULE"  # (placeholders a shell passes on as they are: no <, >, ' or spaces)
PLACEHOLDER_HOST = "THIS_MACHINE_ADDRESS"
SITE_CERTIFICATE = ("SITE_CERT.pem", "SITE_KEY.pem")


def host_addresses() -> list[str]:
    """This machine's IPv4 address on its route out, found without sending anything and without a name lookup
    (which can wait seconds for a DNS server); with no route out (a lab network), its interfaces' addresses."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.connect(("192.0.2.1", 9))  # (UDP: connecting picks the route and sends nothing)
            found = s.getsockname()[0]
    except OSError:  # no route out
        return interface_addresses()
    return [] if found.startswith("127.") or found == "0.0.0.0" else [found]


SIOCGIFFLAGS, IFF_UP = 0x8913, 0x1  # Linux's ioctl for an interface's flags, and the flag of one that is up
RTM_GETADDR, NLM_F_DUMP_REQUEST, NLMSG_DONE, NLMSG_ERROR, IFA_ADDRESS, IFA_LOCAL = 22, 0x301, 3, 2, 1, 2  # rtnetlink


def interface_addresses() -> list[str]:
    """The IPv4 addresses of this machine's interfaces that are up, but loopback: every one of an interface, not only
    its first (Linux, asked over rtnetlink; elsewhere none). A lab machine's second address was missed, and a down
    interface's address offered (a multi-host probe)."""
    if not sys.platform.startswith("linux"):
        return []
    import fcntl
    import struct

    try:
        with socket.socket(socket.AF_NETLINK, socket.SOCK_RAW, socket.NETLINK_ROUTE) as nl:
            nl.settimeout(2.0)
            nl.send(struct.pack("=IHHII", 24, RTM_GETADDR, NLM_F_DUMP_REQUEST, 1, 0)
                    + struct.pack("=BBBBI", socket.AF_INET, 0, 0, 0, 0))  # nlmsghdr + ifaddrmsg: every IPv4 one
            by_index: list[tuple[int, str]] = []
            done = False
            while not done:
                data, at = nl.recv(65536), 0
                while at + 16 <= len(data):
                    length, kind = struct.unpack_from("=IH", data, at)
                    if kind in (NLMSG_DONE, NLMSG_ERROR) or length < 16:
                        done = True
                        break
                    index = struct.unpack_from("=I", data, at + 20)[0]  # ifaddrmsg's interface index
                    attrs, address = at + 24, {}
                    while attrs + 4 <= at + length:
                        size, what = struct.unpack_from("=HH", data, attrs)
                        if size < 4:
                            break
                        if what in (IFA_ADDRESS, IFA_LOCAL) and size == 8:
                            address[what] = socket.inet_ntoa(data[attrs + 4:attrs + 8])
                        attrs += (size + 3) & ~3
                    if address:
                        by_index.append((index, address.get(IFA_LOCAL, address.get(IFA_ADDRESS, ""))))
                    at += (length + 3) & ~3
    except OSError:  # no rtnetlink here (a sandbox): nothing to offer
        return []
    found = []
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for index, address in by_index:
            try:
                name = socket.if_indextoname(index)
                flags = struct.unpack_from("=H", fcntl.ioctl(s.fileno(), SIOCGIFFLAGS,
                                                             struct.pack("256s", name[:15].encode())), 16)[0]
            except OSError:  # gone meanwhile
                continue
            if flags & IFF_UP and not address.startswith("127.") and address not in found:
                found.append(address)
    return found


def attach_endpoint(listen: str | None, endpoint: str) -> tuple[str, str]:
    """The endpoint an external subsim is told, and a hint on reaching it from another machine. A router listening
    on every address (0.0.0.0) is reached at one this machine cannot name for the other: a placeholder then."""
    proto = (listen or endpoint).partition("/")[0]
    try:
        host, port = split_endpoint(listen or endpoint)[0], split_endpoint(endpoint)[1]
    except ValueError:  # a Unix socket
        return endpoint, "from another machine: the same command, on a machine that reaches this address"
    if host in UNSPECIFIED_HOSTS:  # listening on every address: the one to give is the one the other reaches
        addresses = host_addresses()
        if proto in ("tls", "quic"):  # the subsim checks the router's certificate against the name it is given
            seen = f" (this machine's address: {addresses[0]})" if addresses else ""
            return (f"{proto}/{PLACEHOLDER_HOST}:{port}", f"replace {PLACEHOLDER_HOST} by the name or address the "
                    f"router's certificate (--tls-cert) is for, as the subsim's machine reaches it{seen}")
        if len(addresses) == 1:
            return (f"{proto}/{addresses[0]}:{port}", f"{addresses[0]} is this machine's address; if the subsim's "
                    "machine reaches it at another, give that")
        have = f"this machine has {', '.join(addresses)}" if addresses else "none found here"
        return (f"{proto}/{PLACEHOLDER_HOST}:{port}", f"replace {PLACEHOLDER_HOST} by an address of this machine the "
                f"subsim's machine reaches ({have})")
    if host in ("127.0.0.1", "localhost", "[::1]", "::1"):
        return endpoint, (f"from another machine: run cosim with --listen {proto}/<an address of this machine>:<port> "
                          "(or 0.0.0.0 for every address) and give the subsim that address")
    return endpoint, "from another machine: the same command, on a machine that reaches this address"


def elsewhere(spec: SubsimSpec) -> Elsewhere | None:
    """How ``spec``'s subsim is started on another machine, or None (here)."""
    if not spec.launcher:
        return None
    return Elsewhere(spec.launcher, spec.workdir, spec.python, spec.connect)


def _resume_point(scenario: Scenario, method: str, key: str, output: Path, stop: float) -> Saved:
    """The resume point beside ``output``, if it is one of this scenario (``key``: its fingerprint) and method."""
    saved = load_resume(resume_path(output))
    if saved.fingerprint != key or saved.t_start != scenario.start:
        changed = [] if saved.scenario is None else changes(saved.scenario, fingerprinted(scenario.raw, method))
        shown = "; ".join(changed[:3]) + ("; ..." if len(changed) > 3 else "")
        raise OutputError(f"{resume_path(output)} is a resume point of another scenario or method than "
                          f"{scenario.path} with method {method} (they must be the same but for stop"
                          + (f"; changed: {shown}" if shown else "") + "): run it from the start (--overwrite; "
                          "cosim.run without resume)")
    if saved.point.t >= stop:
        raise OutputError(f"{output}: the run it continues got to t = {saved.point.t:g}, at or past stop = {stop:g}: "
                          "nothing to resume")
    return saved


def _restore(session: Session, saved: Saved, where: Path) -> None:
    """Every subsim (configured at the start) to its committed state at the resume point."""
    if set(saved.states) != set(session.handles):
        raise OutputError(f"{where} holds the subsims {sorted(saved.states)}, this run has {sorted(session.handles)}")
    for name, state in saved.states.items():
        model = session.descriptions[name].model
        if state.model != model:
            raise OutputError(f"{where}: {name} was a {state.model}, now it is a {model}: run it from the start "
                              "with --overwrite")
        session.handles[name].set_state(state)


def build_plan(scenario: Scenario, descriptions: dict[str, Description], method: str) -> Plan:
    """The couplings checked against the described ports, once; errors name the scenario key."""
    try:
        plan = plan_for(descriptions, scenario.couplings, scenario.settings_for(method))
    except CouplingError as exc:
        coupling = scenario.couplings[exc.index] if 0 <= exc.index < len(scenario.couplings) else None
        ends = [] if coupling is None else [coupling.target.subsim, *(s.subsim for s in coupling.sources)]
        for name in dict.fromkeys(ends):  # another model attached: its ports are not the scenario's fault
            if name in descriptions and scenario.subsims.get(name) is not None and scenario.subsims[name].external:
                other_model(scenario, name, descriptions[name].model, f"[couplings[{exc.index}]] {exc}",
                            "does not fit the couplings")
        raise ScenarioError(f"{scenario.path}: [couplings[{exc.index}]] {exc}") from None
    return replace(plan, held=MappingProxyType(held_inputs(scenario, descriptions)),
                   guess=MappingProxyType(guessed_inputs(scenario, descriptions)))


def held_inputs(scenario: Scenario, descriptions: dict[str, Description]) -> dict[str, tuple[float, ...]]:
    """Every input is fed, by a coupling or by a constant of [subsims.<name>.inputs]; the constants."""
    coupled, held = {str(c.target) for c in scenario.couplings}, {}
    for name, d in descriptions.items():
        given = scenario.subsims[name].inputs
        for port, p in d.inputs.items():
            if f"{name}.{port}" not in coupled and port not in given:
                raise ScenarioError(f"{scenario.path}: [subsims.{name}.inputs] input {name}.{port} ({p.size} x "
                                    f"{p.unit or 'unitless'}) is fed by no coupling: couple it ([[couplings]] to = "
                                    f"\"{name}.{port}\") or hold it constant ({port} = {[0.0] * p.size})")
        held.update(_input_values(scenario, name, d, "inputs", coupled))
    return held


def _input_values(scenario: Scenario, name: str, d: Description, table: str, coupled: set[str]
                  ) -> dict[str, tuple[float, ...]]:
    """The values of [subsims.<name>.<table>] by "subsim.port", each checked against the described inputs:
    ``inputs`` holds those no coupling feeds, ``guess`` gives those a coupling feeds a start."""
    found = {}
    for port, values in getattr(scenario.subsims[name], table).items():
        p, ref = d.inputs.get(port), f"{name}.{port}"
        if p is None:
            why = "is no input"
        elif table == "inputs" and ref in coupled:
            why = "is fed by a coupling"
        elif table == "guess" and ref not in coupled:
            why = f"is fed by no coupling (a constant goes in [subsims.{name}.inputs])"
        elif len(values) != p.size:
            why = f"takes {p.size} value{'s' if p.size != 1 else ''}, got {len(values)}"
        else:
            found[ref] = values
            continue
        raise ScenarioError(f"{scenario.path}: [subsims.{name}.{table}.{port}] {ref} {why} "
                            f"(inputs: {', '.join(d.inputs) or 'none'})")
    return found


def guessed_inputs(scenario: Scenario, descriptions: dict[str, Description]) -> dict[str, tuple[float, ...]]:
    """The values of [subsims.<name>.guess]: each names a coupled input, with one value per channel."""
    coupled, guessed = {str(c.target) for c in scenario.couplings}, {}
    for name, d in descriptions.items():
        guessed.update(_input_values(scenario, name, d, "guess", coupled))
    return guessed


def output_signals(scenario: Scenario, descriptions: dict[str, Description]) -> list[tuple[SignalRef, int]]:
    if scenario.output_signals is None:
        return [(SignalRef(n, p), port.size) for n, d in descriptions.items() for p, port in d.outputs.items()]
    out = []
    for i, text in enumerate(scenario.output_signals):
        try:
            ref = SignalRef.parse(text)
            out.append((ref, descriptions[ref.subsim].outputs[ref.port].size))
        except (ValueError, KeyError):
            msg = f"{scenario.path}: [output.signals[{i}]] {text!r} is not an output of any subsim"
            raise ScenarioError(msg) from None
    return out


def default_listen(scenario: Scenario, security: Security | None) -> str:
    """Where the router listens when the user does not say: over TLS on loopback with a certificate; on loopback
    TCP when a subsim is external (it may be on another machine: --listen tcp/0.0.0.0:<port> then); else on a
    Unix socket only this user can reach (another user's flood of connections could stop a run on TCP)."""
    if security is not None and security.tls:
        return "tls/localhost:0"
    if any(spec.external for spec in scenario.subsims.values()):
        return "tcp/127.0.0.1:0"
    return PRIVATE


def default_output(scenario: Scenario, method: str) -> Path:
    """``[output] path``, else results/<name>-<method>.csv: ScenarioError when the name would make that a path
    (name = '../../x' wrote results/../../x-distributed.csv, outside results/)."""
    if scenario.output_path is not None:
        return scenario.output_path
    name = scenario.name
    if not name.strip() or name in (".", "..") or any(c in name for c in "/\\\0"):
        raise ScenarioError(f"{scenario.path}: [name] {name!r} names the default results file results/<name>-"
                            f"<method>.csv: a name without '/' or '\\', or a file of its own ([output] path or "
                            "--output)")
    return Path.cwd() / "results" / f"{name}-{method}.csv"


def run_scenario(
    scenario: Scenario,
    method: str | None = None,
    stop: float | None = None,
    output: Path | None = None,
    inprocess: bool = False,
    listen: str | None = None,
    progress: bool = True,
    log: Log = say,
    on_interval: Callable[[Interval], None] | None = None,
    overwrite: bool = True,
    restarts: int | None = None,
    timeout: float | None = None,
    security: Security | None = None,
    run_id: str | None = None,
    attach_wait: float = 300.0,
    resume: bool = False,
    record: bool = True,
) -> RunReport:
    """Run ``scenario``. ``overwrite=False`` refuses an existing result (OutputError) before anything is
    launched; ``restarts`` and ``timeout`` override its [run] table (see ``cosim.scenario.KEYS``). ``resume``:
    go on with the interrupted run that wrote ``output``, from its latest resume point (:mod:`cosim.resume`).
    ``record=False``: no result file and no resume point; the intervals reach ``on_interval`` only. ``progress``:
    the progress display, and the subsims started say "serving run ... (pid N)"."""
    if resume and not record:
        raise ValueError("resume goes on with a run's result file: it needs record=True")
    method = method or scenario.default_method
    settings = scenario.settings_for(method)
    stop = scenario.stop if stop is None else stop
    check_resolution(scenario, settings, method, stop)
    if settings.auto is None and stop - scenario.start < settings.interval:  # (a newcomer's interval = 500, stop = 100)
        log(f"cosim: [coupling] interval = {settings.interval:g} s is longer than the run ({scenario.start:g} to "
            f"{stop:g} s): it runs one whole interval, to t = {scenario.start + settings.interval:g}")
    output = Path(output) if output is not None else default_output(scenario, method)
    lock = reserve_output(output, overwrite or resume) if record else None  # locked before anything is launched
    key = fingerprint(scenario.raw, method)  # what a resume point of this run is saved under
    tables = fingerprinted(scenario.raw, method)
    models = model_files({name: spec.params for name, spec in scenario.subsims.items()}) if record else {}
    try:
        saved = _resume_point(scenario, method, key, output, stop) if resume else None
        session = open_session(scenario, inprocess=inprocess, listen=listen, log=log, security=security,
                               run_id=run_id, external_wait=attach_wait, announce=progress,
                               restarts=scenario.run.restarts if restarts is None else restarts)
    except BaseException:
        if lock is not None:
            lock.release()
        raise
    try:
        if saved is not None:
            _restore(session, saved, resume_path(output))
            if saved.written is None:
                log(f"cosim: the resume point at t = {saved.point.t:g} was saved by an earlier cosim, without the "
                    f"sizes and hashes of {output} and its diagnostics: edits to them since are not found")
            for path, digest in (saved.models or {}).items():
                if models.get(path) != digest:
                    log(f"cosim: {path} is not the file the run had when its resume point at t = {saved.point.t:g} "
                        "was saved: the results before that point came from the earlier one")
            now = {name: d.code for name, d in session.descriptions.items()}
            for name, modules in changed_code(saved.code or {}, now).items():
                shown = ", ".join(modules[:4]) + (f" and {len(modules) - 4} more" if len(modules) > 4 else "")
                log(f"cosim: {name}'s code is not what the run had when its resume point at t = {saved.point.t:g} "
                    f"was saved ({shown} changed since): the results before that point came from the earlier code")
        for line in unused_settings(settings, session.plans[method]):
            log(f"cosim: {line}")
        spec = scenario.run
        restarts = session.restarts_left  # (those a subsim lost while it started used are gone)
        recovery = None
        if restarts and not inprocess:
            recovery = Recovery(session.revive, restarts, spec.checkpoint_every, log)
        away = any(sub.external or sub.launcher for sub in scenario.subsims.values())
        deadline = Deadline(fixed=timeout if timeout is not None else spec.timeout,
                            floor=AWAY_FLOOR if away else Deadline.floor)
        checkpoints: list[Saved] = []  # taken, their intervals not yet written
        coordinator = Coordinator(session.handles, session.plans[method], settings, recovery=recovery,
                                  deadline=deadline, checkpoint_every=spec.checkpoint_every,
                                  on_checkpoint=None if lock is None else lambda point, states: checkpoints.append(
                                      Saved(key, scenario.start, point, states, scenario=tables, code={
                                          name: d.code for name, d in session.descriptions.items()})))
        writer: ResultWriter | Unrecorded = Unrecorded() if lock is None else ResultWriter(
            output, output_signals(scenario, session.descriptions), output_units(session.descriptions), lock=lock,
            resume_at=None if saved is None else saved.point.t, written=None if saved is None else saved.written)
        bar = Progress(scenario.start if saved is None else saved.point.t, stop, enabled=progress)

        unsaved: list[float] = []  # the times of resume points that could not be saved

        def save_points() -> None:
            """Save the resume points taken whose intervals are all in the files now."""
            with interrupt.deferred():  # a signal while a resume point is saved: raised once it is (it was lost)
                while checkpoints and writer.t_last is not None and checkpoints[0].point.t <= writer.t_last:
                    writer.sync()  # (a point saved, fsynced, before the rows it names are on disk: a power cut
                    point = checkpoints.pop(0)  # would leave a point whose files the resume refuses)
                    try:
                        save_resume(resume_path(output), replace(point, written=writer.written(point.point.t),
                                                                 models=models))
                    except OutputWriteError as exc:  # the results still go on: only a later --resume loses
                        if not unsaved:  # (a read-only directory stopped the run, results writable: a red team)
                            why = str(exc).removesuffix(", then run again")  # (this run goes on)
                            log(f"cosim: the resume point at t = {point.point.t:g} could not be saved ({why}); "
                                "the run goes on, and an interrupted run goes on (--resume) from the last point "
                                "saved, if any")
                        unsaved.append(point.point.t)

        def each(interval: Interval) -> Iterator[None]:  # in steps: the coordinator writes while it waits
            try:
                yield from writer.write_steps(interval)
                if checkpoints:  # (one every checkpoint_every intervals: most have none to save)
                    save_points()
            except interrupt.Interrupted:  # a signal held back while the interval was written: it is in the files
                if on_interval is not None and writer.holds(interval):
                    on_interval(interval)
                raise
            bar.update(interval)
            if on_interval is not None:
                on_interval(interval)

        try:
            summary = coordinator.run(scenario.start, stop, each, resume=None if saved is None else saved.point)
        except BaseException:
            writer.close(failed_run=True)
            bar.done()
            raise
        interrupt.finished()  # a stop asked for now would only cut the cleanup of a finished run short
        writer.close()
        bar.done()
        restarted = {"restarts": [*session.started_again, *coordinator.restarts]}
        if lock is None:
            return RunReport(method, summary, None, None, coordinator.order, [str(c) for c in coordinator.feedback],
                             restarted)
        try:
            resume_path(output).unlink(missing_ok=True)  # finished: nothing to resume
        except OSError as exc:  # (a directory made read-only since its last point: the run's results are whole)
            log(f"cosim: {resume_path(output)} could not be removed ({exc.strerror}): the run is finished, delete it")
        return RunReport(method, summary, output, diag_path(output), coordinator.order,
                         [str(c) for c in coordinator.feedback], restarted)
    finally:
        with interrupt.deferred():  # a signal arriving now must not cut the subsims' stop short
            session.close()
        if lock is not None:
            lock.release()  # if the writer never took it
