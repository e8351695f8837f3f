"""External subsims: a launcher fixes the run id, reads a machine-readable attach line, and the
subsim it started receives ``shutdown`` when the run ends. The login it is handed serves that subsim only."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import zenoh

from cosim.protocol.security import ZENOH_AUTH_ENV, ClientSecurity, parse_login
from cosim.protocol.transport.session import client_config
from cosim.results import read_results

pytestmark = [pytest.mark.slow]  # the inner loop: pytest -m "not slow"

ROOT = Path(__file__).parents[1]
OSCILLATOR = ROOT / "scenarios" / "oscillator.toml"
COSIM = [sys.executable, "-m", "cosim.cli"]



def external_scenario(tmp_path: Path) -> Path:
    sc = tmp_path / "ext.toml"
    text = OSCILLATOR.read_text()
    head = '[subsims.mass2]\nmodel = "subsims.oscillator.subsim:Mass"'
    assert head in text
    sc.write_text(text.replace(head, head + "\nexternal = true"))
    return sc


def start_waiting(tmp_path: Path, procs: list, *options: str) -> tuple[subprocess.Popen, dict]:
    """``cosim run`` of the oscillator with mass2 external, to 0.1 s, up to its ``cosim-attach`` line: (the coordinator,
    that line's JSON)."""
    coord = subprocess.Popen([*COSIM, "run", str(external_scenario(tmp_path)), "--stop", "0.1", "--quiet", *options],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    procs.append(coord)
    for line in coord.stderr:
        if line.startswith("cosim-attach "):
            return coord, json.loads(line.removeprefix("cosim-attach "))
    raise AssertionError("no attach line")


def test_run_id_attach_line_and_shutdown_of_the_external_subsim(tmp_path: Path, procs: list) -> None:
    out = tmp_path / "ext.csv"
    coord, attach = start_waiting(tmp_path, procs, "--output", str(out), "--run-id", "launcher-run.1")
    assert attach["run"] == "launcher-run.1" and attach["name"] == "mass2"
    assert attach["endpoint"].startswith("tcp/127.0.0.1:")
    command = attach["command"]
    assert command[:4] == ["python", "-m", "cosim.serve", "subsims.oscillator.subsim:Mass"]
    # whoever holds mass2's login (its operator, or anyone it leaks to) may serve mass2 only: a queryable on
    # every subsim's key sees none of mass1's requests (with one login shared by the run it saw all of them)
    login = parse_login(attach["env"][ZENOH_AUTH_ENV], ZENOH_AUTH_ENV)
    spy = zenoh.open(client_config(attach["endpoint"], 10.0, security=ClientSecurity(bytes(32), login)))
    seen: list[str] = []
    trap = spy.declare_queryable("cosim/launcher-run.1/*/rpc", lambda query: seen.append(str(query.key_expr)))
    user = subprocess.Popen([sys.executable, *command[1:]], stderr=subprocess.PIPE, text=True,
                            env={**os.environ, **attach["env"]})  # the run's key and login for this subsim
    procs.append(user)
    try:
        coord.communicate(timeout=120)
    finally:
        trap.undeclare()
        spy.close()
    assert seen == []
    assert coord.returncode == 0
    _, err = user.communicate(timeout=30)
    assert user.returncode == 0
    assert "mass2: shutdown requested by the coordinator" in err, err
    _, data = read_results(out)
    assert data[-1, 0] == pytest.approx(0.1)


def test_attach_wait_is_settable_and_a_missing_external_subsim_stops_the_run(tmp_path: Path) -> None:
    done = subprocess.run([*COSIM, "run", str(external_scenario(tmp_path)), "--quiet", "--attach-wait", "0.5",
                           "--output", str(tmp_path / "x.csv")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    assert "waiting up to 0.5 s for external subsim 'mass2'" in done.stderr
    assert "mass2.connect: [no_responder] no process appeared within 0.5 s" in done.stderr


def test_a_bad_run_id_is_refused_by_the_command_line() -> None:
    done = subprocess.run([*COSIM, "run", str(OSCILLATOR), "--run-id", "a/b"], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2 and "--run-id 'a/b' must be 1-64 characters" in done.stderr


def test_a_launcher_runs_the_subsim_in_its_workdir_with_its_secrets_on_standard_input(tmp_path: Path) -> None:
    """``launcher = ["sh", "-c"]`` stands for ``ssh host``: the one shell line it gets goes to a workdir whose name
    needs quoting, takes the secrets from standard input and runs the subsim there; the results are the plain
    run's, byte for byte."""
    from cosim.runner import run_scenario
    from cosim.scenario import load

    workdir = tmp_path / "lab's dir"
    workdir.mkdir()
    (workdir / "lab_mass.py").write_text("from subsims.oscillator.subsim import Mass as LabMass\n")  # only there
    sc = tmp_path / "launched.toml"
    head = '[subsims.mass2]\nmodel = "subsims.oscillator.subsim:Mass"'
    sc.write_text(OSCILLATOR.read_text().replace(head, '[subsims.mass2]\nmodel = "lab_mass:LabMass"\n'
                                                 f'launcher = ["sh", "-c"]\nworkdir = {json.dumps(str(workdir))}\n'
                                                 f'python = {json.dumps(sys.executable)}'))
    plain, launched = tmp_path / "plain.csv", tmp_path / "launched.csv"
    run_scenario(load(OSCILLATOR), stop=0.5, output=plain, progress=False, log=lambda m: None)
    run_scenario(load(sc), stop=0.5, output=launched, progress=False, log=lambda m: None, listen="tcp/127.0.0.1:0")
    assert launched.read_bytes() == plain.read_bytes()


@pytest.mark.parametrize(("workdir", "where"), [
    ("~", "{home}"), ("~/sat dir", "{home}/sat dir"), ("-dash", "{cwd}/-dash"), ("it's $HOME", "{cwd}/it's $HOME"),
])
def test_a_launchers_line_goes_to_its_workdir_as_written(tmp_path: Path, workdir: str, where: str) -> None:
    """``~`` is the home directory over there (it was quoted: 'cd: can't cd to ~'), a name starting with '-' is a
    directory, not an option of cd, and quotes and $ are the path's own."""
    from cosim.launch import launcher_line

    home, cwd = tmp_path / "home", tmp_path / "cwd"
    for d in (home / "sat dir", cwd / "-dash", cwd / "it's $HOME"):
        d.mkdir(parents=True)
    done = subprocess.run(["sh", "-c", launcher_line(["sh", "-c", 'pwd; echo "$COSIM_SECRET"'], workdir)],
                          input="key\nlogin\n", capture_output=True, text=True, cwd=cwd, timeout=30,
                          env={**os.environ, "HOME": str(home)})
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [where.format(home=home, cwd=cwd), "key"]


def test_every_external_subsims_command_comes_before_the_wait_and_carries_the_runs_lease(tmp_path: Path) -> None:
    """Two external subsims: the second's command (and secrets) came only once the first had attached, so two
    sites could not start theirs at the same time; and a [run] lease did not reach them (multi-host probe)."""
    sc = tmp_path / "both.toml"
    text = OSCILLATOR.read_text().replace('model = "subsims.oscillator.subsim:Mass"',
                                          'model = "subsims.oscillator.subsim:Mass"\nexternal = true')
    assert text.count("external = true") == 2
    sc.write_text(text + "\n[run]\nlease = 30\n")
    done = subprocess.run([*COSIM, "run", str(sc), "--quiet", "--attach-wait", "1", "--output",
                           str(tmp_path / "x.csv")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    attach = [json.loads(x.removeprefix("cosim-attach ")) for x in done.stderr.splitlines()
              if x.startswith("cosim-attach ")]
    assert [a["name"] for a in attach] == ["mass1", "mass2"]
    assert all(a["command"][-2:] == ["--lease", "30"] for a in attach), attach
    assert done.stderr.index("cosim-attach ") < done.stderr.index("waiting up to 1 s for external subsims 'mass1', "
                                                                   "'mass2'")
    assert done.stderr.rindex("cosim-attach ") < done.stderr.index("waiting up to")
    assert "mass1.connect: [no_responder] no process appeared within 1 s (--attach-wait; " in done.stderr


def test_a_router_on_every_address_gives_its_one_address_or_a_placeholder_a_shell_passes_on(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """--listen tcp/0.0.0.0:P printed tcp/<this machine's address>:P, which a shell refuses when pasted (the quote
    and the redirections); the machine's address when it has one, else a placeholder naming those it has."""
    import shlex

    import cosim.runner as runner

    monkeypatch.setattr(runner, "host_addresses", lambda: ["10.1.2.3"])
    assert runner.attach_endpoint("tcp/0.0.0.0:7447", "tcp/127.0.0.1:7447")[0] == "tcp/10.1.2.3:7447"
    monkeypatch.setattr(runner, "host_addresses", lambda: ["10.1.2.3", "192.168.5.6"])
    endpoint, hint = runner.attach_endpoint("tcp/0.0.0.0:7447", "tcp/127.0.0.1:7447")
    assert endpoint == "tcp/THIS_MACHINE_ADDRESS:7447" and shlex.split(endpoint) == [endpoint]
    assert "this machine has 10.1.2.3, 192.168.5.6" in hint
    monkeypatch.setattr(runner, "host_addresses", lambda: [])
    assert "none found here" in runner.attach_endpoint("tcp/0.0.0.0:7447", "tcp/127.0.0.1:7447")[1]
    monkeypatch.setattr(runner, "host_addresses", lambda: ["10.1.2.3"])  # TLS: the certificate's name, not an address
    endpoint, hint = runner.attach_endpoint("tls/0.0.0.0:7447", "tls/127.0.0.1:7447")
    assert endpoint == "tls/THIS_MACHINE_ADDRESS:7447" and "the router's certificate (--tls-cert) is for" in hint


def test_a_subsim_of_another_protocol_version_is_named_as_such_on_both_sides(cosim_bus, tmp_path: Path) -> None:
    """A protocol-2 subsim answered a protocol-1 coordinator: 'malformed reply: protocol version 2 not supported
    (this end speaks 1)' there (a buggy subsim?), and on the subsim's terminal only 'the coordinator left'."""
    from cosim.contract import PROTOCOL_VERSION, SubsimError
    from cosim.launch import terminate

    newer = ("import sys, cosim.contract as c; c.PROTOCOL_VERSION += 1\n"  # before the codec reads it
             "from cosim.serve import main; sys.exit(main(sys.argv[1:]))\n")
    proc = subprocess.Popen([sys.executable, "-c", newer, "subsims.oscillator.subsim:Mass", "--connect",
                             cosim_bus.endpoint, "--run", cosim_bus.run, "--name", "m2"],
                            env={**os.environ, **cosim_bus.subsim_env("m2")}, stderr=subprocess.PIPE, text=True)
    handle = None
    try:
        handle = cosim_bus.attach("m2", timeout=20.0, wait=20.0)
        with pytest.raises(SubsimError) as err:
            handle.describe()
        assert err.value.code == "version" and "malformed" not in str(err.value)
        assert err.value.message == (f"it speaks protocol {PROTOCOL_VERSION + 1}, this coordinator {PROTOCOL_VERSION}: "
                                     "run the same cosim version on its machine and here (cosim --version)")
    finally:
        if handle is not None:
            handle.close()
        terminate(proc, 5.0)
    said = proc.stderr.read()
    assert (f"m2: refused a request in protocol {PROTOCOL_VERSION}, this subsim speaks {PROTOCOL_VERSION + 1}: if your "
            "coordinator sent it, run the same cosim version on both machines (cosim --version)") in said, said


def test_an_external_subsim_serving_another_model_is_refused_naming_both(tmp_path: Path, procs: list) -> None:
    """Another model attached as mass2 was configured with mass2's params, and the run stopped on
    '[subsims.mass2.params] configure: bad parameter: unknown parameter(s) 'm', 'k', ...': the scenario blamed for
    the remote's code."""
    coord, attach = start_waiting(tmp_path, procs, "--output", str(tmp_path / "x.csv"))
    other = [sys.executable, "-m", "cosim.serve", "subsims.integrator.subsim:Integrator", *attach["command"][4:]]
    procs.append(subprocess.Popen(other, stderr=subprocess.DEVNULL, env={**os.environ, **attach["env"]}))
    _, err = coord.communicate(timeout=120)
    assert coord.returncode == 2
    assert ("[subsims.mass2] model = 'subsims.oscillator.subsim:Mass', but the process that attached as 'mass2' "
            "serves subsims.integrator.subsim.Integrator, which refused its params (configure: bad parameter: "
            "unknown parameter(s)") in err, err
    assert err.rstrip().endswith("start it with the command printed for it"), err


@pytest.mark.parametrize("external", [True, False])
def test_an_external_subsim_whose_ports_do_not_fit_is_named_as_another_model(tmp_path: Path, external: bool) -> None:
    """Another model attached as mass2 that took mass2's params (a newcomer served the wall model as the free one):
    the coupling check blamed the scenario, '[couplings[0]] ... has no input ...'. Now the run says which class
    serves mass2; a subsim this run started is not named so (its model is the scenario's own: the ports are)."""
    from cosim.handles import InProcessHandle
    from cosim.runner import build_plan
    from cosim.runtime import Runtime
    from cosim.scenario import ScenarioError, load
    from subsims.integrator.subsim import Integrator
    from subsims.oscillator.subsim import Mass

    scenario = load(external_scenario(tmp_path) if external else OSCILLATOR)
    descriptions = {"mass1": InProcessHandle(Runtime(Mass(), "mass1")).describe(),
                    "mass2": InProcessHandle(Runtime(Integrator(), "mass2")).describe()}
    with pytest.raises(ScenarioError) as err:
        build_plan(scenario, descriptions, "distributed")
    served = "[subsims.mass2] model = 'subsims.oscillator.subsim:Mass', but the process that attached as 'mass2' " \
             "serves subsims.integrator.subsim.Integrator, which does not fit the couplings ([couplings[0]] coupling"
    assert (served in str(err.value)) is external, err.value
    assert "[couplings[0]] coupling mass2.u -> mass1.F" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("edited", [False, True], ids=["same-code", "edited-copy"])
def test_an_external_subsim_running_other_code_than_this_machines_is_said(tmp_path: Path, procs: list,
                                                                          edited: bool) -> None:
    """mass2 served from a copy of the subsims package with its model's file edited (an older checkout on the
    machine it moved to): the run went on without a word; now one line names the module whose file differs. The
    same code says nothing."""
    import shutil

    copy = tmp_path / "there"
    shutil.copytree(ROOT / "subsims", copy / "subsims", ignore=shutil.ignore_patterns("__pycache__", "*.fmu", "build*"))
    if edited:
        model = copy / "subsims" / "oscillator" / "model.py"
        model.write_text(model.read_text() + "\n# an older copy of this file\n")
    coord, attach = start_waiting(tmp_path, procs, "--output", str(tmp_path / "x.csv"))
    user = subprocess.Popen([sys.executable, *attach["command"][1:]], stderr=subprocess.DEVNULL, cwd=copy,
                            env={**os.environ, **attach["env"], "PYTHONPATH": str(copy)})
    procs.append(user)
    _, err = coord.communicate(timeout=120)
    assert coord.returncode == 0, err
    said = "cosim: mass2 runs other code than this machine has for subsims.oscillator.model (the files differ): its " \
           "results may differ from the same run here"
    assert (said in err) is edited, err
    assert err.count("runs other code") == edited
