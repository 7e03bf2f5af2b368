"""The gateway's login rules, pinned one by one (:class:`LoginGuard`, hash formats, trust).

Users, passwords (right, wrong, missing, empty, too long), anonymous on and off, the verdict
asyncua's user-manager call reads, equal cost for every user name, the failed-login limit per
client address (threshold, ageing, reset by a success, the bound on remembered addresses,
busy refusals), trusted certificates and the hash format's bounds. A deterministic clock
stands in for time where the rule is about time.
"""

from __future__ import annotations

import asyncio
import itertools
import time
from collections.abc import Callable, Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

pytest.importorskip("asyncua")
from asyncua.crypto import cert_gen
from asyncua.crypto.permission_rules import UserRole
from asyncua.crypto.truststore import TrustStore
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID
from pyopenshowvar_apps.gateway.passwords import UserEntry
from pyopenshowvar_apps.gateway.security import (
    VERDICT,
    LoginGuard,
    Verdict,
    _digest,
    check_hash_format,
    ensure_certificate,
    hash_password,
    trust_check,
    verify_password,
)

FAST = 10_000  # the smallest iteration count the format allows: quick tests
PW = "correct horse"


class Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def clock() -> Clock:
    return Clock()


def guard(
    clock: Callable[[], float] = time.monotonic,
    *,
    users: dict[str, str] | None = None,
    anonymous: bool = False,
    **kw: object,
) -> LoginGuard:
    entries = [
        UserEntry(name, hash_password(pw, iterations=FAST))
        for name, pw in (users or {"scada": PW}).items()
    ]
    return LoginGuard(entries, anonymous=anonymous, clock=clock, **kw)  # type: ignore[arg-type]


@pytest.fixture
def g(clock: Clock) -> Iterator[LoginGuard]:
    made = guard(clock, max_failures=3, window=10.0)
    yield made
    made.close()


# ---------------------------------------------------------------------- passwords


def test_only_the_right_password_of_a_known_user_passes(g: LoginGuard) -> None:
    assert g.check("scada", PW) is True
    for user, password in [
        ("scada", PW + " "),  # a trailing character
        ("scada", PW.upper()),  # passwords are case-sensitive
        ("scada", PW[:-1]),
        ("Scada", PW),  # so are user names
        ("scada ", PW),
        ("nobody", PW),
        ("", PW),
        (None, PW),
        ("scada", None),  # a user name without a password
        ("scada", ""),
    ]:
        assert g.check(user, password) is False, (user, password)


def test_an_empty_password_never_passes_even_if_it_was_hashed() -> None:
    made = guard(users={"blank": ""})
    try:
        assert made.check("blank", "") is False
        assert made.check("blank", None) is False
    finally:
        made.close()


def test_an_overlong_password_is_refused_even_when_it_is_right() -> None:
    long_pw = "x" * 1025
    made = guard(users={"long": long_pw, "edge": "y" * 1024})
    try:
        assert made.check("long", long_pw) is False
        assert made.check("edge", "y" * 1024) is True  # 1024 characters is the limit
    finally:
        made.close()


def _cpu_pair(
    a: Callable[[], object],
    b: Callable[[], object],
    runs: int = 3,
    settled: Callable[[float, float], bool] = lambda a, b: True,
    most: int = 15,
) -> tuple[float, float]:
    """The least CPU time of ``a`` and of ``b`` on this thread, measured interleaved.

    CPU time does not count waiting, but a loaded machine still slows a run (shared caches,
    frequency, a neighbour's burst): the minimum of interleaved runs is each call's own cost
    under the same conditions. After ``runs`` rounds, more rounds (up to ``most``) are taken
    while ``settled(min_a, min_b)`` is false: the minimum only falls towards the true cost, so
    a real difference (a refusal that skips the hash) stays visible however many rounds run.
    """
    times: tuple[list[float], list[float]] = ([], [])
    for done in range(1, most + 1):
        for fn, into in ((a, times[0]), (b, times[1])):
            t0 = time.thread_time()
            fn()
            into.append(time.thread_time() - t0)
        if done >= runs and settled(min(times[0]), min(times[1])):
            break
    return min(times[0]), min(times[1])


