"""TLS (openssl-made certificates, as tests/util/test_pki.cc makes them), mTLS and bearer
tokens against nupmpc-server started with --tls_* and --auth_tokens_file."""

import subprocess

import pytest

import nupmpc
from conftest import ServerProcess

TOKEN = "py-client-token-0123456789"
NEW_KEY = ["openssl", "req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]


def _run(args):
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


@pytest.fixture(scope="module")
def pki(tmp_path_factory):
    d = tmp_path_factory.mktemp("pki")
    _run(NEW_KEY + ["-x509", "-days", "2", "-keyout", d / "ca.key", "-out", d / "ca.pem", "-subj", "/CN=nupmpc-test-ca"])

    def issue(name, subject, server):
        (d / f"{name}.ext").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\nextendedKeyUsage=serverAuth\n"
                                       if server else "extendedKeyUsage=clientAuth\n")
        _run(NEW_KEY + ["-keyout", d / f"{name}.key", "-out", d / f"{name}.csr", "-subj", subject])
        _run(["openssl", "x509", "-req", "-days", "2", "-in", d / f"{name}.csr", "-CA", d / "ca.pem", "-CAkey",
              d / "ca.key", "-CAcreateserial", "-out", d / f"{name}.pem", "-extfile", d / f"{name}.ext"])
        return str(d / f"{name}.pem"), str(d / f"{name}.key")

    issue("server", "/CN=localhost", True)
    issue("client", "/CN=python-client/O=nupmpc-tests", False)
    return d


def _solves(client, masses):
    return client.solve_once(masses.spec).converged and client.session(masses.problem).step(
        masses.closed_loop_states[0]).converged


def test_a_token_reaches_a_server_with_auth_tokens_on_loopback(tmp_path, masses):
    tokens = tmp_path / "tokens"
    tokens.write_text(f"{TOKEN} python-tests\n")
    server = ServerProcess("--auth_tokens_file", str(tokens))
    try:
        with nupmpc.connect(server.target, token=TOKEN) as client:
            assert _solves(client, masses)
        with nupmpc.connect(server.target) as client:
            with pytest.raises(nupmpc.Unauthenticated) as caught:
                client.solve_once(masses.spec)
            assert caught.value.code.name == "UNAUTHENTICATED"
        with nupmpc.connect(server.target, token="not-the-token-0123456789") as client:
            with pytest.raises(nupmpc.Unauthenticated):
                client.session(masses.problem)
    finally:
        server.stop()


def test_a_token_is_not_sent_in_clear_text_to_a_remote_target():
    with pytest.raises(ValueError) as caught:
        nupmpc.connect("plant-gw.example:50051", token=TOKEN)
    assert str(caught.value).startswith("token:")


def test_tls_and_mtls_with_openssl_made_certificates(pki, tmp_path, masses):
    tokens = tmp_path / "tokens"
    tokens.write_text(f"{TOKEN} python-tests\n")
    server = ServerProcess("--tls_cert_file", str(pki / "server.pem"), "--tls_key_file", str(pki / "server.key"),
                           "--auth_tokens_file", str(tokens))
    try:
        with nupmpc.connect(server.target, ca_file=str(pki / "ca.pem"), token=TOKEN) as client:
            assert _solves(client, masses)
        # The certificate names localhost and 127.0.0.1: another name is refused.
        with nupmpc.connect(server.target, ca_file=str(pki / "ca.pem"), token=TOKEN, server_name="elsewhere",
                            deadline_s=5) as client:
            with pytest.raises(nupmpc.Unavailable):
                client.solve_once(masses.spec)
        # Plaintext to a TLS port fails.
        with nupmpc.connect(server.target, deadline_s=5) as client:
            with pytest.raises(nupmpc.Unavailable):
                client.solve_once(masses.spec)
    finally:
        server.stop()
    mutual = ServerProcess("--tls_cert_file", str(pki / "server.pem"), "--tls_key_file", str(pki / "server.key"),
                           "--tls_client_ca_file", str(pki / "ca.pem"))
    try:
        with nupmpc.connect(mutual.target, ca_file=str(pki / "ca.pem"), cert_file=str(pki / "client.pem"),
                            key_file=str(pki / "client.key")) as client:
            assert _solves(client, masses)
        with nupmpc.connect(mutual.target, ca_file=str(pki / "ca.pem"), deadline_s=5) as client:
            with pytest.raises(nupmpc.Unavailable):  # no client certificate: the handshake fails
                client.solve_once(masses.spec)
    finally:
        mutual.stop()


def test_unreadable_security_files_are_named():
    with pytest.raises(ValueError) as caught:
        nupmpc.connect("localhost:1", ca_file="/nonexistent/ca.pem")
    assert str(caught.value).startswith("ca_file /nonexistent/ca.pem: cannot be read")
    with pytest.raises(ValueError) as caught:
        nupmpc.connect("localhost:1", cert_file="/nonexistent/c.pem")
    assert "cert_file and key_file" in str(caught.value)
