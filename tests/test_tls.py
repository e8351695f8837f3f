"""TLS and logins through Zenoh's own configuration, on loopback with real processes (docs/reliability.md)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import zenoh
from certs import make_certs

from cosim.launch import Bus
from cosim.protocol.security import ZENOH_AUTH_ENV, ClientSecurity, Security, zenoh_login
from cosim.protocol.transport.session import client_config

pytestmark = [pytest.mark.slow]  # the inner loop: pytest -m "not slow"

T = np.array([0.0, 0.5])
OSCILLATOR = Path(__file__).parents[1] / "scenarios" / "oscillator.toml"


@pytest.fixture(scope="module")
def certs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return make_certs(tmp_path_factory.mktemp("certs"))


def tls_bus(certs: dict[str, Path], mutual: bool = False, auth_file: Path | None = None,
            names: list[str] | None = None) -> Bus:
    security = Security(certs["router_pem"], certs["router_key"], certs["ca_pem"], mutual=mutual, auth_file=auth_file)
    return Bus.open("tls/localhost:0", security=security, names=names)


@pytest.mark.parametrize("mutual", [False, True], ids=["server-cert", "mutual"])
def test_a_subsim_serves_over_tls(certs: dict[str, Path], mutual: bool) -> None:
    with tls_bus(certs, mutual) as bus:
        assert bus.endpoint.startswith("tls/localhost:")
        handle = bus.spawn("subsims.integrator", "secure").handle
        handle.configure({})
        result = handle.run_interval(T, {"u": np.ones((2, 1))})
        assert result.outputs["y"][-1, 0] == pytest.approx(0.5)


@pytest.mark.parametrize("what", ["no CA", "no login", "no client certificate"])
def test_a_client_missing_a_piece_cannot_connect(certs: dict[str, Path], what: str) -> None:
    with tls_bus(certs, mutual=True) as bus:
        login = zenoh_login(bus.secret, bus.run)
        full = {"login": login, "tls_ca": certs["ca_pem"], "tls_cert": certs["subsim_pem"],
                "tls_key": certs["subsim_key"]}
        zenoh.open(client_config(bus.endpoint, 2.0, security=ClientSecurity(bytes(32), **full))).close()  # control
        drop = {"no CA": ("tls_ca",), "no login": ("login",), "no client certificate": ("tls_cert", "tls_key")}[what]
        partial = ClientSecurity(bytes(32), **{k: v for k, v in full.items() if k not in drop})
        with pytest.raises(zenoh.ZError, match="Unable to connect"):
            zenoh.open(client_config(bus.endpoint, 2.0, security=partial)).close()


def test_an_auth_file_login_serves_an_external_subsim(certs: dict[str, Path], tmp_path: Path) -> None:
    """A subsim started by hand with --auth-file (one of the router's dictionary lines) and its key; a site login
    may serve any of the subsims a run was opened with (each of which has its own login too)."""
    users = tmp_path / "users"
    users.write_text("# operators\nsite-b:correct horse battery staple\n")
    mine = tmp_path / "site-b"
    mine.write_text("site-b:correct horse battery staple\n")
    with tls_bus(certs, auth_file=users, names=["local", "remote"]) as bus:
        cmd = [*bus.command("subsims.integrator", "remote"), "--auth-file", str(mine)]
        env = {**os.environ, "COSIM_SECRET": bus.key("remote").hex()}
        popen = subprocess.Popen(cmd, env=env)
        try:
            handle = bus.attach("remote", wait=30.0)
            assert handle.configure({}).name == "remote"
            handle.shutdown()
            assert popen.wait(10) == 0
        finally:
            if popen.poll() is None:
                popen.kill()
                popen.wait()


def test_a_tls_endpoint_without_a_certificate_is_refused_with_a_clear_message() -> None:
    with pytest.raises(ValueError, match="--tls-cert"):
        Bus.open("tls/localhost:0")


def test_cosim_run_with_a_certificate_listens_on_tls_by_default_and_asks_for_the_ca(
    certs: dict[str, Path], tmp_path: Path
) -> None:
    """--tls-cert alone used to leave the default tcp/ endpoint (refused: must be tls/), and without --tls-ca the
    launched subsims timed out after 10 s; a missing file is named by its option."""
    cosim = [sys.executable, "-m", "cosim.cli", "run", str(OSCILLATOR), "--stop", "0.1",  # (not --quiet: see below)
             "--tls-cert", str(certs["router_pem"]), "--tls-key", str(certs["router_key"])]
    ok = subprocess.run([*cosim, "--tls-ca", str(certs["ca_pem"]), "--output", str(tmp_path / "a.csv")],
                        capture_output=True, text=True, timeout=120)
    assert ok.returncode == 0, ok.stderr
    assert "via tls/localhost:" in ok.stderr  # the launched subsims said where they connected
    no_ca = subprocess.run([*cosim, "--output", str(tmp_path / "b.csv")], capture_output=True, text=True, timeout=60)
    assert no_ca.returncode == 2 and "need --tls-ca too" in no_ca.stderr and "Traceback" not in no_ca.stderr
    assert len(no_ca.stderr.strip().splitlines()) == 1, no_ca.stderr
    missing = subprocess.run([*cosim, "--tls-ca", str(tmp_path / "nope.pem"), "--output", str(tmp_path / "c.csv")],
                             capture_output=True, text=True, timeout=60)
    assert missing.returncode == 2 and f"--tls-ca (tls_ca in [security]): no such file: {tmp_path / 'nope.pem'}" \
        in missing.stderr


def test_a_ca_or_certificate_that_subsims_would_refuse_is_said_when_the_run_starts(
    certs: dict[str, Path], tmp_path: Path
) -> None:
    """A CA that did not sign the router's certificate, or a certificate for another address than --listen's: the
    launched subsims gave up after 10 s with a line cut mid-sentence, blaming 'login/TLS' (a multi-host probe)."""
    other = make_certs(tmp_path / "other", "IP:10.213.7.99")
    cosim = [sys.executable, "-m", "cosim.cli", "run", str(OSCILLATOR), "--stop", "0.1", "--quiet"]
    cases = [
        ([certs["router_pem"], certs["router_key"], other["ca_pem"]], "tls/localhost:0",
         f"--tls-ca {other['ca_pem']} does not vouch for --tls-cert {certs['router_pem']}: unable to get local "
         "issuer certificate"),
        ([other["router_pem"], other["router_key"], other["ca_pem"]], "tls/127.0.0.1:0",
         f"--tls-cert {other['router_pem']} is not for 127.0.0.1, the address subsims are given: IP address mismatch"),
        ([certs["router_pem"], other["router_key"], certs["ca_pem"]], "tls/localhost:0",
         f"--tls-key {other['router_key']} is not the unencrypted private key of --tls-cert {certs['router_pem']}"),
    ]
    for (cert, key, ca), listen, says in cases:
        done = subprocess.run([*cosim, "--tls-cert", str(cert), "--tls-key", str(key), "--tls-ca", str(ca),
                               "--listen", listen, "--output", str(tmp_path / "x.csv")],
                              capture_output=True, text=True, timeout=60)
        assert done.returncode == 2 and says in done.stderr and len(done.stderr.splitlines()) == 1, done.stderr
    assert not (tmp_path / "x.csv").exists()


def test_the_start_check_passes_what_zenoh_takes_and_never_prompts(certs: dict[str, Path], tmp_path: Path) -> None:
    """The check at start is Python's ssl, stricter than Zenoh's rustls: an intermediate CA given as --tls-ca (rustls
    takes any certificate of it as an anchor) was refused, though the run had worked; an encrypted key made OpenSSL
    ask for a pass phrase on the terminal, or raised OSError (red team)."""
    from certs import _openssl

    from cosim.protocol.security import tls_problem

    d = tmp_path / "chain"
    d.mkdir()
    (d / "int.ext").write_text("basicConstraints=critical,CA:TRUE\nkeyUsage=critical,keyCertSign,cRLSign\n")
    (d / "leaf.ext").write_text("subjectAltName=IP:127.0.0.1\nextendedKeyUsage=serverAuth\n")
    for who, signer, signer_key in (("int", certs["ca_pem"], certs["ca_pem"].with_name("ca.key")),
                                    ("leaf", d / "int.pem", d / "int.key")):
        _openssl("req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes", "-keyout",
                 f"{who}.key", "-out", f"{who}.csr", "-subj", f"/CN={who}", cwd=d)
        _openssl("x509", "-req", "-in", f"{who}.csr", "-CA", str(signer), "-CAkey", str(signer_key), "-CAcreateserial",
                 "-out", f"{who}.pem", "-days", "2", "-extfile", f"{who}.ext", cwd=d)
    assert tls_problem(d / "leaf.pem", d / "leaf.key", d / "int.pem", "127.0.0.1") is None  # the intermediate
    assert "does not vouch" in str(tls_problem(d / "leaf.pem", d / "leaf.key", certs["ca_pem"], "127.0.0.1"))
    _openssl("pkey", "-in", "leaf.key", "-aes256", "-passout", "pass:secret", "-out", "leaf_enc.key", cwd=d)
    done = subprocess.run([sys.executable, "-c", "import sys; from pathlib import Path; from cosim.protocol.security "
                           "import tls_problem; print(tls_problem(*map(Path, sys.argv[1:4]), '127.0.0.1'))",
                           str(d / "leaf.pem"), str(d / "leaf_enc.key"), str(d / "int.pem")],
                          stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=30)
    assert done.returncode == 0 and done.stdout.startswith(
        f"--tls-key {d / 'leaf_enc.key'} is not the unencrypted private key of --tls-cert"), done.stdout + done.stderr


@pytest.mark.parametrize("mutual", [False, True], ids=["server-cert", "mutual"])
def test_a_subsim_the_router_refuses_says_why(certs: dict[str, Path], tmp_path: Path, mutual: bool) -> None:
    """A wrong --tls-ca, none, tcp/ for a TLS router, tls/ for a plain one, no client certificate or one of another CA
    under mutual TLS, a wrong login: each said the same 'something listens there, but its login/TLS refused ours ...:
    check $COSIM_ZENOH_AUTH/--auth-file, tls/ against tcp/ and --tls-ca' after 10 s (a multi-host probe)."""
    other = make_certs(tmp_path / "other")
    ca, wrong_ca = ["--tls-ca", str(certs["ca_pem"])], ["--tls-ca", str(other["ca_pem"])]
    mine = ["--tls-cert", str(certs["subsim_pem"]), "--tls-key", str(certs["subsim_key"])] if mutual else []
    cases = [([*wrong_ca, *mine], None, f"its certificate is not signed by --tls-ca {other['ca_pem']} (unable to get "
              "local issuer certificate): get the CA certificate from the coordinator's machine"),
             (mine, None, "its certificate is not signed by a CA this machine trusts"),
             ([*ca, *mine], "tcp", "it speaks TLS there: connect with tls/localhost:"),
             ([*ca, *mine], "login", "it refused our login: $COSIM_ZENOH_AUTH (or --auth-file) must be the one")]
    if mutual:
        cases += [(ca, None, "it asks for a client certificate (mutual TLS): give --tls-cert and --tls-key"),
                  ([*ca, "--tls-cert", str(other["subsim_pem"]), "--tls-key", str(other["subsim_key"])], None,
                   f"it refused this subsim's certificate, --tls-cert {other['subsim_pem']} (")]
    with tls_bus(certs, mutual, names=["x"]) as bus:
        port = bus.endpoint.rsplit(":", 1)[1]
        for options, change, says in cases:
            env = {**os.environ, **bus.subsim_env("x")}
            if change == "login":
                env[ZENOH_AUTH_ENV] = "site:not-a-login"
            endpoint = f"tcp/localhost:{port}" if change == "tcp" else bus.endpoint
            done = subprocess.run([sys.executable, "-m", "subsims.integrator", "--connect", endpoint, "--run", bus.run,
                                   "--name", "x", "--connect-timeout", "2", *options], env=env, capture_output=True,
                                  text=True, timeout=60)
            assert done.returncode == 2 and says in done.stderr, (options, change, done.stderr)
    with Bus.open(names=["x"], listen="tcp/127.0.0.1:0") as bus:  # a plain router, and tls/ given
        port = bus.endpoint.rsplit(":", 1)[1]
        done = subprocess.run([sys.executable, "-m", "subsims.integrator", "--connect", f"tls/127.0.0.1:{port}",
                               "--run", bus.run, "--name", "x", "--connect-timeout", "2", *ca],
                              env={**os.environ, **bus.subsim_env("x")}, capture_output=True, text=True, timeout=60)
        assert done.returncode == 2 and f"it does not speak TLS there: connect with tcp/127.0.0.1:{port}" in \
            done.stderr, done.stderr


@pytest.mark.parametrize("mutual", [False, True], ids=["server-cert", "mutual"])
def test_an_external_subsims_command_never_hands_out_the_routers_key(certs: dict[str, Path], tmp_path: Path,
                                                                     mutual: bool) -> None:
    """Under mutual TLS the printed command held --tls-cert router.pem --tls-key router.key (version-skew probe): an
    operator following it copied the router's key to every site, and any site could pose as the coordinator."""
    import shlex

    from cosim.runner import attach_lines
    from cosim.scenario import load

    scenario_file = tmp_path / "o.toml"
    scenario_file.write_text(OSCILLATOR.read_text().replace("[subsims.mass2]\n", "[subsims.mass2]\nexternal = true\n"))
    with tls_bus(certs, mutual) as bus:
        text = attach_lines(bus, load(scenario_file), "mass2", None, first=True)
    command = next(line for line in text.splitlines() if "COSIM_SECRET=" in line)
    words = shlex.split(command)  # pasted into a shell as it is printed
    assert str(certs["router_key"]) not in text and str(certs["router_pem"]) not in command
    assert words[words.index("--tls-ca") + 1] == str(certs["ca_pem"])
    # a path on this machine: said so, with what to do from another (a multi-host probe)
    assert (f"(--tls-ca {certs['ca_pem']} is this machine's copy of the CA certificate: from another machine, copy "
            "it there and give its path there)") in text
    if mutual:
        assert words[words.index("--tls-cert") + 1:words.index("--tls-key") + 2] == \
            ["SITE_CERT.pem", "--tls-key", "SITE_KEY.pem"]
        assert "SITE_CERT.pem and SITE_KEY.pem stand for a certificate and key of the subsim's machine" in text
    else:
        assert "--tls-cert" not in words and "SITE_" not in text


def rustls_refused_certs(certs: dict[str, Path], directory: Path) -> dict[str, tuple[Path, Path, Path]]:
    """(certificate, key, CA) that Python's ssl verifies for localhost and 127.0.0.1 but Zenoh's TLS refuses: a
    self-signed certificate with CA:TRUE (openssl req -x509's default) as its own CA, one with CA:TRUE signed by the
    CA, one naming localhost in its CN only, one with a URI as its only subjectAltName; and, taken by both, a
    self-signed one with CA:FALSE."""
    from certs import EC, _openssl

    directory.mkdir()
    ca, ca_key = certs["ca_pem"], certs["ca_pem"].with_name("ca.key")
    sans = "subjectAltName=DNS:localhost,IP:127.0.0.1"
    made = {}
    leaf = ["-addext", "basicConstraints=critical,CA:FALSE"]
    for name, extra in (("self-signed CA", []), ("self-signed leaf", leaf)):
        stem = name.replace(" ", "_")
        _openssl("req", "-x509", *EC, "-keyout", f"{stem}.key", "-out", f"{stem}.pem", "-days", "2", "-subj",
                 "/CN=localhost", "-addext", sans, *extra, cwd=directory)
        made[name] = (directory / f"{stem}.pem", directory / f"{stem}.key", directory / f"{stem}.pem")
    for name, ext in (("signed CA", f"{sans}\nbasicConstraints=CA:TRUE\n"), ("CN only", "basicConstraints=CA:FALSE\n"),
                      ("URI only", "subjectAltName=URI:spiffe://x/y\nbasicConstraints=CA:FALSE\n")):
        stem = name.replace(" ", "_")
        (directory / f"{stem}.ext").write_text(ext)
        _openssl("req", *EC, "-keyout", f"{stem}.key", "-out", f"{stem}.csr", "-subj", "/CN=localhost", cwd=directory)
        _openssl("x509", "-req", "-in", f"{stem}.csr", "-CA", str(ca), "-CAkey", str(ca_key), "-CAcreateserial",
                 "-out", f"{stem}.pem", "-days", "2", "-extfile", f"{stem}.ext", cwd=directory)
        made[name] = (directory / f"{stem}.pem", directory / f"{stem}.key", ca)
    return made


def test_what_zenohs_tls_refuses_and_pythons_takes_is_said_at_start(certs: dict[str, Path], tmp_path: Path) -> None:
    """A CA's certificate as the router's own, or an address in the CN only: the start check (Python's ssl) passed
    them, and every subsim then failed to connect (a red team). Zenoh itself is asked first, so that the test
    follows what it takes."""
    import socket

    from cosim.protocol.security import tls_problem
    from cosim.protocol.transport.session import make_config

    made = rustls_refused_certs(certs, tmp_path / "made")
    says = {"self-signed CA": "is a CA certificate (basicConstraints CA:TRUE",
            "signed CA": "is a CA certificate (basicConstraints CA:TRUE",
            "CN only": "names no DNS name or IP address in a subjectAltName",
            "URI only": "names no DNS name or IP address in a subjectAltName"}
    for name, (cert, key, ca) in made.items():
        with socket.socket() as free:  # (a lost race for the port fails the router's open: seen at once)
            free.bind(("127.0.0.1", 0))
            port = free.getsockname()[1]
        router = make_config("router", listen=[f"tls/localhost:{port}"], extra={
            "transport/link/tls/listen_certificate": str(cert), "transport/link/tls/listen_private_key": str(key)})
        with zenoh.open(router):  # a bare router: cosim's own refuses these certificates before it opens
            client = client_config(f"tls/localhost:{port}", 2.0, security=ClientSecurity(bytes(32), tls_ca=ca))
            try:
                zenoh.open(client).close()
                connects = True
            except zenoh.ZError:
                connects = False
        assert connects is (name == "self-signed leaf"), name  # what Zenoh takes
        for host in ("localhost", None):
            problem = tls_problem(cert, key, ca, host)
            if name == "self-signed leaf":
                assert problem is None, problem
            else:
                assert problem is not None and problem.startswith(f"--tls-cert {cert} {says[name]}"), problem


def test_a_subsim_says_what_zenohs_tls_refuses_in_the_routers_certificate(certs: dict[str, Path],
                                                                           tmp_path: Path) -> None:
    """The same certificates shown by a router of another make (cosim's own refuses to start with them): the subsim's
    diagnosis, a handshake with Python's ssl, passed them and blamed its login."""
    import socket
    import ssl
    import threading

    from cosim.protocol.transport.reach import tls_cause

    made = rustls_refused_certs(certs, tmp_path / "made")
    for name, (cert, key, ca) in made.items():
        server = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
        server.load_cert_chain(cert, key)
        with socket.create_server(("127.0.0.1", 0)) as listener:
            port = listener.getsockname()[1]

            def answer(listener: socket.socket = listener, server: ssl.SSLContext = server) -> None:
                conn, _ = listener.accept()
                try:
                    with server.wrap_socket(conn, server_side=True) as tls:
                        tls.recv(1)
                except (OSError, ssl.SSLError):
                    pass

            serving = threading.Thread(target=answer, daemon=True)
            serving.start()
            said = tls_cause(f"tls/localhost:{port}", ClientSecurity(bytes(32), tls_ca=ca))
            serving.join(timeout=10)
        if name == "self-signed leaf":
            assert said.startswith("it refused our login"), said
        else:
            assert said.startswith("its certificate ") and "the coordinator's operator must change it" in said, said
            assert ("is a CA certificate" if "CA" in name else "names no DNS name or IP address") in said, said
