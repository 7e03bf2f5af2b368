"""Command line of the emulator: ``kukavarproxy-emu`` / ``python -m kukavarproxy_emu``.

Plain argparse so the emulator needs nothing beyond the standard library (and numpy through
the store). The first line on stdout, flushed, is ``listening on HOST:PORT`` with the real
port, so scripts can start it with ``--port 0`` and read where it went (``--robots N``: N such
lines, robot ``k`` on ``PORT + k``). SIGINT and SIGTERM stop
it cleanly with exit status 0, within ``STOP_DEADLINE`` seconds whatever runs: a watchdog
thread, woken by the signal itself (``signal.set_wakeup_fd``, which works even while the main
thread is busy), ends the process if the clean stop has not finished by then, and at once on a
second signal.
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import logging
import os
import signal
import socket
import sys
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from pyopenshowvar.extras import MissingExtraError

from .cell import Cell, cell_configs
from .config import (
    IDLE_RESETS,
    KNOWN_QUIRKS,
    PROXIES,
    ROBOT_PROGRAMS,
    WIRES,
    EmulatorConfig,
)
from .faults import Fault
from .latency import PROFILES
from .plant import PLANTS, Obstacle

__all__ = ["build_parser", "config_from_args", "main"]

log = logging.getLogger("kukavarproxy_emu")

#: Seconds after SIGINT/SIGTERM by which the process has ended, cleanly or not.
STOP_DEADLINE = 0.9


def _same(value: Any) -> Any:
    return value


def _split_quirks(items: list[str]) -> frozenset[str]:
    return frozenset(q.strip() for item in items for q in item.split(",") if q.strip())


@dataclass(frozen=True)
class _Option:
    """One option that sets one :class:`EmulatorConfig` field (its ``dest`` is the field's
    name; its default, for a plain option, the field's default)."""

    flag: str
    field: str
    help: str | None = None
    type: Callable[[str], Any] | None = None
    choices: Sequence[str] | None = None
    metavar: str | None = None
    #: "store"; "append" (repeatable: a list, made a tuple by ``convert``); "store_true" /
    #: "store_false" (a switch); "either" (``--flag`` / ``--no-flag``, unset: the default)
    action: str = "store"
    #: what the parsed value becomes in the config
    convert: Callable[[Any], Any] = _same


#: Every option that sets a config field, by help group, in the order ``--help`` lists them:
#: a new :class:`EmulatorConfig` field that the command line sets is one line here.
_OPTIONS: dict[str, tuple[_Option, ...]] = {
    "network": (
        _Option("--host", "host", "address to bind (default 127.0.0.1)"),
        _Option("--port", "port", "TCP port (default 7000, 0 = ephemeral)", int),
        _Option(
            "--max-clients",
            "max_clients",
            "0 = unlimited (default 10; 64 with --proxy c3bridge)",
            int,
        ),
        _Option(
            "--idle-timeout",
            "idle_timeout",
            "seconds, 0 = never (default 30; never with --proxy c3bridge)",
            float,
        ),
        _Option(
            "--idle-reset",
            "idle_reset",
            "what resets the idle timer: any received bytes, as KVP (default), or only whole"
            " requests",
            choices=IDLE_RESETS,
        ),
        _Option("--udp-port", "udp_port", "discovery port", int),
        _Option(
            "--udp-reply-port",
            "udp_reply_port",
            "port discovery answers go to (default 7000, 0 = the sender's port)",
            int,
        ),
        _Option("--discovery", "discovery", action="either"),
    ),
    "behaviour": (
        _Option(
            "--config",
            "config_files",
            "$CONFIG.DAT-style file whose globals are added to the defaults (repeatable)",
            Path,
            metavar="FILE",
            action="append",
            convert=tuple,
        ),
        _Option(
            "--latency",
            "latency",
            f"none | {' | '.join(PROFILES)} | fixed:SECONDS (default none)",
            metavar="PROFILE",
        ),
        _Option("--seed", "seed", "seed of the latency sampler", int),
        _Option(
            "--proxy",
            "proxy",
            "kvp (default): KUKAVARPROXY 9.0; c3bridge: C3 Bridge 1.4, its extended messages"
            " (read many, program control, files, ...) on the same robot, see docs/c3bridge.md",
            choices=PROXIES,
        ),
        _Option(
            "--strict", "strict", "C3 Bridge style failures (tail 00 00 00)", action="store_true"
        ),
        _Option(
            "--wire",
            "wire",
            "robust (default): reassemble requests, close on garbage; kvp9: parse every"
            " 2048-byte read on its own, byte for byte like KUKAVARPROXY 9.0",
            choices=WIRES,
        ),
        _Option(
            "--quirks",
            "quirks",
            f"reproduce old-proxy bugs: {', '.join(sorted(KNOWN_QUIRKS))}",
            metavar="QUIRK[,QUIRK]",
            action="append",
            convert=_split_quirks,
        ),
        _Option(
            "--fault",
            "faults",
            "inject a fault, KIND[:VALUE][@NTH][,conn=C][,count=K][,pause=S] (repeatable)",
            metavar="SPEC",
            action="append",
            convert=lambda specs: tuple(Fault.parse(spec) for spec in specs),
        ),
    ),
    "simulated robot": (
        _Option(
            "--robot",
            "arm",
            "which KUKA six-axis arm: a catalogue name (kvp arms list: kr6_r900_sixx,"
            " kr10_r1100_2, kr16_r2010_2, kr210_r2700_2, kr560_r3100_2) or an arm file (.toml,"
            " .urdf); default the KR 6 R900 sixx. Its $MODEL_NAME[], limits, speeds and plant"
            " follow it; arms a KRC does not drive over KUKAVARPROXY are refused",
            metavar="NAME|FILE",
        ),
        _Option(
            "--program",
            "program",
            f"robot program: a KRL .src file (its .dat beside it is loaded) or a shipped one,"
            f" {' | '.join(ROBOT_PROGRAMS)} (default follow: LOOP PTP MYAXIS C_PTP; none with"
            " --proxy c3bridge)",
            metavar="NAME|PROG.src",
        ),
        _Option(
            "--sps",
            "sps",
            "submit program run beside it (default: the shipped sps.sub, OUTPUT_VARS to $OUT;"
            " none = no SPS)",
            metavar="SPS.SUB",
        ),
        _Option("--speed", "speed", "simulated time runs F times faster (default 1)", float),
        _Option("--ipo", "ipo", "interpolation cycle, seconds (default 0.012)", float),
        _Option(
            "--plant",
            "plant",
            "dynamic: rigid-body arm, servos, friction, sensor noise (default); ideal: measured"
            " = set-point, exact statics torques",
            choices=PLANTS,
        ),
        _Option(
            "--noise",
            "noise",
            "encoder noise on the measured axes, deg (default: dynamic 2e-5, ideal 0)",
            float,
            metavar="DEG",
        ),
        _Option(
            "--torque-noise",
            "torque_noise",
            "noise on $TORQUE_AXIS_ACT, Nm (default 0.1 %% of each axis' max torque)",
            float,
            metavar="NM",
        ),
        _Option(
            "--calibration-error",
            "calibration_error",
            "the physical robot's geometry and masses differ from the nominal model"
            " (random, realistic amounts drawn with SEED; default off)",
            int,
            metavar="SEED",
        ),
        _Option(
            "--obstacle",
            "obstacles",
            "a box the TCP can push against: centre and half size (mm, $ROBROOT), stiffness"
            " N/mm (default 2), damping N*s/mm (0.02), probe radius mm (0); repeatable",
            metavar="CX,CY,CZ,HX,HY,HZ[,K[,B[,R]]]",
            action="append",
            convert=lambda specs: tuple(Obstacle.parse(spec) for spec in specs),
        ),
        _Option("--no-robot", "robot", "static variables, no motion", action="store_false"),
    ),
}


def _add(group: argparse._ArgumentGroup, opt: _Option, default: Any) -> None:
    if opt.action == "either":  # --flag / --no-flag; neither given: the config's default
        pair = group.add_mutually_exclusive_group()
        pair.add_argument(opt.flag, dest=opt.field, action="store_true", default=default)
        pair.add_argument(f"--no-{opt.flag[2:]}", dest=opt.field, action="store_false")
        return
    kwargs: dict[str, Any] = {"dest": opt.field, "action": opt.action, "help": opt.help}
    if opt.action in ("store", "append"):
        kwargs.update(type=opt.type, choices=opt.choices, metavar=opt.metavar)
        kwargs["default"] = [] if opt.action == "append" else default
    group.add_argument(opt.flag, **kwargs)


def build_parser(prog: str = "kukavarproxy-emu") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=prog,
        description="KUKAVARPROXY 9.0 (or C3 Bridge 1.4) emulator (TCP 7000 protocol, UDP 6999"
        " discovery).",
    )
    defaults = {f.name: f.default for f in fields(EmulatorConfig)}
    groups: dict[str, argparse._ArgumentGroup] = {}
    for title, options in _OPTIONS.items():
        groups[title] = group = parser.add_argument_group(title)
        for opt in options:
            _add(group, opt, defaults[opt.field])
    # Options of the process, not of one emulator's config:
    groups["simulated robot"].add_argument(
        "--robots",
        type=int,
        default=1,
        metavar="N",
        help="a cell: N independent robots in this process on ports PORT..PORT+N-1 (each its"
        " own store, program and seed SEED+k; one 'listening on' line each; default 1)",
    )
    parser.add_argument(
        "--log-level",
        default="warning",
        choices=["debug", "info", "warning", "error"],
        help="logging level on stderr (default warning)",
    )
    return parser


