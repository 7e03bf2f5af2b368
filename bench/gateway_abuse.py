"""``kvp gateway`` under attack: what a hostile robot and a login flood do to the healthy robots.

    .venv/bin/python bench/gateway_abuse.py                 # both scenarios, 8 s phases
    .venv/bin/python bench/gateway_abuse.py --only hostile --seconds 15
    .venv/bin/python bench/gateway_abuse.py --quick         # 2 s phases (smoke test)

Everything runs as its own process: healthy robots (real emulators running a program that
never stops moving), the real ``kvp gateway`` command, the attackers, and this script's OPC UA
client, which subscribes to the healthy robots' axes and reads a node every 20 ms
(``pyopenshowvar_apps.gateway.testbed``; the attackers are in ``.abuse``). Each scenario
measures a baseline phase and then an attack phase on the same gateway:

* **hostile** — one more robot in the cell is a fake one polled at 50 Hz; in the attack phase
  it answers every read with a different ~60 KB nested STRUC;
* **logins** — security on (PBKDF2 with 200 000 iterations, as ``--hash-password`` makes);
  in the attack phase another process logs in with a wrong password over and over. Before
  that, a separate gateway measures how long a refusal takes for a user that exists and for
  one that does not (with the rate limit raised where the gateway has one, so every attempt
  is checked).

Figures: the healthy robots' update gap (between consecutive SourceTimestamps; at 10 Hz the
nominal gap is 100 ms), the OPC UA read round trip, the gateway's CPU and its peak resident
memory during each phase. Targets: gap p99 ≤ 150 ms, read p99 ≤ 50 ms under attack.
"""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import Row, base_parser, machine_info, print_rows, write_json
from pyopenshowvar_apps.gateway.abuse import HostileProcess, LoginTally, login_once
from pyopenshowvar_apps.gateway.cell import CellError, parse_cell
from pyopenshowvar_apps.gateway.security import hash_password
from pyopenshowvar_apps.gateway.testbed import (
    CLIENT_URI,
    CellProcess,
    GatewayProcess,
    Watch,
    cell_file,
    client_certificate,
    measure,
    open_client,
    percentile,
)

SECRET = "correct horse battery"
USER = "scada"


def _security(extra: str = "") -> str:
    digest = hash_password(SECRET)
    return f'[security]\nusers = [{{ name = "{USER}", password_hash = "{digest}" }}]\n{extra}'


def _supports(key: str, value: str) -> bool:
    """Whether this gateway's cell file knows ``[security] key`` (the rate limit's knob)."""
    digest = hash_password(SECRET, iterations=10_000)
    data = {
        "security": {"users": [{"name": USER, "password_hash": digest}], key: int(value)},
        "robot": [{"name": "r", "host": "127.0.0.1"}],
    }
    try:
        parse_cell(data)
    except CellError:
        return False
    return True


async def hostile(robots: int, seconds: float, folder: Path, size: int) -> dict[str, Any]:
    cell_proc, bad = CellProcess(robots, folder), HostileProcess(size)
    gw = GatewayProcess(cell_file(folder, cell_proc.ports, [bad.port]), folder / "gw.log")
    try:
        client = await open_client(gw, folder)
        watch = Watch(client, "abuse", [f"r{i}" for i in range(1, robots + 1)])
        await watch.start()
        await asyncio.sleep(2.0)  # every robot connected and polling
        base = await measure(gw, watch, seconds)
        bad.big(True)
        await asyncio.sleep(2.5)  # the gateway's reconnect backoff is at most 2.4 s
        attack = await measure(gw, watch, seconds)
        bad.big(False)
        await watch.stop()
        await client.disconnect()
    finally:
        gw.stop()
        tally = bad.stop()
        cell_proc.stop()
    return {"baseline": base, "attack": attack, "hostile": tally, "log": _log_tail(gw)}


async def _oracle(robots: int, folder: Path, rounds: int) -> dict[str, Any]:
    """Refusal times for an existing and an unknown user, alternating."""
    cell_proc = CellProcess(robots, folder)
    raise_limit = "max_failed_logins = 100000\n" if _supports("max_failed_logins", "1000") else ""
    gw = GatewayProcess(
        cell_file(folder, cell_proc.ports, security=_security(raise_limit)),
        folder / "gw-oracle.log",
    )
    cert, key = client_certificate(folder, CLIENT_URI)
    known, unknown = LoginTally(), LoginTally()
    try:
        for _ in range(rounds):
            await login_once(gw.url, cert, key, USER, "not the password", known)
            await login_once(gw.url, cert, key, "nobody", "not the password", unknown)
    finally:
        gw.stop()
        cell_proc.stop()
    return {
        "known_ms": sorted(t * 1e3 for t in known.times.get("denied", [])),
        "unknown_ms": sorted(t * 1e3 for t in unknown.times.get("denied", [])),
        "known": known.attempts,
        "unknown": unknown.attempts,
        "errors": known.errors + unknown.errors,
    }