def test_refusing_an_unknown_user_costs_what_refusing_a_known_one_does() -> None:
    entries = [
        UserEntry("strong", hash_password(PW, iterations=100_000)),
        UserEntry("weak", hash_password(PW, iterations=FAST)),  # fewer iterations: padded
    ]
    made = LoginGuard(entries, anonymous=False)
    try:
        for user, password in [
            ("nobody", "wrong"),
            ("weak", "wrong"),
            ("weak", PW),  # even a success costs the same
            ("strong", None),
            ("strong", ""),
            ("strong", "z" * 2000),
            (None, None),
        ]:
            known, cost = _cpu_pair(
                lambda: made.check("strong", "wrong"),
                lambda u=user, p=password: made.check(u, p),  # type: ignore[misc]
                settled=lambda k, c: 0.6 * k < c < 1.6 * k,
            )
            assert known > 0.005  # the measurement means something
            assert 0.6 * known < cost < 1.6 * known, (user, password, cost, known)
    finally:
        made.close()


# ---------------------------------------------------------------------- the address limit


def test_failed_logins_lock_an_address_at_the_threshold_until_they_age_out(
    g: LoginGuard, clock: Clock
) -> None:
    for i in range(2):
        g.failed("10.0.0.1")
        clock.now += 1.0
        assert not g.locked("10.0.0.1"), i
    g.failed("10.0.0.1")  # failures at 1000, 1001, 1002: the third locks
    assert g.locked("10.0.0.1")
    assert not g.locked("10.0.0.2")  # per address
    clock.now = 1009.999
    assert g.locked("10.0.0.1")
    clock.now = 1010.0  # the first failure is 10 s old: gone, two left
    assert not g.locked("10.0.0.1")
    g.failed("10.0.0.1")
    assert g.locked("10.0.0.1")
    clock.now = 1012.0  # all three aged out
    assert not g.locked("10.0.0.1")
    clock.now = 1100.0
    assert not g.locked("10.0.0.1")


def test_a_success_clears_the_failures_of_its_address(g: LoginGuard) -> None:
    g.failed("a")
    g.failed("a")
    g.failed("b")
    g.succeeded("a")
    g.failed("a")
    g.failed("a")
    assert not g.locked("a")  # two since the success, not four
    g.failed("a")
    assert g.locked("a")
    g.failed("b")
    g.failed("b")
    assert g.locked("b")  # b's failures were not cleared by a's success


def test_remembered_addresses_are_bounded(g: LoginGuard) -> None:
    g.max_addresses = 3
    for address in ("a", "b", "c", "d"):
        for _ in range(3):
            g.failed(address)
    assert not g.locked("a")  # the oldest forgotten
    assert g.locked("b") and g.locked("c") and g.locked("d")
    g.failed("b")  # b is active again: c is now the oldest
    for _ in range(3):
        g.failed("e")
    assert not g.locked("c") and g.locked("b") and g.locked("e")


async def test_login_counts_failures_and_refuses_a_locked_address_unchecked(
    g: LoginGuard, clock: Clock
) -> None:
    assert await g.login("10.0.0.9", "scada", PW) == "scada"
    for _ in range(3):
        assert await g.login("10.0.0.9", "scada", "wrong") is None
    assert g.locked("10.0.0.9")
    # the right password no longer helps from that address, and does not reset it
    assert await g.login("10.0.0.9", "scada", PW) is None
    assert g.locked("10.0.0.9")
    assert await g.login("10.0.0.8", "scada", PW) == "scada"  # another address
    clock.now += 10.0
    for _ in range(2):
        assert await g.login("10.0.0.9", "scada", "wrong") is None
    assert await g.login("10.0.0.9", "scada", PW) == "scada"
    for _ in range(2):
        assert await g.login("10.0.0.9", "scada", "wrong") is None
    assert not g.locked("10.0.0.9")  # the success cleared the two failures before it


async def test_a_busy_password_thread_refuses_without_counting_a_failure(g: LoginGuard) -> None:
    g.max_pending = 0
    for _ in range(5):
        assert await g.login("10.0.0.7", "scada", PW) is None
    assert not g.locked("10.0.0.7")
    g.max_pending = 1
    assert await g.login("10.0.0.7", "scada", PW) == "scada"


