"""Two hosts for real: two network namespaces joined by a veth pair, TLS between them.

The coordinator runs ``cosim run`` in one namespace, listening on its end of a private /30; the
oscillator's ``mass2`` is external and is started from the other namespace with the command and the
two environment variables the coordinator printed. The result file must equal, byte for byte, the
one of the same scenario run on one machine. A second test cuts the link under a running subsim and
prints how long the coordinator takes to notice (measured, not asserted: restart is not ours).

Needs root and ``ip netns`` (skips saying why otherwise). Namespaces, links and addresses are unique
per test run and are removed even when the test fails.
"""

from __future__ import annotations

import json
import os
import re
import secrets
import shlex
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from certs import make_certs

from cosim.launch import terminate
from cosim.runner import run_scenario
from cosim.scenario import ScenarioError, load

pytestmark = [pytest.mark.slow]  # the inner loop: pytest -m "not slow"

ROOT = Path(__file__).parents[1]
OSCILLATOR = ROOT / "scenarios" / "oscillator.toml"


def _ip(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)


@dataclass
class Hosts:
    a: str  # namespace of the coordinator
    b: str  # namespace of the remote subsim
    link_a: str
    addr_a: str
    addr_b: str
    link_b: str = ""

    def exec(self, ns: str) -> list[str]:
        return ["ip", "netns", "exec", ns]


@pytest.fixture
def hosts() -> Iterator[Hosts]:
    if shutil.which("ip") is None:
        pytest.skip("no 'ip' command (iproute2) to build network namespaces")
    if os.geteuid() != 0:
        pytest.skip("building network namespaces needs root")
    tag = secrets.token_hex(3)
    h = Hosts(f"cosim-{tag}-a", f"cosim-{tag}-b", f"cva{tag}", "", "", f"cvb{tag}")
    octet = int(tag[:2], 16) % 250 + 1
    base = int(tag[2:4], 16) // 4 * 4  # a /30: base + 1 and base + 2
    h.addr_a, h.addr_b = f"10.231.{octet}.{base + 1}", f"10.231.{octet}.{base + 2}"
    created: list[str] = []
    try:
        for ns in (h.a, h.b):
            done = _ip("netns", "add", ns)
            if done.returncode != 0:
                pytest.skip(f"cannot create network namespaces here: {done.stderr.strip()}")
            created.append(ns)
        steps = [
            ("link", "add", h.link_a, "netns", h.a, "type", "veth", "peer", "name", f"cvb{tag}", "netns", h.b),
            ("-n", h.a, "addr", "add", f"{h.addr_a}/30", "dev", h.link_a),
            ("-n", h.b, "addr", "add", f"{h.addr_b}/30", "dev", f"cvb{tag}"),
            ("-n", h.a, "link", "set", h.link_a, "up"),
            ("-n", h.b, "link", "set", f"cvb{tag}", "up"),
            ("-n", h.a, "link", "set", "lo", "up"),
            ("-n", h.b, "link", "set", "lo", "up"),
        ]
        for step in steps:
            done = _ip(*step)
            if done.returncode != 0:
                pytest.skip(f"cannot build the veth pair: ip {' '.join(step)}: {done.stderr.strip()}")
        yield h
    finally:
        for ns in created:  # deleting a namespace deletes its end of the veth pair, and so the pair
            _ip("netns", "del", ns)


def _stop(popen: subprocess.Popen) -> None:
    terminate(popen, 10.0)


def _external_command(stderr_line: str) -> tuple[dict[str, str], list[str]]:
    """``VAR=value ... python -m cosim.serve ...`` as printed by the coordinator -> (environment, argv)."""
    words = shlex.split(stderr_line)
    env = dict(w.split("=", 1) for w in words if re.match(r"^[A-Z_]+=", w))
    argv = [w for w in words if not re.match(r"^[A-Z_]+=", w)]
    assert argv[0] == "python" and set(env) == {"COSIM_SECRET", "COSIM_ZENOH_AUTH"}, stderr_line
    return env, [sys.executable, *argv[1:]]


