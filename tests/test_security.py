"""Nobody outside the run can reach it (docs/reliability.md, "Security model"), with real processes on loopback.

* a client without the run's login (or with another run's) cannot even connect to the router;
* a logged-in client without the subsim's key gets no answer, finds no key by wildcard scans, and
  cannot intercept the coordinator's requests; a recorded request replayed gets no answer;
* an attacker process hammering ``cosim/**`` with ``shutdown`` and ``run_interval`` during a run
  leaves the oscillator's result file byte-identical to an undisturbed run's.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import zenoh

from cosim.contract import SubsimError
from cosim.launch import Bus
from cosim.protocol.keys import alive_key, new_run_id, rpc_key
from cosim.protocol.messages import decode_reply, encode_request, next_seq, open_reply, seal_request
from cosim.protocol.security import ClientSecurity, Security, zenoh_login
from cosim.protocol.transport.session import client_config
from cosim.runner import run_scenario
from cosim.scenario import load

pytestmark = [pytest.mark.slow]  # the inner loop: pytest -m "not slow"

ROOT = Path(__file__).parents[1]
OSCILLATOR = ROOT / "scenarios" / "oscillator.toml"


def open_client(bus: Bus, login: tuple[str, str] | None) -> zenoh.Session:
    return zenoh.open(client_config(bus.endpoint, 2.0, security=ClientSecurity(bytes(32), login)))


@pytest.fixture
def served(cosim_bus: Bus) -> Iterator[Bus]:
    proc = cosim_bus.spawn("subsims.integrator", "victim")
    proc.handle.configure({})
    proc.handle.run_interval(np.array([0.0, 0.5]), {"u": np.ones((2, 1))})
    proc.handle.commit()
    yield cosim_bus


def test_run_ids_are_unguessable() -> None:
    ids = {new_run_id() for _ in range(1000)}
    assert len(ids) == 1000
    assert all(len(i) == len("run-") + 32 and int(i[4:], 16) >= 0 for i in ids)  # 128 random bits


@pytest.mark.parametrize("login", ["none", "wrong password", "another run's"])
def test_client_without_the_runs_login_cannot_connect(cosim_bus: Bus, login: str) -> None:
    user, password = zenoh_login(cosim_bus.secret, cosim_bus.run)
    other = Bus.open()
    try:
        credentials = {"none": None, "wrong password": (user, password[::-1]),
                       "another run's": zenoh_login(other.secret, other.run)}[login]
        with pytest.raises(zenoh.ZError, match="Unable to connect"):
            open_client(cosim_bus, credentials).close()
    finally:
        other.close()


def test_logged_in_client_without_the_key_gets_nothing(served: Bus) -> None:
    """Even with the run's own login (a leaked dictionary), no key means no answer, no scan, no interception."""
    before = served.attach("victim").get_state()
    session = open_client(served, zenoh_login(served.secret, served.run))
    spy = open_client(served, zenoh_login(served.secret, served.run))  # its own session: not hit by our gets
    try:
        intercepted: list[str] = []
        trap = spy.declare_queryable("cosim/**", lambda q: intercepted.append(str(q.key_expr)))
        run = served.run
        replies, found = 0, 0
        for key in ("cosim/**", f"cosim/{run}/**", rpc_key(run, "victim"), f"cosim/{run}/*/rpc"):
            for body in (encode_request("shutdown"), seal_request(bytes(32), next_seq(), encode_request("shutdown"))):
                replies += sum(r.ok is not None for r in session.get(key, payload=body, timeout=1.0))
            found += sum(r.ok is not None for r in session.liveliness().get(key, timeout=1.0))
        own = f"@/{session.zid()}/"
        admin = [str(r.ok.key_expr) for r in session.get("@/**", timeout=1.0)
                 if r.ok is not None and not str(r.ok.key_expr).startswith(own)]
        handle = served.attach("victim")  # the coordinator's requests still reach the subsim, and only it
        assert handle.status()["name"] == "victim"
        trap.undeclare()
    finally:
        session.close()
        spy.close()
    assert (replies, found, admin, intercepted) == (0, 0, [], [])
    assert handle.get_state().time == before.time and np.array_equal(handle.get_state().state, before.state)


