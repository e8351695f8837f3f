"""What the coordinator makes of a subsim of someone else's making that replies wrongly (docs/protocol.md 6).

The subsim here is a queryable in the test's process that answers with the real runtime and then doctors its
reply: a missing output, a wrong shape, an echoed time off by one ulp, a Zenoh error reply, a dropped query. Each
must end the request in one line naming what the subsim got wrong (a protocol implementer's probe found a raw
KeyError from the results writer, a coupling blamed for the shape, and 'nobody serves this subsim')."""

from __future__ import annotations

import contextlib
import json
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
import pytest
import zenoh

from cosim.contract import SubsimDied, SubsimError
from cosim.protocol.keys import alive_key, rpc_key
from cosim.protocol.messages import open_request, seal_reply
from cosim.protocol.security import SECRET_ENV, ZENOH_AUTH_ENV, ClientSecurity, parse_key, parse_login, zenoh_login
from cosim.protocol.service import answer
from cosim.protocol.transport.client import RemoteHandle
from cosim.protocol.transport.session import client_config
from cosim.runtime import Runtime
from subsims.integrator.subsim import Integrator
from subsims.oscillator.subsim import Mass

NAME = "doctored"
TIMES = np.linspace(0.0, 0.4, 5)
INPUTS = {"u": np.ones((5, 2))}

Doctor = Callable[[str, dict], Any]  # (command, decoded reply) -> the reply to send, DROP or ZENOH_ERROR
DROP, ZENOH_ERROR = "drop", "zenoh error"


@contextlib.contextmanager
def doctored_subsim(endpoint: str, run: str, name: str, key: bytes, login: tuple[str, str], model: type,
                    doctor: Doctor) -> Iterator[None]:
    """A subsim ``name`` serving ``model`` with the real runtime, its replies passed through ``doctor`` first."""
    runtime = Runtime(model, name=name)

    def respond(query: zenoh.Query) -> None:
        opened = open_request(key, query.payload.to_bytes() if query.payload is not None else b"")
        with query:
            if opened is None:
                return
            seq, body = opened
            cmd = msgpack.unpackb(body).get("cmd", "?")
            reply = doctor(cmd, msgpack.unpackb(answer(runtime, body)))
            if reply == ZENOH_ERROR:
                query.reply_err(b"refused by the subsim")
            elif reply != DROP:
                query.reply(query.key_expr, seal_reply(key, seq, msgpack.packb(reply)))

    session = zenoh.open(client_config(endpoint, 10.0, security=ClientSecurity(key, login)))
    try:
        queryable = session.declare_queryable(rpc_key(run, name), respond)
        token = session.liveliness().declare_token(alive_key(run, name))  # last, as a subsim does
        yield
        token.undeclare()
        queryable.undeclare()
    finally:
        session.close()


@pytest.fixture
def doctored(cosim_bus) -> Iterator[Callable[[Doctor], RemoteHandle]]:
    """``doctored(doctor)``: a handle to an integrator (size 2) whose replies pass through ``doctor`` first."""
    with contextlib.ExitStack() as stack:

        def start(doctor: Doctor) -> RemoteHandle:
            login = zenoh_login(cosim_bus.secret, cosim_bus.run)
            stack.enter_context(doctored_subsim(cosim_bus.endpoint, cosim_bus.run, NAME, cosim_bus.key(NAME), login,
                                                Integrator, doctor))
            return cosim_bus.attach(NAME, timeout=20.0)

        yield start


def on_run(change: Callable[[dict], None]) -> Doctor:
    """A doctor that changes only run_interval's result."""

    def doctor(cmd: str, reply: dict) -> dict:
        if cmd == "run_interval" and reply.get("ok"):
            change(reply["result"])
        return reply

    return doctor


def column(result: dict) -> None:  # y as [n] instead of [n, 2]
    y = result["outputs"]["y"]
    y["shape"], y["data"] = [y["shape"][0]], y["data"][: 8 * y["shape"][0]]


