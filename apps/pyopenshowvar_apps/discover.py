"""``kvp discover``: find KUKAVARPROXY and C3 Bridge instances with the UDP ``WHEREAREYOU?`` query.

KVP listens on UDP 6999 and answers ``KUKA|<model>|<serial>`` to the asker's address on
UDP **7000** (not to the source port), so we send from and listen on one socket bound to
``--listen-port`` (default 7000). Proxies that answer to the sender's own port (C3 Bridge,
the emulator with ``udp_reply_port=0``) also work with ``--listen-port 0``.

C3 Bridge answers the same query in its legacy mode (UDP 6999 answering to 7000, like KVP; on
by default) and in its standard mode (UDP 7000 answering the sender's port: ask it with
``--standard-port 7000``), and it answers ``@PROXY_TYPE`` / ``@PROXY_VERSION`` /
``@PROXY_PORT`` queries, which KVP ignores: every proxy that answered is asked those, so the
table says which is which (and C3 Bridge's TCP port).

With ``kvp --emulate discover`` the embedded emulator is asked directly (it answers on an
ephemeral UDP port, to the asker's own port). Nothing answering within ``--timeout`` exits 3
with one line on stderr.
"""

from __future__ import annotations

import json
import socket
import time
from dataclasses import asdict, dataclass, replace
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
#: C3 Bridge's own UDP queries (spec §2.2, §2.3, §2.8); KVP does not answer them.
C3_QUERIES = (b"@PROXY_TYPE", b"@PROXY_VERSION", b"@PROXY_PORT")
C3_TYPE = "C3 BRIDGE INTERFACE"
#: How long to wait for the answers to the C3 queries, at most (they come in < 1 ms).
C3_WAIT = 0.3


@dataclass(frozen=True)
class Answer:
    """One proxy that answered."""

    host: str
    port: int
    model: str
    serial: str
    ms: float
    raw: str
    #: "KUKAVARPROXY" or "C3 Bridge <version>".
    proxy: str = "KUKAVARPROXY"
    #: C3 Bridge's TCP port (@PROXY_PORT); None for KVP (it serves TCP 7000).
    tcp_port: int | None = None


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
    standard_port: int = 0,
) -> list[Answer]:
    """Send the query to ``targets`` (and the broadcast address) and collect answers.

    ``standard_port`` (0: off) is C3 Bridge's standard discovery port, asked too.
    """
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        sock.bind(("", listen_port))
        dests = list(targets) + (["255.255.255.255"] if broadcast else [])
        ports = [udp_port] + (
            [standard_port] if standard_port and standard_port != udp_port else []
        )
        t0 = time.perf_counter()
        for dest in dests:
            for port in ports:
                try:
                    sock.sendto(QUERY, (dest, port))
                except OSError as exc:  # e.g. no route for broadcast in a container
                    typer.echo(
                        f"kvp: cannot send to {dest}:{port}: {exc.strerror or exc}", err=True
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
        return _merge(_identify(sock, found))
    finally:
        sock.close()


def _identify(sock: socket.socket, found: dict[tuple[str, int], Answer]) -> list[Answer]:
    """Ask every answering proxy C3 Bridge's @PROXY_* questions; KVP stays silent."""
    if not found:
        return []
    for address in found:
        for query in C3_QUERIES:
            try:
                sock.sendto(query, address)
            except OSError:
                pass
    said: dict[tuple[str, int], dict[str, str]] = {a: {} for a in found}
    deadline = time.monotonic() + C3_WAIT
    while (left := deadline - time.monotonic()) > 0 and not all(len(v) == 3 for v in said.values()):
        sock.settimeout(left)
        try:
            data, addr = sock.recvfrom(2048)
        except TimeoutError:
            break
        except OSError:
            continue
        key = (addr[0], addr[1])
        if key not in said:
            continue
        text = data.decode("latin-1", errors="replace").strip("\r\n\x00 ")
        if text == C3_TYPE:
            said[key]["type"] = text
        elif text.isdigit():
            said[key]["port"] = text
        elif text[:1].isdigit() and "." in text:
            said[key]["version"] = text
    out = []
    for key, answer in found.items():
        facts = said[key]
        if facts.get("type") != C3_TYPE:
            out.append(answer)
            continue
        version = facts.get("version", "").split(" (")[0]
        port = int(facts["port"]) if "port" in facts else None
        out.append(replace(answer, proxy=f"C3 Bridge {version}".strip(), tcp_port=port))
    return out


def _merge(answers: list[Answer]) -> list[Answer]:
    """One row per server: a C3 Bridge answers from its legacy and its standard listener."""
    rows: dict[tuple[object, ...], Answer] = {}
    for a in answers:
        key = (a.host, a.tcp_port, a.model, a.serial) if a.tcp_port else (a.host, a.port)
        rows.setdefault(key, a)
    return list(rows.values())


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
    standard_port: Annotated[
        int,
        typer.Option(
            "--standard-port",
            callback=_check_listen_port,
            help="Also ask C3 Bridge's standard discovery port (7000; it answers the sender's"
            " port). Default 0: only the legacy query, which C3 Bridge answers too.",
        ),
    ] = 0,
    as_json: Annotated[bool, typer.Option("--json", help="Print answers as JSON.")] = False,
) -> None:
    """List the KUKAVARPROXY and C3 Bridge instances that answer UDP WHEREAREYOU? (exit 3 if
    none); C3 Bridge is told apart by its @PROXY_TYPE answer."""
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
            standard_port=standard_port,
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
    for col in ("address", "proxy", "model", "serial", "ms"):
        table.add_column(col, justify="right" if col == "ms" else "left")
    for a in answers:
        where = f"{a.host}:{a.tcp_port}" if a.tcp_port else a.host
        table.add_row(where, a.proxy, a.model, a.serial, f"{a.ms:.1f}")
    Console().print(table)