def _local_and_remote_run(hosts: Hosts, tmp_path: Path, stop: float,
                          *options: str) -> tuple[Path, Path, subprocess.Popen, dict]:
    """The oscillator run here to ``stop`` (the reference), and ``cosim run`` of it in namespace a over TLS with
    mass2 external: (local results, remote results, the coordinator, the environment for the remote subsim)."""
    certs = make_certs(tmp_path / "certs", f"IP:{hosts.addr_a}")
    scenario = tmp_path / "oscillator-remote.toml"
    scenario.write_text(OSCILLATOR.read_text().replace("[subsims.mass2]\n", "[subsims.mass2]\nexternal = true\n"))
    local = tmp_path / "local.csv"
    run_scenario(load(OSCILLATOR), method="distributed", stop=stop, output=local, progress=False, log=lambda m: None)
    remote = tmp_path / "remote.csv"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1"}
    coordinator = subprocess.Popen(
        [*hosts.exec(hosts.a), sys.executable, "-m", "cosim.cli", "run", str(scenario), "--method", "distributed",
         "--stop", str(stop), "--output", str(remote), "--quiet", "--listen", f"tls/{hosts.addr_a}:7447",
         "--tls-cert", str(certs["router_pem"]), "--tls-key", str(certs["router_key"]),
         "--tls-ca", str(certs["ca_pem"]), *options],
        env=env, stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=tmp_path)
    return local, remote, coordinator, env


def test_a_subsim_attached_from_another_host_over_tls_gives_the_local_results(hosts: Hosts, tmp_path: Path) -> None:
    local, remote, coordinator, env = _local_and_remote_run(hosts, tmp_path, 1.0)
    subsim = None
    try:
        assert coordinator.stderr is not None
        seen = []
        for line in coordinator.stderr:
            seen.append(line)
            if "COSIM_SECRET=" in line:
                break
        else:
            pytest.fail(f"the coordinator printed no command for the external subsim: {''.join(seen)[-2000:]}")
        secrets_env, argv = _external_command(line.strip())
        assert f"tls/{hosts.addr_a}:7447" in argv and "--tls-ca" in argv
        subsim = subprocess.Popen([*hosts.exec(hosts.b), *argv], env={**env, **secrets_env})
        out, err = coordinator.communicate(timeout=600)
        assert coordinator.returncode == 0, err[-2000:]
        assert subsim.wait(30) == 0  # told to shut down when the run ended
    finally:
        _stop(coordinator)
        if subsim is not None:
            _stop(subsim)
    assert remote.read_bytes() == local.read_bytes()