def ulp(result: dict) -> None:  # the echoed t one ulp off at its end
    t = np.frombuffer(result["t"]["data"], "<f8").copy()
    t[-1] = np.nextafter(t[-1], 1.0)
    result["t"]["data"] = t.tobytes()


@pytest.mark.parametrize(("change", "words"), [
    (lambda r: r["outputs"].pop("y"), "malformed reply: missing output(s) ['y'] (described: y)"),
    (lambda r: r["outputs"].update(z=r["outputs"]["y"]), "malformed reply: unknown output(s) ['z'] (described: y)"),
    (column, "malformed reply: output 'y' has shape [5], needs [5, 2] (5 samples of its size 2)"),
    (ulp, "malformed reply: t is not the request's t, bit for bit (it is echoed)"),
    (lambda r: r.update(end_time=0.5), "malformed reply: end_time 0.5 is not the request's last time 0.4"),
])
def test_a_run_reply_that_does_not_match_the_description_is_named(doctored, change: Callable[[dict], None],
                                                                    words: str) -> None:
    handle = doctored(on_run(change))
    handle.configure({"size": 2})
    with pytest.raises(SubsimError) as info:
        handle.run_interval(TIMES, INPUTS)
    assert str(info.value) == f"{NAME}.run_interval: [bad_value] {words}"


def test_a_reply_that_matches_its_description_passes(doctored) -> None:
    """The doctor that changes nothing: the checks above refuse only what is wrong."""
    handle = doctored(on_run(lambda r: None))
    handle.configure({"size": 2})
    result = handle.run_interval(TIMES, INPUTS)
    np.testing.assert_array_equal(result.outputs["y"], np.outer(TIMES, [1.0, 1.0]))


@pytest.mark.parametrize(("field", "value", "words"), [
    ("name", "other", "[bad_value] malformed reply: it describes itself as 'other', but serves as 'doctored'"),
    ("protocol", 2, "[version] malformed reply: it speaks protocol 2, this coordinator 1"),
])
def test_a_description_naming_another_subsim_or_protocol_is_refused(doctored, field: str, value: Any,
                                                                     words: str) -> None:
    def doctor(cmd: str, reply: dict) -> dict:
        if cmd in ("describe", "configure") and reply.get("ok"):
            reply["result"][field] = value
        return reply

    handle = doctored(doctor)
    with pytest.raises(SubsimError) as info:
        handle.configure({"size": 2})
    assert str(info.value).startswith(f"{NAME}.configure: {words}")


def test_a_zenoh_error_reply_is_named_as_such_at_once(doctored) -> None:
    """It read '[timeout] no reply within 120 s (<its bytes>)', 0.2 s after the request."""
    handle = doctored(lambda cmd, reply: ZENOH_ERROR if cmd == "run_interval" else reply)
    handle.configure({"size": 2})
    started = time.monotonic()
    with pytest.raises(SubsimError) as info:
        handle.run_interval(TIMES, INPUTS)
    assert time.monotonic() - started < 10.0
    assert info.value.code == "bad_value"
    assert "answered with a Zenoh error reply ('refused by the subsim')" in str(info.value)
    assert "an error goes in a protocol reply" in str(info.value)


def test_a_request_its_process_ends_without_a_reply_is_named_as_such(doctored) -> None:
    """It read 'no process serves this subsim' of a process that was up and serving."""
    handle = doctored(lambda cmd, reply: DROP if cmd == "run_interval" else reply)
    handle.configure({"size": 2})
    with pytest.raises(SubsimError) as info:
        handle.run_interval(TIMES, INPUTS)
    assert "its process ended the request without a reply" in str(info.value), str(info.value)


OSCILLATOR = Path(__file__).parents[1] / "scenarios" / "oscillator.toml"


def configure_without_history_limit(cmd: str, reply: dict) -> dict:
    if cmd == "configure" and reply.get("ok"):
        del reply["result"]["history_limit"]
    return reply