def config_from_args(args: argparse.Namespace) -> EmulatorConfig:
    values = {
        opt.field: opt.convert(getattr(args, opt.field))
        for options in _OPTIONS.values()
        for opt in options
    }
    return EmulatorConfig(**values)


async def serve(config: EmulatorConfig, robots: int = 1) -> None:
    """Run until SIGINT/SIGTERM; ``robots > 1`` serves a cell (:mod:`.cell`)."""
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    restore = _arm_stop_signals(loop, stop)
    try:
        async with Cell(cell_configs(config, robots)) as cell:
            # This process is the emulator's alone: what start-up built (store, robot, numpy,
            # the physics) lives as long as the process, so the cyclic collector need not scan
            # it again. A full collection then scans only what was created since: under a flood
            # of requests an 86 ms pause became < 1 ms.
            gc.freeze()
            for emu in cell.emulators:
                print(f"listening on {emu.host}:{emu.port}", flush=True)
            await stop.wait()
            served = sum(emu.stats.requests for emu in cell.emulators)
            log.info("stopping (%d requests served)", served)
    finally:
        restore()


def _arm_stop_signals(loop: asyncio.AbstractEventLoop, stop: asyncio.Event) -> Callable[[], None]:
    """SIGINT/SIGTERM set ``stop``; the watchdog makes sure the process ends in time.

    Returns the function that puts the previous signal handling back.
    """
    if threading.current_thread() is not threading.main_thread():
        return lambda: None  # signals are the main thread's business only
    rsock, wsock = socket.socketpair()
    wsock.setblocking(False)

    def on_signal(signum: int, frame: object) -> None:
        loop.call_soon_threadsafe(stop.set)

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    old_fd = signal.set_wakeup_fd(wsock.fileno(), warn_on_full_buffer=False)
    # The thread holds both ends: the wakeup fd must stay open for as long as it is installed.
    threading.Thread(
        target=_watchdog, args=(rsock, wsock), name="stop-watchdog", daemon=True
    ).start()

    def restore() -> None:
        signal.set_wakeup_fd(old_fd)
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        wsock.close()  # the watchdog's recv returns b"": it ends without acting

    return restore


