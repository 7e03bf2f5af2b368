"""``python -m kukavarproxy_emu.abuse probe HOST PORT SECONDS VAR``: the bystander process.

:func:`~kukavarproxy_emu.abuse.start_probe` starts it; it prints ``ready`` once connected and,
at the end, one JSON :class:`~kukavarproxy_emu.abuse.ProbeResult`.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
from collections.abc import Sequence
from dataclasses import asdict

from .probe import run_probe


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m kukavarproxy_emu.abuse")
    sub = parser.add_subparsers(dest="command", required=True)
    probe = sub.add_parser("probe", help="be the bystander; print a JSON ProbeResult")
    probe.add_argument("host")
    probe.add_argument("port", type=int)
    probe.add_argument("seconds", type=float)
    probe.add_argument("var", help="an INT variable the probe may write")
    probe.add_argument(
        "--emulator-pid", type=int, help="measure this process's CPU time per round trip"
    )
    probe.add_argument(
        "--until-eof", action="store_true", help="run until stdin closes (SECONDS: a cap)"
    )
    probe.add_argument("--min-requests", type=int, default=0, help="time at least this many")
    args = parser.parse_args(argv)
    stop = threading.Event()

    def wait_for_eof() -> None:
        sys.stdin.read()
        stop.set()

    if args.until_eof:
        threading.Thread(target=wait_for_eof, daemon=True).start()
    result = run_probe(
        args.host,
        args.port,
        args.seconds,
        args.var,
        ready=lambda: print("ready", flush=True),
        emulator_pid=args.emulator_pid,
        stop=stop.is_set if args.until_eof else None,
        min_requests=args.min_requests,
    )
    print(json.dumps(asdict(result)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