@pytest.mark.parametrize(("doctor", "words"), [
    (on_run(lambda r: r["outputs"].pop("v")),
     "cosim: run stopped: mass2.run_interval: [bad_value] malformed reply: missing output(s) ['v'] (described: u, v)"),
    # not '[subsims.mass2.params] malformed reply', which sent the user to the scenario's parameters
    (configure_without_history_limit,
     "cosim: run stopped: mass2.configure: [bad_request] malformed reply: result: missing required field "
     "'history_limit'"),
])
def test_cosim_run_with_an_external_subsim_that_replies_wrongly_stops_in_one_line(tmp_path: Path, procs: list,
                                                                                    doctor: Doctor,
                                                                                    words: str) -> None:
    """Through `cosim run`: a missing output was a KeyError traceback from the results writer."""
    text = OSCILLATOR.read_text()
    head = '[subsims.mass2]\nmodel = "subsims.oscillator.subsim:Mass"'
    assert head in text
    (tmp_path / "ext.toml").write_text(text.replace(head, head + "\nexternal = true"))
    coord = subprocess.Popen([sys.executable, "-m", "cosim.cli", "run", str(tmp_path / "ext.toml"), "--stop", "0.2",
                              "--output", str(tmp_path / "x.csv"), "--quiet", "--attach-wait", "60"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    procs.append(coord)
    attach = None
    assert coord.stderr is not None
    for line in coord.stderr:
        if line.startswith("cosim-attach "):
            attach = json.loads(line.removeprefix("cosim-attach "))
            break
    assert attach is not None, "no attach line"
    env = attach["env"]
    key, login = parse_key(env[SECRET_ENV]), parse_login(env[ZENOH_AUTH_ENV], ZENOH_AUTH_ENV)
    with doctored_subsim(attach["endpoint"], attach["run"], "mass2", key, login, Mass, doctor):
        _, err = coord.communicate(timeout=120)  # (what the loop above buffered past the attach line is not in err)
    assert coord.returncode == 1 and err.strip().splitlines()[-1] == words, err
    assert "Traceback" not in err and "[subsims.mass2.params]" not in err


def test_a_process_started_again_under_the_name_of_one_that_died_is_a_death_not_a_duplicate(cosim_bus) -> None:
    """Two external subsims cut off longer than their lease both leave; their operator starts both again, and the
    one with no request in flight then answered its old handle from a new process: '[duplicate] a second process
    answers as 'aero' ... stop one of them' (multi-host probe), where there was no second copy to stop. That is
    its death (so the run replaces it: attaches the new process, restores it)."""
    key, login = cosim_bus.key(NAME), zenoh_login(cosim_bus.secret, cosim_bus.run)
    serve = lambda: doctored_subsim(cosim_bus.endpoint, cosim_bus.run, NAME, key, login, Integrator,  # noqa: E731
                                    lambda cmd, reply: reply)
    with serve():
        handle = cosim_bus.attach(NAME, timeout=20.0)
        handle.configure({"size": 2})
        handle.run_interval(TIMES, INPUTS)
    deadline = time.monotonic() + 20
    while handle.alive and time.monotonic() < deadline:  # its token's DELETE
        time.sleep(0.01)
    with serve():
        assert handle.wait_alive(20.0)
        with pytest.raises(SubsimDied) as info:
            handle.run_interval(TIMES, INPUTS)
    assert "its process died, and the process now serving its name was started since" in str(info.value)


@pytest.mark.parametrize("times", [[0, 1, 2], np.arange(3), np.array([0.0, 0.5, 1.0], np.float32),
                                   np.array([0.0, 0.5, 1.0], ">f8")])
def test_times_given_as_other_numbers_are_checked_as_the_floats_they_travel_as(doctored, times) -> None:
    """They were refused as 'not the request's t' (red team): the wire carries little-endian float64."""
    handle = doctored(on_run(lambda r: None))
    handle.configure({"size": 2})
    result = handle.run_interval(times, {"u": np.ones((3, 2))})
    np.testing.assert_array_equal(result.t, np.asarray(times, dtype=np.float64))