def test_a_subsims_own_login_cannot_read_serve_or_cover_for_another_subsim() -> None:
    """With its subsims named up front (as ``cosim run`` does) a bus gives each its own login, which may serve only
    that subsim's keys. Holding ``other``'s login, a client sees none of ``victim``'s requests through a wildcard or
    an exact queryable (with one shared login the wildcard one received all of them), and its token on victim's
    liveliness key does not hide victim's death (it did: Zenoh reports a key gone only when its last token goes)."""
    with pytest.raises(ValueError, match="name at least one subsim"):  # no login at all: a router open to anyone
        Bus.open(names=[])
    with Bus.open(names=["victim", "other"]) as bus:
        with pytest.raises(ValueError, match="'stranger' is not one of this run's subsims"):
            bus.subsim_env("stranger")
        proc = bus.spawn("subsims.integrator", "victim")
        spy = open_client(bus, zenoh_login(bus.secret, bus.run, "other"))
        seen: list[str] = []
        try:
            for key in (f"cosim/{bus.run}/*/rpc", rpc_key(bus.run, "victim"), "cosim/**"):
                spy.declare_queryable(key, lambda query: seen.append(str(query.key_expr)))
            spy.liveliness().declare_token(alive_key(bus.run, "victim"))
            time.sleep(0.5)  # declarations propagate
            for _ in range(10):
                assert proc.handle.status()["name"] == "victim"
            proc.popen.kill()
            proc.popen.wait()
            deadline = time.monotonic() + 5.0
            while proc.handle.alive and time.monotonic() < deadline:
                time.sleep(0.02)
            alive = proc.handle.alive
        finally:
            spy.close()
    assert seen == [] and not alive


def test_a_site_login_serves_only_the_subsims_started_by_hand(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An ``--auth-file`` line is a site's login for the subsims it starts by hand. It may serve (and so read the
    requests of) every subsim of the run: a red-team probe read orbit's, attitude's and aero's inputs with one.
    ``cosim run`` now lets it serve only the external ones; here it sees none of a launched subsim's requests."""
    users = tmp_path / "users"
    users.write_text("site1:site-password\n")
    with Bus.open(names=["launched", "remote"], security=Security(auth_file=users), site_serves=["remote"]) as bus:
        proc = bus.spawn("subsims.integrator", "launched")
        spy = open_client(bus, ("site1", "site-password"))
        seen: list[str] = []
        try:
            for key in (rpc_key(bus.run, "launched"), f"cosim/{bus.run}/*/rpc", "cosim/**"):
                spy.declare_queryable(key, lambda query: seen.append(str(query.key_expr)))
            time.sleep(0.5)  # declarations propagate
            for _ in range(10):
                assert proc.handle.status()["name"] == "launched"
        finally:
            spy.close()
    assert seen == []
    opened: list = []  # and cosim run gives a site login the external subsims only: here none
    real_open = Bus.open

    def recording(*args: object, **kwargs: object) -> Bus:
        opened.append(kwargs.get("site_serves"))
        return real_open(*args, **kwargs)

    monkeypatch.setattr(Bus, "open", recording)
    run_scenario(load(OSCILLATOR), stop=0.05, output=tmp_path / "x.csv", progress=False, log=lambda m: None)
    assert opened == [[]]


def test_a_replayed_request_gets_no_answer(served: Bus) -> None:
    key = served.key("victim")
    seq = next_seq()
    frame = seal_request(key, seq, encode_request("status"))

    def send() -> list[bytes]:
        replies = served.session.get(rpc_key(served.run, "victim"), payload=frame, timeout=5.0)
        return [r.ok.payload.to_bytes() for r in replies if r.ok is not None]

    first = send()
    assert len(first) == 1
    body = open_reply(key, seq, first[0])
    assert body is not None and decode_reply("status", body)["name"] == "victim"
    assert send() == []  # the same frame again: refused as a replay
    assert served.attach("victim").status()["name"] == "victim"  # the subsim serves on


def test_a_request_with_another_subsims_key_gets_no_answer(served: Bus) -> None:
    frame = seal_request(served.key("someone-else"), next_seq(), encode_request("shutdown"))
    replies = list(served.session.get(rpc_key(served.run, "victim"), payload=frame, timeout=5.0))
    assert replies == []
    assert served.attach("victim").status()["name"] == "victim"