def test_how_long_a_cut_link_takes_to_notice(hosts: Hosts, tmp_path: Path) -> None:
    """Prints the detection time of a cut (veth down) on the coordinator side; asserts only that it is noticed."""
    certs = make_certs(tmp_path / "certs", f"IP:{hosts.addr_a}")
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1"}
    watcher = subprocess.Popen(
        [*hosts.exec(hosts.a), sys.executable, str(ROOT / "tests" / "netns_coordinator.py"),
         f"tls/{hosts.addr_a}:7447", str(certs["router_pem"]), str(certs["router_key"]), str(certs["ca_pem"])],
        env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    subsim = None
    try:
        assert watcher.stdout is not None and watcher.stdin is not None
        start = json.loads(watcher.stdout.readline())
        subsim = subprocess.Popen([*hosts.exec(hosts.b), *start["argv"]], env={**env, **start["env"]})
        assert watcher.stdout.readline().strip() == "attached"
        watcher.stdin.write("cut\n")
        watcher.stdin.flush()
        assert watcher.stdout.readline().strip() == "cutting"
        cut = time.monotonic()
        done = _ip("-n", hosts.a, "link", "set", hosts.link_a, "down")
        assert done.returncode == 0, done.stderr
        report = json.loads(watcher.stdout.readline())
        print(f"\ncut link noticed by the coordinator after {report['seconds']:.2f} s ({report['how']})")
        assert report["noticed"]
        subsim_rc = subsim.wait(60)
        print(f"the cut-off subsim exited with code {subsim_rc} {time.monotonic() - cut:.2f} s after the cut")
        assert subsim_rc == 3  # not 0: a supervisor (Restart=on-failure) starts it again (multi-host probe)
    finally:
        _stop(watcher)
        if subsim is not None:
            _stop(subsim)


@pytest.mark.parametrize("timeout", [None, "1.5"], ids=["auto", "1.5"])
def test_a_cut_link_is_waited_out_or_found_by_the_deadline_and_healed(hosts: Hosts, tmp_path: Path,
                                                                     timeout: str) -> None:
    """The link to the remote subsim goes down for 4 s mid-run. With the automatic deadline (at least 10 s for a
    subsim on another machine) the blip is waited out: no restart. With --timeout 1.5 the coordinator calls it
    hung, waits for it to answer again under its name, restores it and goes on. Either way the results equal
    the local run's, byte for byte."""
    local, remote, coordinator, env = _local_and_remote_run(hosts, tmp_path, 40.0,
                                                            *(["--timeout", timeout] if timeout else []))
    subsim = None
    try:
        assert coordinator.stderr is not None
        for line in coordinator.stderr:
            if "COSIM_SECRET=" in line:
                break
        secrets_env, argv = _external_command(line.strip())
        subsim = subprocess.Popen([*hosts.exec(hosts.b), *argv], env={**env, **secrets_env})
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and (not remote.exists() or len(remote.read_text().splitlines()) < 400):
            time.sleep(0.05)  # well into the run: the deadline has adapted to the measured requests
        assert _ip("-n", hosts.a, "link", "set", hosts.link_a, "down").returncode == 0
        time.sleep(4.0)  # past the deadline (1.5 s), short of the 10 s lease: the subsim keeps its session
        assert _ip("-n", hosts.a, "link", "set", hosts.link_a, "up").returncode == 0
        _, err = coordinator.communicate(timeout=600)
        assert coordinator.returncode == 0, err[-2000:]
        if timeout is None:
            assert "hung" not in err and "replaced" not in err, err[-2000:]
        else:
            assert "mass2 hung" in err and "replaced (1 of 2)" in err, err[-2000:]
        assert subsim.wait(30) == 0
    finally:
        _stop(coordinator)
        if subsim is not None:
            _stop(subsim)
    assert remote.read_bytes() == local.read_bytes()


def _children(pid: int) -> list[int]:
    found = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        found += [int(c) for c in (task / "children").read_text().split()]
    return found


def _launched_mass2(coordinator: int, hosts: Hosts) -> int:
    """The PID of mass2, a child of the coordinator (the launcher execs the shell, which execs the subsim), checked
    to run in the other namespace with no secret among its arguments."""
    away = []
    for pid in _children(coordinator):
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        if b"mass2" in argv and b"cosim.serve" in argv:
            assert not any(b"COSIM_SECRET" in a or b"COSIM_ZENOH_AUTH" in a for a in argv), argv
            away.append(pid)
    assert len(away) == 1, away
    netns = subprocess.run(["ip", "netns", "identify", str(away[0])], capture_output=True, text=True)
    assert netns.stdout.strip() == hosts.b  # it runs over there
    return away[0]


def _launched_run(hosts: Hosts, tmp_path: Path, stop: float = 30.0) -> tuple[Path, Path, subprocess.Popen]:
    """The oscillator run here to ``stop`` (the reference), and ``cosim run`` of it in namespace a with mass2 started
    in namespace b by its launcher, once it is well into the run: (local results, remote results, the coordinator,
    which the caller stops)."""
    scenario = tmp_path / "oscillator-launched.toml"
    launcher = json.dumps(["ip", "netns", "exec", hosts.b, "sh", "-c"])
    scenario.write_text(OSCILLATOR.read_text().replace(
        "[subsims.mass2]\n", f"[subsims.mass2]\nlauncher = {launcher}\nworkdir = {json.dumps(str(ROOT))}\n"
                             f"python = {json.dumps(sys.executable)}\n"))
    local = tmp_path / "local.csv"
    run_scenario(load(OSCILLATOR), method="distributed", stop=stop, output=local, progress=False, log=lambda m: None)
    remote = tmp_path / "remote.csv"
    coordinator = subprocess.Popen(
        [*hosts.exec(hosts.a), sys.executable, "-m", "cosim.cli", "run", str(scenario), "--method", "distributed",
         "--stop", str(stop), "--output", str(remote), "--quiet", "--listen", f"tcp/{hosts.addr_a}:7447"],
        env={**os.environ, "PYTHONPATH": str(ROOT)}, stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
        cwd=tmp_path)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and (not remote.exists() or len(remote.read_text().splitlines()) < 100):
            assert coordinator.poll() is None, coordinator.communicate()[1][-2000:]
            time.sleep(0.02)
    except BaseException:
        _stop(coordinator)
        raise
    return local, remote, coordinator


def test_a_subsim_started_on_another_host_by_its_launcher_gives_the_local_results_and_is_replaced(
        hosts: Hosts, tmp_path: Path) -> None:
    """``launcher`` starts mass2 in the other namespace (as ``ssh host`` would on another machine), its secrets on
    its standard input: the results equal the one-machine run's, byte for byte; killed there mid-run it is started
    again through its launcher and the results are still the same; the launcher never sees the secrets as
    arguments."""
    local, remote, coordinator = _launched_run(hosts, tmp_path)
    try:
        first = _launched_mass2(coordinator.pid, hosts)
        os.kill(first, signal.SIGKILL)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and coordinator.poll() is None:  # its replacement: over there too
            try:
                if _launched_mass2(coordinator.pid, hosts) != first:
                    break
            except (AssertionError, OSError):  # not yet started, or between exec()s
                time.sleep(0.01)
        else:
            pytest.fail("no replacement of mass2 was seen while the run went on")
        _, err = coordinator.communicate(timeout=600)
        assert coordinator.returncode == 0, err[-2000:]
        assert "replaced (1 of 2)" in err, err[-2000:]
    finally:
        _stop(coordinator)
    assert remote.read_bytes() == local.read_bytes()


def test_a_launched_subsim_lost_in_an_outage_is_started_again_once_the_link_is_back(hosts: Hosts,
                                                                                    tmp_path: Path) -> None:
    """The link to the other host goes down for 14 s, past the 10 s lease: mass2 is lost, and starting it again
    fails at once while the network is down. Every try used up a restart (five in under a second); now it is tried
    again every 5 s, as an external subsim is waited for, and the run goes on once the link is back, with the
    one-machine results byte for byte."""
    local, remote, coordinator = _launched_run(hosts, tmp_path)
    try:
        # down on the far side: there the route goes too, and a new subsim fails at once (network unreachable)
        assert _ip("-n", hosts.b, "link", "set", hosts.link_b, "down").returncode == 0
        time.sleep(14.0)
        assert _ip("-n", hosts.b, "link", "set", hosts.link_b, "up").returncode == 0
        assert _ip("-n", hosts.b, "addr", "add", f"{hosts.addr_b}/30", "dev", hosts.link_b).returncode in (0, 2)
        _, err = coordinator.communicate(timeout=600)
        assert coordinator.returncode == 0, err[-2000:]
        assert "mass2 could not be started again over there" in err and "replaced (1 of 2)" in err, err[-2000:]
    finally:
        _stop(coordinator)
    assert remote.read_bytes() == local.read_bytes()


def test_listening_on_every_address_without_a_route_out_tells_the_subsim_its_one_address(hosts: Hosts) -> None:
    """--listen tcp/0.0.0.0:7447 on a machine whose only network is a lab's (no default route): the printed command
    and the cosim-attach line had THIS_MACHINE_ADDRESS, '(none found here)', though the machine has one (a multi-host
    probe). Its interfaces' addresses are found now."""
    code = "from cosim.runner import attach_endpoint; print(*attach_endpoint('tcp/0.0.0.0:7447', 'tcp/0.0.0.0:7447'))"
    done = subprocess.run([*hosts.exec(hosts.a), sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60, cwd=Path(__file__).resolve().parents[1])
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(f"tcp/{hosts.addr_a}:7447 {hosts.addr_a} is this machine's address"), done.stdout


def test_every_address_of_an_interface_that_is_up_is_offered_and_none_of_one_that_is_down(hosts: Hosts) -> None:
    """A lab machine with a second address on its interface (missed: only an interface's first was read) and an
    interface that is down (its address was offered, though no subsim could reach it there)."""
    octet = hosts.addr_a.split(".")[2]
    second, down = f"10.232.{octet}.1", f"10.233.{octet}.1"
    tag = hosts.link_a[3:]
    for step in (("-n", hosts.a, "addr", "add", f"{second}/24", "dev", hosts.link_a),
                 ("-n", hosts.a, "link", "add", f"cvd{tag}", "type", "veth", "peer", "name", f"cve{tag}"),
                 ("-n", hosts.a, "addr", "add", f"{down}/24", "dev", f"cvd{tag}")):  # (left down)
        done = _ip(*step)
        assert done.returncode == 0, done.stderr
    code = "from cosim.runner import interface_addresses; print(*interface_addresses())"
    done = subprocess.run([*hosts.exec(hosts.a), sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60, cwd=Path(__file__).resolve().parents[1])
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == [hosts.addr_a, second], done.stdout


def test_a_launched_subsim_needs_an_endpoint_its_machine_can_be_told(tmp_path: Path) -> None:
    scenario = tmp_path / "launched.toml"
    scenario.write_text(OSCILLATOR.read_text().replace("[subsims.mass2]\n",
                                                       "[subsims.mass2]\nlauncher = ['ssh', 'lab-2']\n"))
    for listen, says in ((None, "give --listen tcp/"), ("tcp/0.0.0.0:0", "cannot be told")):
        with pytest.raises(ScenarioError, match=says):
            run_scenario(load(scenario), stop=0.1, output=tmp_path / "x.csv", progress=False, listen=listen,
                         log=lambda m: None)
    assert not (tmp_path / "x.csv").exists()