async def logins(robots: int, seconds: float, folder: Path, rounds: int) -> dict[str, Any]:
    oracle = await _oracle(robots, folder, rounds)
    cell_proc = CellProcess(robots, folder)
    gw = GatewayProcess(cell_file(folder, cell_proc.ports, security=_security()), folder / "gw.log")
    try:
        client = await open_client(gw, folder, USER, SECRET)
        watch = Watch(client, "abuse", [f"r{i}" for i in range(1, robots + 1)])
        await watch.start()
        await asyncio.sleep(2.0)
        base = await measure(gw, watch, seconds)
        flood = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "pyopenshowvar_apps.gateway.abuse", "logins", gw.url,
            "--user", USER, "--user", "nobody", "--seconds", str(seconds),
            "--folder", str(folder),
            stdout=subprocess.PIPE,
        )  # fmt: skip
        attack = await measure(gw, watch, seconds)
        out, _ = await asyncio.wait_for(flood.communicate(), 60)
        tally = json.loads(out.decode().strip().splitlines()[-1])
        tally.pop("times", None)
        await watch.stop()
        await client.disconnect()
    finally:
        gw.stop()
        cell_proc.stop()
    return {"baseline": base, "attack": attack, "flood": tally, "oracle": oracle}


def _log_tail(gw: GatewayProcess) -> str:
    return "\n".join(gw.log.read_text().splitlines()[-5:])


def _rows(name: str, r: dict[str, Any]) -> list[Row]:
    rows = []
    for phase in ("baseline", "attack"):
        p = r[phase]
        target = phase == "attack"
        rows += [
            Row(f"{name} {phase}: update gap p50", p["gap_p50"], "ms"),
            Row(
                f"{name} {phase}: update gap p99",
                p["gap_p99"],
                "ms",
                target=("ours", "<=", 150.0) if target else None,
            ),
            Row(f"{name} {phase}: update gap max", p["gap_max"], "ms", note=f"{p['gaps']} gaps"),
            Row(f"{name} {phase}: read p50", p["read_p50"], "ms"),
            Row(
                f"{name} {phase}: read p99",
                p["read_p99"],
                "ms",
                target=("ours", "<=", 50.0) if target else None,
            ),
            Row(f"{name} {phase}: read max", p["read_max"], "ms", note=f"{p['reads']} reads"),
            Row(f"{name} {phase}: gateway CPU", p["cpu_pct"], "%", note="of one core"),
            Row(f"{name} {phase}: gateway peak RSS", p["peak_rss_mb"], "MB"),
        ]
    return rows


def main() -> None:
    ap = base_parser(__doc__)
    ap.add_argument("--only", choices=["hostile", "logins"], help="one scenario")
    ap.add_argument("--robots", type=int, default=3, help="healthy robots (10 Hz)")
    ap.add_argument("--seconds", type=float, default=8.0, help="length of each phase")
    ap.add_argument("--rounds", type=int, default=6, help="refusals timed per user kind")
    ap.add_argument(
        "--hostile-size", type=int, default=60_000, help="characters of each hostile reply"
    )
    args = ap.parse_args()
    seconds = 2.0 if args.quick else args.seconds
    rounds = 2 if args.quick else args.rounds
    rows: list[Row] = []
    extra: dict[str, Any] = {"machine": machine_info()}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        if args.only in (None, "hostile"):
            r = asyncio.run(hostile(args.robots, seconds, folder, args.hostile_size))
            extra["hostile"] = r
            rows += _rows("hostile robot", r)
            sent = r["hostile"]["big_replies"]
            rows.append(Row(f"hostile robot: {args.hostile_size}-character replies", sent, ""))
        if args.only in (None, "logins"):
            r = asyncio.run(logins(args.robots, seconds, folder, rounds))
            extra["logins"] = r
            rows += _rows("login flood", r)
            f, o = r["flood"], r["oracle"]
            rows.append(
                Row(
                    "login flood: attempts",
                    f["attempts"],
                    "",
                    note=f"denied {f['denied']}, locked {f['locked']}, accepted {f['accepted']}, "
                    f"errors {f['errors']}",
                )
            )
            rows.append(
                Row("refusal time, existing user, p50", percentile(o["known_ms"], 50), "ms")
            )
            rows.append(
                Row("refusal time, unknown user, p50", percentile(o["unknown_ms"], 50), "ms")
            )
    print_rows("kvp gateway under attack", rows)
    write_json(args.json, "Gateway abuse", rows, extra)


if __name__ == "__main__":
    main()
