"""`windowshop serve --certfile --keyfile`: the page over HTTPS, as a phone on the local network
needs it to open its camera (docs/capture.md)."""

from __future__ import annotations

import os
import shutil
import ssl
import subprocess
import sys
import time

import httpx
import pytest

from service_helpers import free_port

pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl is absent")


def self_signed(folder):
    cert, key = folder / "cert.pem", folder / "key.pem"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", str(key),
                    "-out", str(cert), "-days", "2", "-subj", "/CN=windowshop",
                    "-addext", "subjectAltName=IP:127.0.0.1"], check=True, capture_output=True)
    return cert, key


def serve(*flags, data):
    return subprocess.Popen([sys.executable, "-m", "windowshop", "serve", "--data", str(data), *flags],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, "WINDOWSHOP_CONCURRENCY": "1"})


def test_serve_speaks_https_with_the_certificate_given(tmp_path):
    cert, key = self_signed(tmp_path)
    port = free_port()
    process = serve("--port", str(port), "--certfile", str(cert), "--keyfile", str(key),
                    data=tmp_path / "data")
    trusted = ssl.create_default_context(cafile=str(cert))  # the certificate checked, not skipped
    try:
        deadline, page = time.monotonic() + 60, None
        while page is None:
            assert process.poll() is None, process.stdout.read()
            assert time.monotonic() < deadline, "the service did not come up"
            try:
                page = httpx.get(f"https://127.0.0.1:{port}/", verify=trusted, timeout=2)
            except httpx.TransportError:
                time.sleep(0.3)
        assert page.status_code == 200 and "windowshop" in page.text
        with pytest.raises(httpx.TransportError):  # plain HTTP is not spoken on that port
            httpx.get(f"http://127.0.0.1:{port}/api/health", timeout=2)
    finally:
        process.terminate()
        output = process.communicate(timeout=30)[0]
    assert f"serving https://127.0.0.1:{port}/" in output


def test_a_certificate_without_its_key_is_refused_with_what_to_give(tmp_path):
    cert, _ = self_signed(tmp_path)
    process = serve("--port", str(free_port()), "--certfile", str(cert), data=tmp_path / "data")
    output = process.communicate(timeout=60)[0]
    assert process.returncode != 0
    assert "HTTPS needs both --certfile and --keyfile" in output