def _oscillator(out: Path, monkeypatch: pytest.MonkeyPatch | None = None, tmp: Path | None = None) -> dict:
    """Run the oscillator over Zenoh; with ``monkeypatch``, an attacker process hammers the run meanwhile."""
    attack: dict = {}
    if monkeypatch is not None:
        real_open = Bus.open

        def open_under_attack(*args: object, **kwargs: object) -> Bus:
            bus = real_open(*args, **kwargs)
            user, password = zenoh_login(bus.secret, bus.run, "mass1")  # the strongest outsider: a subsim's login
            for who, login in (("logged-in", f"{user}:{password}"), ("anonymous", None)):
                cmd = [sys.executable, str(ROOT / "tests" / "attacker.py"), bus.endpoint, bus.run]
                popen = subprocess.Popen([*cmd, login] if login else cmd, stdout=subprocess.PIPE, text=True,
                                         env={**os.environ, "PYTHONPATH": str(ROOT)})
                attack[who] = popen
                assert popen.stdout is not None and popen.stdout.readline().strip() == "ready"
            return bus

        monkeypatch.setattr(Bus, "open", open_under_attack)
    try:
        run_scenario(load(OSCILLATOR), method="distributed", stop=1.0, output=out, progress=False, log=lambda m: None)
    finally:
        for popen in attack.values():
            popen.terminate()
        counts = {who: popen.communicate(timeout=30)[0] for who, popen in attack.items()}
        for popen in attack.values():
            if popen.poll() is None:
                popen.kill()
                popen.wait()
    return {who: json.loads(text.strip().splitlines()[-1]) for who, text in counts.items()}