def _watchdog(rsock: socket.socket, wsock: socket.socket) -> None:
    with rsock:
        if not rsock.recv(1):
            return  # closed: the emulator stopped without a signal
        rsock.settimeout(STOP_DEADLINE)
        try:
            if not rsock.recv(1):
                return  # the clean stop finished in time
        except TimeoutError:
            pass
        # A second signal, or the event loop did not get to the stop in time.
        print(
            f"kukavarproxy-emu: not stopped {STOP_DEADLINE} s after the signal; exiting now",
            file=sys.stderr,
            flush=True,
        )
        os._exit(0)


def main(argv: Sequence[str] | None = None, *, prog: str = "kukavarproxy-emu") -> int:
    """Run the emulator until SIGINT/SIGTERM; ``prog`` names the command in help and errors."""
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=args.log_level.upper(),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    try:
        config = config_from_args(args)
        cell_configs(config, args.robots)  # a bad count or port range is a usage error
    except (ValueError, OSError) as exc:
        parser.error(str(exc))
    try:
        asyncio.run(serve(config, args.robots))
    except KeyboardInterrupt:
        pass
    except (OSError, ValueError, MissingExtraError) as exc:
        # port in use, bad --config, KRL syntax error, MuJoCo not installed
        print(f"kukavarproxy-emu: error: {exc}", file=sys.stderr, flush=True)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
