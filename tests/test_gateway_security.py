"""``kvp gateway`` as a command, with security on: who gets in and who does not.

The real command in a subprocess (its first line is ``serving opc.tcp://HOST:PORT``), an
emulated KRC in this process, and asyncua clients that try: no security at all, encryption
without a user, a wrong password, and finally the right one.
"""

from __future__ import annotations

import asyncio
import re
import signal
import sys
from collections.abc import Awaitable
from pathlib import Path

import pytest

pytest.importorskip("asyncua")
from asyncua import Client as UaClient
from asyncua import ua
from asyncua.crypto import cert_gen
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from cryptography.hazmat.primitives import serialization
from cryptography.x509.oid import ExtendedKeyUsageOID
from pyopenshowvar_apps.gateway.model import GATEWAY_URI
from pyopenshowvar_apps.gateway.security import hash_password

from kukavarproxy_emu import Emulator, EmulatorConfig

CLIENT_URI = "urn:pyopenshowvar:test-client"


def _client_certificate(folder: Path, name: str = "client") -> tuple[Path, Path]:
    key = cert_gen.generate_private_key()
    cert = cert_gen.generate_self_signed_app_certificate(
        key,
        "test client",
        {},
        [cert_gen.x509.UniformResourceIdentifier(CLIENT_URI)],
        extended=[ExtendedKeyUsageOID.CLIENT_AUTH],
    )
    cert_path, key_path = folder / f"{name}-cert.der", folder / f"{name}-key.pem"
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.DER))
    key_path.write_bytes(cert_gen.dump_private_key_as_pem(key))
    return cert_path, key_path


async def _secure_client(
    url: str, cert: Path, key: Path, user: str | None, password: str | None
) -> UaClient:
    client = UaClient(url, timeout=10)
    client.application_uri = CLIENT_URI
    await client.set_security(
        SecurityPolicyBasic256Sha256,
        str(cert),
        str(key),
        mode=ua.MessageSecurityMode.SignAndEncrypt,
    )
    if user is not None:
        client.set_user(user)
        client.set_password(password or "")
    return client


@pytest.mark.timeout(120)
async def test_secured_gateway_refuses_anonymous_and_unencrypted_clients(tmp_path: Path) -> None:
    async with Emulator(
        EmulatorConfig(port=0, discovery=False, idle_timeout=0, plant="ideal")
    ) as emu:
        secret = "correct horse battery"
        # only this client's certificate is trusted (security.trusted_clients)
        trusted = tmp_path / "trusted"
        trusted.mkdir()
        cert, key = _client_certificate(tmp_path)
        (trusted / cert.name).write_bytes(cert.read_bytes())
        stranger_cert, stranger_key = _client_certificate(tmp_path, "stranger")
        cell = tmp_path / "cell.toml"
        cell.write_text(
            '[cell]\nname = "secure"\nendpoint = "opc.tcp://127.0.0.1:0"\n'
            '[security]\ntrusted_clients = "trusted"\n'
            f'users = [{{ name = "scada", password_hash = "{hash_password(secret, iterations=10_000)}" }}]\n'
            f'[[robot]]\nname = "r1"\nhost = "127.0.0.1"\nport = {emu.port}\n'
        )
        proc = await asyncio.create_subprocess_exec(
            sys.executable,
            "-c",
            "from pyopenshowvar_apps.cli import main; main()",
            "gateway",
            str(cell),
            "--log-level",
            "warning",
            stdout=asyncio.subprocess.PIPE,
        )
        assert proc.stdout is not None
        try:
            first = (await asyncio.wait_for(proc.stdout.readline(), 90)).decode().strip()
            m = re.fullmatch(r"serving (opc\.tcp://127\.0\.0\.1:(\d+))", first)
            assert m and int(m.group(2)) > 0, first
            url = m.group(1)
            second = (await asyncio.wait_for(proc.stdout.readline(), 10)).decode()
            assert re.fullmatch(r"certificate SHA-256 ([0-9a-f]{2}:){31}[0-9a-f]{2}\n", second)
            assert (tmp_path / "pki" / "gateway-key.pem").stat().st_mode & 0o077 == 0

            # 1. no security, no user: the server offers no such endpoint
            plain = UaClient(url, timeout=10)
            with pytest.raises((ua.UaError, OSError, TimeoutError)):
                await plain.connect()
            endpoints = await UaClient(url, timeout=10).connect_and_get_server_endpoints()
            assert {e.SecurityPolicyUri.rsplit("#", 1)[1] for e in endpoints} == {"Basic256Sha256"}
            assert {e.SecurityMode for e in endpoints} == {ua.MessageSecurityMode.SignAndEncrypt}
            tokens = {t.TokenType for e in endpoints for t in e.UserIdentityTokens}
            assert tokens == {ua.UserTokenType.UserName}

            # 2. encrypted but anonymous, 3. a wrong password or user, 4. the right password
            # from a client whose certificate is not trusted: all refused
            attempts = [
                (cert, key, None, None),
                (cert, key, "scada", "wrong password"),
                (cert, key, "nobody", secret),
                (stranger_cert, stranger_key, "scada", secret),
            ]
            for c, k, user, password in attempts:
                client = await _secure_client(url, c, k, user, password)
                with pytest.raises((ua.UaError, OSError, TimeoutError)):
                    await client.connect()
                    await client.disconnect()  # pragma: no cover - only if it got in
            # 5. the trusted client with the right user and password: in, and the robot is there
            client = await _secure_client(url, cert, key, "scada", secret)
            async with client:
                ours = await client.get_namespace_index(GATEWAY_URI)
                model = client.get_node(ua.NodeId("secure.MotionDevices.r1.Model", ours))
                for _ in range(100):
                    dv = await model.read_data_value(raise_on_bad_status=False)
                    if (
                        dv.StatusCode.is_good()
                        and dv.Value.Value is not None
                        and dv.Value.Value.Text
                    ):
                        break
                    await asyncio.sleep(0.1)
                assert dv.Value.Value.Text == "KR6R900SIXX C4SR FLR"
        finally:
            if proc.returncode is None:
                proc.send_signal(signal.SIGTERM)
            assert await asyncio.wait_for(proc.wait(), 30) == 0