async def test_logins_wait_in_line_for_one_password_thread(g: LoginGuard) -> None:
    g.max_pending = 2
    results = await asyncio.gather(*(g.login(f"10.1.0.{i}", "scada", PW) for i in range(3)))
    assert results == ["scada", "scada", None]  # the third found two logins waiting


async def test_the_event_loop_runs_while_a_password_is_checked() -> None:
    entries = [UserEntry("scada", hash_password(PW, iterations=400_000))]
    made = LoginGuard(entries, anonymous=False)
    try:
        t0 = time.thread_time()
        made.check("scada", "wrong")
        cost = time.thread_time() - t0
        ticks: list[float] = []

        async def ticker() -> None:
            while True:
                ticks.append(time.perf_counter())
                await asyncio.sleep(0.002)

        task = asyncio.create_task(ticker())
        await asyncio.sleep(0.3)  # the baseline: what this machine's load alone does
        idle = [b - a for a, b in itertools.pairwise(ticks)]
        last = len(ticks) - 1  # the gap from the last idle tick on counts
        assert await made.login("10.0.0.1", "scada", "wrong") is None
        await asyncio.sleep(0.01)  # a tick after the login, so a stall shows as a gap
        task.cancel()
        gaps = [b - a for a, b in itertools.pairwise(ticks[last:])]
        # a check on the loop would stall it for the whole PBKDF2 (``cost`` or longer)
        assert max(gaps) < max(idle) + 0.5 * cost, (max(gaps), max(idle), cost)
    finally:
        made.close()


# ---------------------------------------------------------------------- certificates


def _cert(folder: Path, name: str, *, expired: bool = False) -> tuple[bytes, x509.Certificate]:
    key = cert_gen.generate_private_key()
    if expired:
        now = datetime.now(UTC)
        subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)])
        cert = (
            x509.CertificateBuilder()
            .subject_name(subject)
            .issuer_name(subject)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - timedelta(days=10))
            .not_valid_after(now - timedelta(days=1))
            .add_extension(
                x509.SubjectAlternativeName([x509.UniformResourceIdentifier("urn:x")]), False
            )
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), True)
            .sign(key, hashes.SHA256())
        )
    else:
        cert = cert_gen.generate_self_signed_app_certificate(
            key,
            name,
            {},
            [x509.UniformResourceIdentifier(f"urn:{name}")],
            extended=[ExtendedKeyUsageOID.CLIENT_AUTH],
        )
    der = cert.public_bytes(serialization.Encoding.DER)
    (folder / f"{name}.der").write_bytes(der)
    return der, cert


async def test_only_certificates_in_the_trusted_folder_pass(tmp_path: Path) -> None:
    trusted, elsewhere = tmp_path / "trusted", tmp_path / "other"
    trusted.mkdir()
    elsewhere.mkdir()
    good, _ = _cert(trusted, "client")
    stranger, _ = _cert(elsewhere, "stranger")
    store = TrustStore([trusted], [])
    await store.load()
    trusts = trust_check(store)
    assert trusts(good) is True
    assert trusts(stranger) is False
    assert trusts(None) is False
    assert trusts(b"") is False
    assert trusts(b"not a certificate") is False
    assert trusts(good[:-5]) is False


async def test_an_expired_certificate_fails_even_in_the_trusted_folder(tmp_path: Path) -> None:
    old, _ = _cert(tmp_path, "old", expired=True)
    store = TrustStore([tmp_path], [])
    await store.load()
    assert trust_check(store)(old) is False


async def test_login_with_an_untrusted_certificate_is_refused_and_counted(
    g: LoginGuard,
) -> None:
    seen: list[bytes | None] = []

    def trusts(der: bytes | None) -> bool:
        seen.append(der)
        return der == b"good"

    g.close()
    g = guard(trusts=trusts, max_failures=3, window=10.0)  # as the gateway makes it
    assert await g.login("a", "scada", PW, b"good") == "scada"
    assert await g.login("a", "scada", PW, b"bad") is None
    assert await g.login("a", "scada", PW, None) is None
    assert seen == [b"good", b"bad", None]
    await g.login("a", "scada", PW, b"bad")
    assert g.locked("a")  # three certificate refusals are three failures
    g.close()


async def test_without_a_trusted_folder_any_certificate_passes(g: LoginGuard) -> None:
    assert g.trusts is None
    assert await g.login("a", "scada", PW, b"anything") == "scada"
    assert await g.login("a", "scada", PW, None) == "scada"