def test_attacks_during_a_run_leave_its_results_identical(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _oscillator(tmp_path / "calm.csv")
    attacks = _oscillator(tmp_path / "attacked.csv", monkeypatch)
    print(attacks)
    assert attacks["anonymous"]["connected"] is False
    hit = attacks["logged-in"]
    assert hit["connected"] and hit["sent"] > 0 and hit["rounds"] >= 1
    assert (hit["replies"], hit["found"], hit["intercepted"]) == (0, 0, 0)
    assert (tmp_path / "attacked.csv").read_bytes() == (tmp_path / "calm.csv").read_bytes()


def test_a_wildcard_query_is_ignored_even_when_sealed_with_the_right_key(served: Bus) -> None:
    """The subsim answers only queries on exactly its rpc key (the coordinator's own session is not filtered
    by access control, so this reaches the subsim)."""
    frame = seal_request(served.key("victim"), next_seq(), encode_request("shutdown"))
    for key in ("cosim/**", f"cosim/{served.run}/**", f"cosim/{served.run}/*/rpc"):
        assert list(served.session.get(key, payload=frame, timeout=5.0)) == []
    assert served.attach("victim").status()["name"] == "victim"


def test_the_gate_accepts_each_sequence_number_once_within_the_window() -> None:
    from cosim.protocol.service import REPLAY_WINDOW, Gate
    from cosim.runtime import Runtime
    from subsims.integrator.subsim import Integrator

    key = bytes(range(32))
    gate = Gate(Runtime(Integrator), key)

    def answered(seq: int) -> bool:
        admitted, _ = gate.admit(seal_request(key, seq, encode_request("status")))
        return admitted is not None and gate.answer(admitted) is not None

    base = 10**15
    assert answered(base + 10) and answered(base + 12)
    assert answered(base + 11)  # out of order, within the window: once
    assert not answered(base + 11) and not answered(base + 12) and not answered(base + 10)  # replays
    assert not answered(base + 12 - REPLAY_WINDOW)  # too far below the highest accepted
    assert gate.admit(seal_request(bytes(32), base + 99, encode_request("status"))) == (None, None)  # wrong key
    assert gate.counts["replayed"] == 4 and gate.counts["dropped"] == 1


def test_a_replay_is_dropped_before_its_size_is_looked_at() -> None:
    """A replayed frame gets nothing, not even the ``too_large`` (or ``busy``) reply a fresh one would get:
    the replay check comes first, where the frame is received."""
    from cosim.protocol.service import Gate
    from cosim.runtime import Runtime
    from subsims.integrator.subsim import Integrator

    key = bytes(range(32))
    gate = Gate(Runtime(Integrator), key, max_request=64)
    frame = seal_request(key, 10**15, encode_request("status") + b"\0" * 100)  # over the cap of 64
    admitted, reply = gate.admit(frame)
    assert admitted is None and reply is not None and b"too_large" in reply
    assert gate.admit(frame) == (None, None)
    small = seal_request(key, 10**15 + 1, encode_request("status"))
    admitted, reply = gate.admit(small)
    assert admitted is not None and reply is None
    assert gate.admit(small) == (None, None)  # queued once; a replay never reaches the queue
    assert gate.counts["replayed"] == 2 and gate.counts["too_large"] == 1 and gate.counts["admitted"] == 1


@pytest.mark.parametrize("impostor", ["answers with an error", "swallows every query"])
def test_a_login_holder_on_a_subsims_key_cannot_stop_or_starve_the_run(served: Bus, impostor: str) -> None:
    """A client with the run's login (every subsim has it) declares a queryable on another subsim's key. Zenoh's error
    replies are not the subsim's: they are skipped like forged ones (one stopped a run as a 'timeout'); and queries go
    to every queryable on the key, so one declared complete that never answers cannot take them all (it black-holed
    the subsim until its restarts ran out)."""
    handle = served.attach("victim")
    handle.deadline = 2.0
    attacker = open_client(served, zenoh_login(served.secret, served.run))
    held: list = []

    def answer_with_an_error(query: zenoh.Query) -> None:
        with query:
            query.reply_err(b"attacker")

    def swallow(query: zenoh.Query) -> None:
        held.append(query)  # kept, never answered (the query would stay open until zenoh's timeout)

    try:
        if impostor == "answers with an error":
            trap = attacker.declare_queryable(rpc_key(served.run, "victim"), answer_with_an_error)
        else:
            trap = attacker.declare_queryable(rpc_key(served.run, "victim"), swallow, complete=True)
        t = np.array([0.5, 1.0])
        for _ in range(5):
            assert handle.status()["name"] == "victim"
            result = handle.run_interval(t, {"u": np.ones((2, 1))})
            assert result.end_time == 1.0
        trap.undeclare()
    finally:
        held.clear()
        attacker.close()


def test_a_private_bus_listens_where_only_this_user_can_connect() -> None:
    """Bus.open(PRIVATE): a Unix socket in a fresh 0700 directory (another user's processes cannot connect at all:
    on TCP, a flood of their connections stopped a run); the directory goes with the bus."""
    from cosim.launch import PRIVATE

    with Bus.open(PRIVATE) as bus:
        directory = Path(bus.private_dir)
        assert bus.endpoint == f"unixsock-stream/{directory}/router.sock"
        assert directory.stat().st_mode & 0o777 == 0o700 and (directory / "router.sock").is_socket()
        proc = bus.spawn("subsims.integrator", "a", quiet=True)
        proc.handle.configure({})
        assert proc.handle.run_interval(np.array([0.0, 0.5]), {"u": np.ones((2, 1))}).end_time == 0.5
    assert not directory.exists()


@pytest.mark.parametrize(("external", "endpoint"), [(False, "unixsock-stream//"), (True, "tcp/127.0.0.1:")])
def test_cosim_run_listens_privately_unless_a_subsim_may_come_from_elsewhere(
    tmp_path: Path, external: bool, endpoint: str
) -> None:
    from cosim.runner import default_listen

    text = OSCILLATOR.read_text()
    if external:
        text = text.replace("[subsims.mass2]\n", "[subsims.mass2]\nexternal = true\n", 1)
    (tmp_path / "s.toml").write_text(text)
    listen = default_listen(load(tmp_path / "s.toml"), None)
    assert listen == ("tcp/127.0.0.1:0" if external else "private")
    if not external:  # a whole run: its subsims say where they connected
        done = subprocess.run([sys.executable, "-m", "cosim.cli", "run", str(tmp_path / "s.toml"), "--stop", "0.1",
                               "--output", str(tmp_path / "x.csv")], capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr
        assert f"via {endpoint}" in done.stderr and "/router.sock" in done.stderr


def test_a_killed_coordinators_private_directory_is_swept_by_the_next_one(tmp_path: Path) -> None:
    """SIGKILL leaves a private bus's directory behind; the next Bus.open(PRIVATE) removes those whose router lock
    is free or gone (no router listens there) and leaves a live router's alone."""
    import tempfile
    import time

    from cosim.launch import PRIVATE, PRIVATE_PREFIX

    stale = Path(tempfile.mkdtemp(prefix=PRIVATE_PREFIX))
    (stale / "router.sock.lock").touch()
    empty = Path(tempfile.mkdtemp(prefix=PRIVATE_PREFIX))  # its router closed, then the coordinator died
    old = time.time() - 3600
    os.utime(stale, (old, old))
    os.utime(empty, (old, old))
    with Bus.open(PRIVATE) as live:
        live_dir = Path(live.private_dir)
        os.utime(live_dir, (old, old))  # old enough to be swept, were its lock free
        with Bus.open(PRIVATE) as other:
            assert live_dir.exists() and Path(other.private_dir).exists()
        assert not stale.exists() and not empty.exists()


def test_idle_connections_without_a_login_do_not_keep_a_subsim_out() -> None:
    """300 TCP connections to the router that never send a byte (no login needed to open one). With Zenoh's defaults
    (100 handshakes pending at a time, 10 s each) the subsim's own connection waited behind them past its 10 s connect
    timeout and the run could not start; now they all wait as pending handshakes and the subsim gets in."""
    with Bus.open() as bus:
        host, port = bus.endpoint.removeprefix("tcp/").rsplit(":", 1)
        idle = []
        try:
            for _ in range(300):
                sock = socket.create_connection((host, int(port)), timeout=5.0)
                idle.append(sock)
            handle = bus.spawn("subsims.integrator", "squeezed", wait=20.0).handle
            assert handle.status()["name"] == "squeezed"
        finally:
            for sock in idle:
                sock.close()


def test_the_router_keeps_half_of_its_descriptors_from_pending_handshakes(monkeypatch: pytest.MonkeyPatch) -> None:
    """The pending-handshake bound follows the descriptors the process may open (its soft limit raised towards the hard
    one first), so that a flood cannot leave the run without descriptors for its files and processes."""
    import resource

    from cosim.protocol.transport import session

    limits = {"now": (1024, 1024)}
    monkeypatch.setattr(resource, "getrlimit", lambda which: limits["now"])
    monkeypatch.setattr(resource, "setrlimit", lambda which, value: limits.__setitem__("now", value))
    assert session.accept_pending() == 512  # the hard limit is 1024: nothing to raise
    limits["now"] = (1024, 1_048_576)
    assert session.accept_pending() == 10_000 and limits["now"] == (20_000, 1_048_576)
    limits["now"] = (150, 150)
    assert session.accept_pending() == 100  # never below Zenoh's default


def test_a_router_too_busy_to_close_in_time_does_not_fail_a_finished_run() -> None:
    """Under a connection flood Zenoh's close can time out ("close operation timed out!") after the run has
    finished and written everything: that turned a complete run into exit code 1. Closing now goes on."""
    from cosim.launch import PRIVATE

    bus = Bus.open(PRIVATE)
    real = bus.session

    class SlowToClose:
        def __getattr__(self, name: str) -> object:
            return getattr(real, name)

        def close(self) -> None:
            real.close()
            raise zenoh.ZError("close operation timed out!")

    bus.session = SlowToClose()  # type: ignore[assignment]
    bus.close()
    assert bus.private_dir is not None and not Path(bus.private_dir).exists()


def test_a_subsim_process_that_cannot_be_started_is_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    import cosim.launch

    def out_of_descriptors(*args: object, **kwargs: object) -> None:
        raise OSError(24, "Too many open files")

    with Bus.open() as bus:
        monkeypatch.setattr(cosim.launch.subprocess, "Popen", out_of_descriptors)
        with pytest.raises(SubsimError, match=r"^never\.spawn: \[no_responder\] cannot start its process: "
                                              r"\[Errno 24\] Too many open files$"):
            bus.spawn("subsims.integrator", "never")
        assert bus.processes == []


def test_a_subsim_whose_replies_carry_no_valid_tag_is_named_unauthenticated(cosim_bus: Bus) -> None:
    """Something serves the name (its token is there) and answers every request, but with a tag for another seq (a
    subsim in another language that seals its replies wrongly): the wait says 'unauthenticated', not that nothing
    answers."""
    from cosim.protocol.messages import seal_reply

    key = cosim_bus.key("mis")
    impostor = open_client(cosim_bus, zenoh_login(cosim_bus.secret, cosim_bus.run))

    def answer(query: zenoh.Query) -> None:
        with query:
            query.reply(query.key_expr, seal_reply(key, 1, b"\x83\xa1v\x01\xa2ok\xc3\xa6result\x80"))  # seq 1: wrong

    try:
        queryable = impostor.declare_queryable(rpc_key(cosim_bus.run, "mis"), answer)
        token = impostor.liveliness().declare_token(alive_key(cosim_bus.run, "mis"))
        with pytest.raises(SubsimError, match=r"mis.connect: \[unauthenticated\] it answers, but none of its \d+ "
                                              r"replies in \d+ s carried a valid tag"):
            cosim_bus.attach("mis", wait=5.0)
        token.undeclare()
        queryable.undeclare()
    finally:
        impostor.close()
