"""``kvp discover``: find KUKAVARPROXY instances with the UDP ``WHEREAREYOU?`` query.

KVP listens on UDP 6999 and answers ``KUKA|<model>|<serial>`` to the asker's address on
UDP **7000** (not to the source port), so we send from and listen on one socket bound to
``--listen-port`` (default 7000). Proxies that answer to the sender's own port (C3 Bridge,
the emulator with ``udp_reply_port=0``) also work with ``--listen-port 0``.

With ``kvp --emulate discover`` the embedded emulator is asked directly (it answers on an
ephemeral UDP port, to the asker's own port). Nothing answering within ``--timeout`` exits 3
with one line on stderr.
"""

from __future__ import annotations

import json
import socket
import time
from dataclasses import asdict, dataclass
from typing import Annotated

import typer

from pyopenshowvar_apps.common import (
    EXIT_CONNECTION,
    Opts,
    check_port,
    check_seconds,
    fail,
    start_embedded_emulator,
)

QUERY = b"WHEREAREYOU?"


@dataclass(frozen=True)
class Answer:
    """One proxy that answered."""

    host: str
    port: int
    model: str
    serial: str
    ms: float
    raw: str


def parse_answer(data: bytes) -> tuple[str, str] | None:
    """``KUKA|model|serial`` → (model, serial); None for anything else."""
    text = data.decode("latin-1", errors="replace").strip("\r\n\x00 ")
    parts = text.split("|")
    if len(parts) < 3 or parts[0].upper() != "KUKA":
        return None
    return parts[1], "|".join(parts[2:])


def discover_proxies(
    targets: list[str],
    *,
    broadcast: bool,
    udp_port: int = 6999,
    listen_port: int = 7000,
    timeout: float = 1.0,
) -> list[Answer]:
    """Send the query to ``targets`` (and the broadcast address) and collect answers."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        sock.bind(("", listen_port))
        dests = list(targets) + (["255.255.255.255"] if broadcast else [])
        t0 = time.perf_counter()
        for dest in dests:
            try:
                sock.sendto(QUERY, (dest, udp_port))
            except OSError as exc:  # e.g. no route for broadcast in a container
                typer.echo(
                    f"kvp: cannot send to {dest}:{udp_port}: {exc.strerror or exc}", err=True
                )
        found: dict[tuple[str, int], Answer] = {}
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            sock.settimeout(left)
            try:
                data, addr = sock.recvfrom(2048)
            except TimeoutError:
                break
            except OSError:  # ICMP port unreachable from a unicast target
                continue
            parsed = parse_answer(data)
            if parsed is None or (addr[0], addr[1]) in found:
                continue
            ms = (time.perf_counter() - t0) * 1e3
            found[(addr[0], addr[1])] = Answer(
                addr[0], addr[1], parsed[0], parsed[1], ms, data.decode("latin-1")
            )
        return list(found.values())
    finally:
        sock.close()


def _check_listen_port(value: int) -> int:
    return value if value == 0 else check_port(value)


def discover(
    to: Annotated[
        list[str] | None,
        typer.Option("--to", help="Ask this host directly (repeatable); default: broadcast only."),
    ] = None,
    broadcast: Annotated[
        bool | None,
        typer.Option(
            "--broadcast/--no-broadcast",
            help="Also broadcast to 255.255.255.255 (default: on unless --to is given).",
        ),
    ] = None,
    udp_port: Annotated[
        int, typer.Option("--udp-port", callback=check_port, help="Proxies' discovery port.")
    ] = 6999,
    listen_port: Annotated[
        int,
        typer.Option(
            "--listen-port",
            callback=_check_listen_port,
            help="Local UDP port for answers (KVP answers to 7000; 0: any free port).",
        ),
    ] = 7000,
    timeout: Annotated[
        float,
        typer.Option(
            "--timeout", "-t", callback=check_seconds, help="Seconds to wait for answers."
        ),
    ] = 1.0,
    as_json: Annotated[bool, typer.Option("--json", help="Print answers as JSON.")] = False,
) -> None:
    """List the KUKAVARPROXY instances that answer UDP WHEREAREYOU? (exit 3 if none)."""
    targets = list(to or [])
    do_broadcast = broadcast if broadcast is not None else not targets
    if Opts.emulate:  # the embedded emulator answers on its own UDP port, to ours
        emulator = start_embedded_emulator()
        targets, do_broadcast = ["127.0.0.1"], False
        udp_port, listen_port = emulator.emulator.udp_port, 0
    try:
        answers = discover_proxies(
            targets,
            broadcast=do_broadcast,
            udp_port=udp_port,
            listen_port=listen_port,
            timeout=timeout,
        )
    except OSError as exc:
        hint = " (try --listen-port 0 for proxies that answer the sender's port)"
        fail(EXIT_CONNECTION, f"cannot listen on UDP {listen_port}: {exc.strerror or exc}{hint}")
    asked = ", ".join(targets + (["broadcast"] if do_broadcast else []))
    if not answers:
        fail(EXIT_CONNECTION, f"no proxy answered WHEREAREYOU? ({asked}, UDP {udp_port})")
    if as_json:
        typer.echo(json.dumps([asdict(a) for a in answers], indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    what = "1 proxy" if len(answers) == 1 else f"{len(answers)} proxies"
    table = Table(title=f"{what} answered ({asked})", title_justify="left")
    for col in ("address", "model", "serial", "ms"):
        table.add_column(col, justify="right" if col == "ms" else "left")
    for a in answers:
        table.add_row(a.host, a.model, a.serial, f"{a.ms:.1f}")
    Console().print(table)