# ---------------------------------------------------------------------- asyncua's call


def _with(verdict: Verdict | None, fn: Callable[[], object]) -> object:
    token = VERDICT.set(verdict)
    try:
        return fn()
    finally:
        VERDICT.reset(token)


def test_anonymous_sessions_only_when_anonymous_is_on() -> None:
    on, off = guard(anonymous=True), guard(anonymous=False)
    try:
        user = on.get_user(None)
        assert user is not None and user.name == "anonymous" and user.role == UserRole.User
        assert off.get_user(None) is None
        # a user name, or a password, is never taken for anonymous (nor let in unchecked)
        for kw in (
            {"username": "scada"},
            {"username": "scada", "password": ""},
            {"password": PW},
            {"username": "", "password": ""},
            {"username": "admin", "password": "admin"},
        ):
            assert on.get_user(None, **kw) is None, kw
            assert off.get_user(None, **kw) is None, kw
    finally:
        on.close()
        off.close()


def test_the_user_manager_gives_exactly_the_checked_verdict(g: LoginGuard) -> None:
    ok = Verdict("scada", _digest(PW), "scada")
    user = _with(ok, lambda: g.get_user(None, "scada", PW))
    assert user is not None and user.name == "scada"  # type: ignore[attr-defined]
    assert user.role == UserRole.User  # type: ignore[attr-defined]  # never Admin
    # the verdict of another login does not let this one in
    assert _with(ok, lambda: g.get_user(None, "scada", PW + "x")) is None
    assert _with(ok, lambda: g.get_user(None, "other", PW)) is None
    assert _with(ok, lambda: g.get_user(None, "scada", None)) is None
    refused = Verdict("scada", _digest(PW), None)
    assert _with(refused, lambda: g.get_user(None, "scada", PW)) is None
    # no verdict at all (asyncua without the gateway's hook): refused, even the right password
    assert _with(None, lambda: g.get_user(None, "scada", PW)) is None
    assert _digest(None) != _digest("")


# ---------------------------------------------------------------------- hash formats


def test_hash_format_bounds() -> None:
    good = hash_password(PW, iterations=FAST)
    scheme, iterations, salt, digest = good.split("$")
    assert scheme == "pbkdf2-sha256" and iterations == "10000"
    assert check_hash_format(good) is None
    assert hash_password(PW, iterations=FAST) != good  # a new salt every time
    import base64

    def b64(n: int) -> str:
        return base64.b64encode(b"s" * n).decode().rstrip("=")

    bad = {
        f"pbkdf2-sha1${iterations}${salt}${digest}": "expected",
        f"{iterations}${salt}${digest}": "expected",
        f"{good}$x": "expected",
        f"pbkdf2-sha256$abc${salt}${digest}": "iterations",
        f"pbkdf2-sha256$9999${salt}${digest}": "iterations",
        f"pbkdf2-sha256$2000001${salt}${digest}": "iterations",
        f"pbkdf2-sha256$-10000${salt}${digest}": "iterations",
        f"pbkdf2-sha256${iterations}$!!!!${digest}": "base64",
        f"pbkdf2-sha256${iterations}${b64(7)}${digest}": "salt",
        f"pbkdf2-sha256${iterations}${salt}${b64(31)}": "32-byte",
        f"pbkdf2-sha256${iterations}${salt}${b64(33)}": "32-byte",
        "": "expected",
    }
    for text, why in bad.items():
        problem = check_hash_format(text)
        assert problem is not None and why in problem, (text, problem)
        assert verify_password(PW, text) is False
    assert check_hash_format(f"pbkdf2-sha256$2000000${salt}${digest}") is None
    assert check_hash_format(f"pbkdf2-sha256${iterations}${b64(8)}${digest}") is None
    assert verify_password(PW, good) and not verify_password(PW + "!", good)
    assert verify_password("", hash_password("", iterations=FAST))  # the primitive itself


def test_failures_of_one_address_are_remembered_up_to_the_threshold(g: LoginGuard) -> None:
    for _ in range(100):  # a flood from one address: bounded memory, still locked
        g.failed("10.9.9.9")
    assert len(g._failures["10.9.9.9"]) == g.max_failures
    assert g.locked("10.9.9.9")


