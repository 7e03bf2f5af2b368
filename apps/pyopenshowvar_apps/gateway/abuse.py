"""The attackers of ``kvp gateway``: a hostile robot and a login flood (the abuse suite's).

``tests/abuse/test_abuse_gateway.py`` and ``bench/gateway_abuse.py`` set them on the test bed
of :mod:`.testbed` (healthy robots, the gateway, a watching client):

* ``python -m pyopenshowvar_apps.gateway.abuse hostile`` (:class:`HostileProcess`) — a fake
  robot, a TCP server that answers every KVP read with a different nested STRUC of ``--size``
  characters (60 000 by default, the costliest text a KVP frame can carry) while ``on`` (a
  line on its stdin), and closes every connection while ``off`` (the gateway then sees a robot
  that is down);
* ``python -m pyopenshowvar_apps.gateway.abuse logins`` (:func:`login_flood`) — logins with a
  wrong password, one after the other, as fast as the gateway answers (at most 10 a second);
  prints ``flooding`` once it starts and its :class:`LoginTally` (JSON) at the end.

Nothing here asserts: the suite and the benchmark decide what is acceptable.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import functools
import json
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from pyopenshowvar.protocol import Mode, Request
from pyopenshowvar.testing import FakeProxy, answer

from .testbed import CLIENT_URI, PYTHON, client_certificate, expect_line

__all__ = [
    "HostileProcess",
    "LoginTally",
    "hostile_text",
    "login_flood",
    "login_once",
    "serve_hostile",
]


def hostile_text(counter: int, size: int = 60_000) -> str:
    """A nested STRUC of about ``size`` characters, different for every ``counter``."""
    return f"{{HOSTILE_T: N {counter}{_hostile_body(size)}"


@functools.cache
def _hostile_body(size: int) -> str:
    # built once: the fake robot must send faster than the gateway can parse
    member = ", M{0} {{A {0}, B {{C 1.5, D TRUE, E #ON}}, F {0}.25}}"
    parts: list[str] = []
    length, i = 0, 0
    while length < size - 80:
        part = member.format(i)
        parts.append(part)
        length += len(part)
        i += 1
    return "".join(parts) + "}"


@dataclass
class HostileTally:
    replies: int = 0
    big_replies: int = 0
    bytes_sent: int = 0


async def serve_hostile(size: int) -> None:
    """The fake robot: ``listening on HOST:PORT``, then ``on``/``off`` lines on stdin switch
    it between 60 KB replies and closed connections; at the end of stdin it prints its tally
    (JSON) and stops. (A reply's kind never changes on one connection: our client drops a
    connection whose replies change kind, as from a confused proxy.)"""
    tally = HostileTally()
    big = asyncio.Event()

    async def handler(req: Request, writer: asyncio.StreamWriter, n: int) -> None:
        if not big.is_set():
            writer.transport.abort()
            return
        if req.mode == Mode.READ:
            frame = answer(req, hostile_text(n, size).encode())
            tally.big_replies += 1
        else:
            frame = answer(req)
        tally.replies += 1
        tally.bytes_sent += len(frame)
        writer.write(frame)
        await writer.drain()

    loop = asyncio.get_running_loop()
    async with FakeProxy(handler) as port:
        print(f"listening on 127.0.0.1:{port}", flush=True)
        while line := await loop.run_in_executor(None, sys.stdin.readline):
            if line.strip() == "on":
                big.set()
            elif line.strip() == "off":
                big.clear()
    print(json.dumps(asdict(tally)), flush=True)


class HostileProcess:
    """The fake robot of :func:`serve_hostile` in its own process (its CPU is not ours)."""

    def __init__(self, size: int = 60_000) -> None:
        self.proc = subprocess.Popen(
            [PYTHON, "-m", __name__, "hostile", "--size", str(size)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
        )  # fmt: skip
        self.port = int(expect_line(self.proc, "listening on ").rpartition(":")[2])

    def big(self, on: bool) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write("on\n" if on else "off\n")
        self.proc.stdin.flush()

    def stop(self) -> dict[str, Any]:
        """Its tally (replies, big_replies, bytes_sent)."""
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.close()
        out = self.proc.stdout.read()
        self.proc.wait(20)
        return dict(json.loads(out.strip().splitlines()[-1]))


# --------------------------------------------------------------------------- logins


@dataclass
class LoginTally:
    """What the login abuser saw: every attempt ends in exactly one of the counters."""

    attempts: int = 0
    #: the gateway answered BadUserAccessDenied (checked and refused)
    denied: int = 0
    #: refused at once, before a session (BadSecurityChecksFailed: the address is locked out)
    locked: int = 0
    #: logged in: must stay 0 with a wrong password
    accepted: int = 0
    #: anything else (a timeout, an unexpected status): the abuser's own errors
    errors: int = 0
    notes: list[str] = field(default_factory=list)
    #: seconds each attempt took, by kind ("denied", "locked", ...)
    times: dict[str, list[float]] = field(default_factory=dict)


async def login_once(
    url: str, cert: Path, key: Path, user: str, password: str, tally: LoginTally
) -> None:
    """One login attempt with Basic256Sha256 Sign&Encrypt; counted in ``tally``."""
    from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256

    from . import ua
    from .ua import Client

    client = Client(url, timeout=10)
    client.application_uri = CLIENT_URI
    client.set_user(user)
    client.set_password(password)
    tally.attempts += 1
    started = time.perf_counter()
    kind = "errors"
    try:
        # set_security asks the server for its endpoints: a locked-out client fails here
        await client.set_security(
            SecurityPolicyBasic256Sha256, str(cert), str(key),
            mode=ua.MessageSecurityMode.SignAndEncrypt,
        )  # fmt: skip
        await client.connect()
        kind = "accepted"
        await client.disconnect()
    except ua.UaStatusCodeError as exc:
        kinds = {
            ua.StatusCodes.BadUserAccessDenied: "denied",
            ua.StatusCodes.BadSecurityChecksFailed: "locked",
        }
        kind = kinds.get(exc.code, "errors")
        if kind == "errors":
            tally.notes.append(f"{type(exc).__name__}: {exc}")
    except (TimeoutError, OSError, ua.UaError) as exc:
        tally.notes.append(f"{type(exc).__name__}: {exc}")
    finally:
        with contextlib.suppress(Exception):
            await client.close_secure_channel()
        with contextlib.suppress(Exception):
            client.disconnect_socket()
    setattr(tally, kind, getattr(tally, kind) + 1)
    tally.times.setdefault(kind, []).append(time.perf_counter() - started)


async def login_flood(
    url: str,
    users: Sequence[str],
    seconds: float,
    folder: Path,
    *,
    interval: float = 0.1,
    max_attempts: int = 10_000,
    on_start: Callable[[], None] | None = None,
) -> LoginTally:
    """Wrong-password logins for ``seconds``, cycling through ``users``, one at a time, a new
    one at most every ``interval`` seconds (the default, 10 a second, is more than twice the
    rate of a flood that stalled the gateway before the login checks left the event loop; a
    faster one on the same machine mostly measures the attacker's own CPU)."""
    cert, key = client_certificate(folder, CLIENT_URI)
    tally = LoginTally()
    if on_start is not None:  # ready: imports done, the key made
        on_start()
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and tally.attempts < max_attempts:
        started = time.monotonic()
        user = users[tally.attempts % len(users)]
        await login_once(url, cert, key, user, "not the password", tally)
        await asyncio.sleep(max(0.0, started + interval - time.monotonic()))
    return tally


# --------------------------------------------------------------------------- command line


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pyopenshowvar_apps.gateway.abuse")
    sub = ap.add_subparsers(dest="what", required=True)
    hostile = sub.add_parser("hostile", help="a fake robot with ~60 KB replies (stdin: on/off)")
    hostile.add_argument("--size", type=int, default=60_000)
    logins = sub.add_parser("logins", help="wrong-password logins; prints the tally (JSON)")
    logins.add_argument("url")
    logins.add_argument("--user", action="append", required=True)
    logins.add_argument("--seconds", type=float, default=5.0)
    logins.add_argument("--folder", type=Path, required=True)
    logins.add_argument("--interval", type=float, default=0.1, help="seconds between attempts")
    args = ap.parse_args(argv)
    if args.what == "hostile":
        asyncio.run(serve_hostile(args.size))
        return 0
    flood = login_flood(
        args.url, args.user, args.seconds, args.folder, interval=args.interval,
        on_start=lambda: print("flooding", flush=True),
    )  # fmt: skip
    tally = asyncio.run(flood)
    print(json.dumps(asdict(tally)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
