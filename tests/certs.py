"""Test certificates made with the openssl command line (the commands of docs/reliability.md)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

EC = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]


def _openssl(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True, timeout=60)


def make_certs(directory: Path, alt_names: str = "DNS:localhost,IP:127.0.0.1") -> dict[str, Path]:
    """A CA, a router certificate for ``alt_names`` and a client certificate, all signed by the CA."""
    if shutil.which("openssl") is None:
        pytest.skip("the openssl command is needed to make test certificates")
    directory.mkdir(parents=True, exist_ok=True)
    _openssl("req", "-x509", *EC, "-keyout", "ca.key", "-out", "ca.pem", "-days", "2", "-subj", "/CN=cosim test CA",
             "-addext", "basicConstraints=critical,CA:TRUE", "-addext", "keyUsage=critical,keyCertSign,cRLSign",
             cwd=directory)
    for who, sans, usage in (("router", alt_names, "serverAuth,clientAuth"), ("subsim", "DNS:subsim", "clientAuth")):
        (directory / f"{who}.ext").write_text(
            f"subjectAltName={sans}\nextendedKeyUsage={usage}\nbasicConstraints=CA:FALSE\n")
        _openssl("req", *EC, "-keyout", f"{who}.key", "-out", f"{who}.csr", "-subj", f"/CN=cosim {who}",
                 cwd=directory)
        _openssl("x509", "-req", "-in", f"{who}.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial",
                 "-out", f"{who}.pem", "-days", "2", "-extfile", f"{who}.ext", cwd=directory)
    names = ["ca.pem", "router.pem", "router.key", "subsim.pem", "subsim.key"]
    return {n.replace(".", "_"): directory / n for n in names}