# ---------------------------------------------------------------------- the server certificate


def _san(cert_path: Path) -> x509.SubjectAlternativeName:
    cert = x509.load_der_x509_certificate(cert_path.read_bytes())
    return cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value


def test_the_server_certificate_names_the_gateway_and_lasts_ten_years(tmp_path: Path) -> None:
    import socket

    pki = tmp_path / "cell" / "pki"  # made with its parents
    cert_path, key_path, fingerprint = ensure_certificate(pki, "urn:cell:a", "10.1.2.3")
    assert (cert_path, key_path) == (pki / "gateway-cert.der", pki / "gateway-key.pem")
    cert = x509.load_der_x509_certificate(cert_path.read_bytes())
    assert fingerprint == cert.fingerprint(hashes.SHA256()).hex(":")
    subject = cert.subject
    assert subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == (
        "pyopenshowvar kvp gateway"
    )
    assert subject.get_attributes_for_oid(NameOID.ORGANIZATION_NAME)[0].value == "pyopenshowvar"
    assert cert.not_valid_after_utc - cert.not_valid_before_utc == timedelta(days=3650)
    san = _san(cert_path)
    assert socket.gethostname() in san.get_values_for_type(x509.DNSName)
    assert [str(ip) for ip in san.get_values_for_type(x509.IPAddress)] == ["10.1.2.3"]


@pytest.mark.parametrize("host", ["0.0.0.0", "::"])
def test_a_wildcard_bind_is_no_name_in_the_certificate(tmp_path: Path, host: str) -> None:
    import socket

    cert_path, _, _ = ensure_certificate(tmp_path, "urn:cell:a", host)
    san = _san(cert_path)
    assert san.get_values_for_type(x509.IPAddress) == []
    assert san.get_values_for_type(x509.DNSName) == [socket.gethostname()]


def test_a_certificate_without_alternative_names_is_replaced(tmp_path: Path) -> None:
    cert_path, key_path, _ = ensure_certificate(tmp_path, "urn:cell:a", "127.0.0.1")
    key = serialization.load_pem_private_key(key_path.read_bytes(), password=None)
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "bare")])
    now = datetime.now(UTC)
    bare = (
        x509.CertificateBuilder()
        .subject_name(subject)
        .issuer_name(subject)
        .public_key(key.public_key())  # type: ignore[arg-type]
        .serial_number(x509.random_serial_number())
        .not_valid_before(now)
        .not_valid_after(now + timedelta(days=1))
        .sign(key, hashes.SHA256())  # type: ignore[arg-type]
    )
    cert_path.write_bytes(bare.public_bytes(serialization.Encoding.DER))
    _, _, fingerprint = ensure_certificate(tmp_path, "urn:cell:a", "127.0.0.1")
    assert fingerprint != bare.fingerprint(hashes.SHA256()).hex(":")
    assert _san(cert_path).get_values_for_type(x509.UniformResourceIdentifier) == ["urn:cell:a"]


def test_a_key_that_is_not_rsa_is_refused(tmp_path: Path) -> None:
    from cryptography.hazmat.primitives.asymmetric import ec

    key = ec.generate_private_key(ec.SECP256R1())
    (tmp_path / "gateway-key.pem").write_bytes(
        key.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption(),
        )
    )
    with pytest.raises(ValueError, match=r"gateway-key\.pem: not an RSA key"):
        ensure_certificate(tmp_path, "urn:cell:a", "127.0.0.1")


def test_an_empty_user_name_never_logs_in_even_if_declared() -> None:
    made = guard(users={"": PW})
    try:
        assert made.check("", PW) is False
        assert made.check(None, PW) is False
    finally:
        made.close()


async def test_every_login_is_checked_on_the_guards_one_thread(g: LoginGuard) -> None:
    """A flood of logins takes one core: the checks queue on the guard's own thread, never
    on the event loop's default executor (which has a thread per core)."""
    import threading

    threads: set[str] = set()
    check = g.check

    def recording(username: str | None, password: str | None) -> bool:
        threads.add(threading.current_thread().name)
        return check(username, password)

    g.check = recording  # type: ignore[method-assign]
    results = await asyncio.gather(*(g.login(f"10.2.0.{i}", "scada", PW) for i in range(3)))
    assert results == ["scada"] * 3
    assert len(threads) == 1 and next(iter(threads)).startswith("gateway-login")