def _blank_create_session_certificate(client: UaClient) -> None:
    """A client that leaves its certificate out of CreateSession (the channel still has it):
    asyncua's own trust check looks only at that copy."""
    original = client.uaclient.create_session

    async def create_session(params: ua.CreateSessionParameters) -> object:
        params.ClientCertificate = None
        return await original(params)

    client.uaclient.create_session = create_session  # type: ignore[method-assign]


async def _refused(make: Awaitable[UaClient], tamper: bool = False) -> bool:
    """Whether a login is refused (setting the client up already asks for the endpoints)."""
    try:
        client = await make
        if tamper:
            _blank_create_session_certificate(client)
        await client.connect()
    except (ua.UaError, OSError, TimeoutError, asyncio.IncompleteReadError):
        return True
    await client.disconnect()
    return False


@pytest.mark.timeout(120)
async def test_logins_checked_on_the_channel_certificate_and_limited_per_address(
    tmp_path: Path,
) -> None:
    from pyopenshowvar_apps.gateway.cell import load_cell
    from pyopenshowvar_apps.gateway.server import Gateway

    async with Emulator(
        EmulatorConfig(port=0, discovery=False, idle_timeout=0, plant="ideal")
    ) as emu:
        secret = "correct horse battery"
        trusted = tmp_path / "trusted"
        trusted.mkdir()
        cert, key = _client_certificate(tmp_path)
        (trusted / cert.name).write_bytes(cert.read_bytes())
        stranger_cert, stranger_key = _client_certificate(tmp_path, "stranger")
        cell = tmp_path / "cell.toml"
        digest = hash_password(secret, iterations=10_000)
        cell.write_text(
            '[cell]\nname = "secure"\nendpoint = "opc.tcp://127.0.0.1:0"\n'
            '[security]\ntrusted_clients = "trusted"\nmax_failed_logins = 2\n'
            f'lockout_seconds = 2\nusers = [{{ name = "scada", password_hash = "{digest}" }}]\n'
            f'[[robot]]\nname = "r1"\nhost = "127.0.0.1"\nport = {emu.port}\n'
        )
        async with Gateway(load_cell(cell)) as gw:
            # 1. an untrusted certificate, the right password, and no certificate in
            # CreateSession: refused (the channel's certificate is what counts)
            sneaky = _secure_client(gw.url, stranger_cert, stranger_key, "scada", secret)
            assert await _refused(sneaky, tamper=True)
            # the trusted client gets in the same way, so it was the certificate
            honest = _secure_client(gw.url, cert, key, "scada", secret)
            assert not await _refused(honest, tamper=True)
            # 2. two failed logins lock 127.0.0.1 out: even the right password is refused,
            # its connection closed before a session
            for _ in range(2):  # (the success above cleared the certificate's failure)
                assert not gw.guard.locked("127.0.0.1")
                assert await _refused(_secure_client(gw.url, cert, key, "scada", "x"))
            assert gw.guard.locked("127.0.0.1")
            assert await _refused(_secure_client(gw.url, cert, key, "scada", secret))
            # 3. once the failures are lockout_seconds old, the address may log in again
            await asyncio.sleep(2.1)
            assert not gw.guard.locked("127.0.0.1")
            assert not await _refused(_secure_client(gw.url, cert, key, "scada", secret))