async def test_a_finished_login_no_longer_counts_as_waiting(g: LoginGuard) -> None:
    g.max_pending = 1
    for _ in range(3):  # one after the other: each finds none waiting
        assert await g.login("10.3.0.1", "scada", PW) == "scada"
    g.max_pending = 2
    results = await asyncio.gather(*(g.login(f"10.3.0.{i}", "scada", PW) for i in range(3)))
    assert results == ["scada", "scada", None]  # still at most two at once


def test_a_one_character_password_is_a_password() -> None:
    made = guard(users={"short": "x"})  # the cell file's hash decides, not a length rule
    try:
        assert made.check("short", "x") is True
        assert made.check("short", "y") is False
    finally:
        made.close()


async def test_closing_the_guard_drops_the_logins_still_waiting() -> None:
    """The gateway is stopping: a login that waits for the password thread is cancelled, not
    checked after the server is gone (the one being checked finishes)."""
    made = guard(users={"slow": PW})
    made._users["slow"] = hash_password(PW, iterations=200_000)  # long enough to close meanwhile
    t0 = time.perf_counter()
    first = asyncio.create_task(made.login("10.4.0.1", "slow", PW))
    second = asyncio.create_task(made.login("10.4.0.2", "slow", PW))
    async with asyncio.timeout(5):
        while made._pending < 2:  # noqa: ASYNC110 - both handed to the password thread
            await asyncio.sleep(0)
    t1 = time.perf_counter()
    made.close()  # on the event loop: it must not wait for the check that runs
    closing = time.perf_counter() - t1
    results = await asyncio.gather(first, second, return_exceptions=True)
    assert results[0] == "slow"
    assert isinstance(results[1], asyncio.CancelledError)
    assert closing < (time.perf_counter() - t0) / 2


def test_without_limits_the_guard_has_the_cell_files_defaults(clock: Clock) -> None:
    from pyopenshowvar_apps.gateway.cell import SecurityConfig

    defaults = SecurityConfig(enabled=True)
    made = LoginGuard([], anonymous=False, clock=clock)
    try:
        for _ in range(defaults.max_failed_logins - 1):
            made.failed("10.5.0.1")
        assert not made.locked("10.5.0.1")
        made.failed("10.5.0.1")
        assert made.locked("10.5.0.1")
        clock.now += defaults.lockout_seconds - 0.001
        assert made.locked("10.5.0.1")
        clock.now += 0.001
        assert not made.locked("10.5.0.1")
    finally:
        made.close()


def test_a_guard_without_users_refuses_every_login() -> None:
    made = LoginGuard([], anonymous=False)
    try:
        assert made.cost == 200_000  # the cost of a login: that of a default hash
        assert made.check("scada", PW) is False
    finally:
        made.close()


def test_a_hash_has_a_16_byte_salt_and_a_bad_one_is_named_exactly() -> None:
    import base64

    _, _, salt, digest = hash_password(PW, iterations=FAST).split("$")
    assert "=" not in salt + digest  # unpadded base64, as the format shows it
    assert len(base64.b64decode(salt + "==")) == 16 and len(base64.b64decode(digest + "=")) == 32
    # what the cell file's check says (kvp gateway prints it with the user's entry)
    assert check_hash_format(f"pbkdf2-sha256$10000$!!!!${digest}") == (
        "salt and hash must be base64"
    )
    assert check_hash_format(f"pbkdf2-sha256$10000${salt}${salt}") == (
        "salt of at least 8 bytes and a 32-byte hash expected"
    )
    assert check_hash_format("pbkdf2-sha256$1$a$b") == "iterations must be within 10000..2000000"
    assert check_hash_format("x") == "expected pbkdf2-sha256$ITERATIONS$SALT$HASH"


def test_unpadded_base64_round_trips_whatever_its_last_character() -> None:
    from pyopenshowvar_apps.gateway.passwords import b64, unb64

    for data in (b"\x00\x00\x17", b"\x00\x00\x17\x00", b"\xff" * 16, b"", b"a"):
        text = b64(data)
        assert "=" not in text and unb64(text) == data, (data, text)
    assert b64(b"\x00\x00\x17") == "AAAX"
