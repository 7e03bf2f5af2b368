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
from pathlib import Path

from pyopenshowvar.extras import MissingExtraError

from .cell import Cell, cell_configs
from .config import (
    DEFAULT_PORT,
    DEFAULT_UDP_PORT,
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


def build_parser(prog: str = "kukavarproxy-emu") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=prog,
        description="KUKAVARPROXY 9.0 (or C3 Bridge 1.4) emulator (TCP 7000 protocol, UDP 6999"
        " discovery).",
    )
    net = parser.add_argument_group("network")
    net.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    net.add_argument(
        "--port", type=int, default=DEFAULT_PORT, help="TCP port (default 7000, 0 = ephemeral)"
    )
    net.add_argument(
        "--max-clients",
        type=int,
        default=-1,
        help="0 = unlimited (default 10; 64 with --proxy c3bridge)",
    )
    net.add_argument(
        "--idle-timeout",
        type=float,
        default=-1.0,
        help="seconds, 0 = never (default 30; never with --proxy c3bridge)",
    )
    net.add_argument(
        "--idle-reset",
        choices=IDLE_RESETS,
        default="bytes",
        help="what resets the idle timer: any received bytes, as KVP (default), or only whole"
        " requests",
    )
    net.add_argument("--udp-port", type=int, default=DEFAULT_UDP_PORT, help="discovery port")
    net.add_argument(
        "--udp-reply-port",
        type=int,
        default=DEFAULT_PORT,
        help="port discovery answers go to (default 7000, 0 = the sender's port)",
    )
    disc = net.add_mutually_exclusive_group()
    disc.add_argument("--discovery", dest="discovery", action="store_true", default=None)
    disc.add_argument("--no-discovery", dest="discovery", action="store_false")

    beh = parser.add_argument_group("behaviour")
    beh.add_argument(
        "--config",
        action="append",
        default=[],
        metavar="FILE",
        type=Path,
        help="$CONFIG.DAT-style file whose globals are added to the defaults (repeatable)",
    )
    beh.add_argument(
        "--latency",
        default="none",
        metavar="PROFILE",
        help=f"none | {' | '.join(PROFILES)} | fixed:SECONDS (default none)",
    )
    beh.add_argument("--seed", type=int, default=None, help="seed of the latency sampler")
    beh.add_argument(
        "--proxy",
        default="kvp",
        choices=PROXIES,
        help="kvp (default): KUKAVARPROXY 9.0; c3bridge: C3 Bridge 1.4, its extended messages"
        " (read many, program control, files, ...) on the same robot, see docs/c3bridge.md",
    )
    beh.add_argument(
        "--strict", action="store_true", help="C3 Bridge style failures (tail 00 00 00)"
    )
    beh.add_argument(
        "--wire",
        default="robust",
        choices=WIRES,
        help="robust (default): reassemble requests, close on garbage; kvp9: parse every"
        " 2048-byte read on its own, byte for byte like KUKAVARPROXY 9.0",
    )
    beh.add_argument(
        "--quirks",
        action="append",
        default=[],
        metavar="QUIRK[,QUIRK]",
        help=f"reproduce old-proxy bugs: {', '.join(sorted(KNOWN_QUIRKS))}",
    )
    beh.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="SPEC",
        help="inject a fault, KIND[:VALUE][@NTH][,conn=C][,count=K][,pause=S] (repeatable)",
    )
    rob = parser.add_argument_group("simulated robot")
    rob.add_argument(
        "--robot",
        dest="arm",
        default="",
        metavar="NAME|FILE",
        help="which KUKA six-axis arm: a catalogue name (kvp arms list: kr6_r900_sixx,"
        " kr10_r1100_2, kr16_r2010_2, kr210_r2700_2, kr560_r3100_2) or an arm file (.toml,"
        " .urdf); default the KR 6 R900 sixx. Its $MODEL_NAME[], limits, speeds and plant"
        " follow it; arms a KRC does not drive over KUKAVARPROXY are refused",
    )
    rob.add_argument(
        "--program",
        default="",
        metavar="NAME|PROG.src",
        help=f"robot program: a KRL .src file (its .dat beside it is loaded) or a shipped one,"
        f" {' | '.join(ROBOT_PROGRAMS)} (default follow: LOOP PTP MYAXIS C_PTP; none with"
        " --proxy c3bridge)",
    )
    rob.add_argument(
        "--sps",
        default="sps",
        metavar="SPS.SUB",
        help="submit program run beside it (default: the shipped sps.sub, OUTPUT_VARS to $OUT;"
        " none = no SPS)",
    )
    rob.add_argument(
        "--speed", type=float, default=1.0, help="simulated time runs F times faster (default 1)"
    )
    rob.add_argument(
        "--ipo", type=float, default=0.012, help="interpolation cycle, seconds (default 0.012)"
    )
    rob.add_argument(
        "--plant",
        choices=PLANTS,
        default="dynamic",
        help="dynamic: rigid-body arm, servos, friction, sensor noise (default); ideal: measured"
        " = set-point, exact statics torques",
    )
    rob.add_argument(
        "--noise",
        type=float,
        default=None,
        metavar="DEG",
        help="encoder noise on the measured axes, deg (default: dynamic 2e-5, ideal 0)",
    )
    rob.add_argument(
        "--torque-noise",
        type=float,
        default=None,
        metavar="NM",
        help="noise on $TORQUE_AXIS_ACT, Nm (default 0.1 %% of each axis' max torque)",
    )
    rob.add_argument(
        "--calibration-error",
        type=int,
        default=None,
        metavar="SEED",
        help="the physical robot's geometry and masses differ from the nominal model"
        " (random, realistic amounts drawn with SEED; default off)",
    )
    rob.add_argument(
        "--obstacle",
        action="append",
        default=[],
        metavar="CX,CY,CZ,HX,HY,HZ[,K[,B[,R]]]",
        help="a box the TCP can push against: centre and half size (mm, $ROBROOT), stiffness"
        " N/mm (default 2), damping N*s/mm (0.02), probe radius mm (0); repeatable",
    )
    rob.add_argument(
        "--no-robot", dest="robot", action="store_false", help="static variables, no motion"
    )
    rob.add_argument(
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
    quirks = frozenset(q.strip() for item in args.quirks for q in item.split(",") if q.strip())
    return EmulatorConfig(
        host=args.host,
        port=args.port,
        config_files=tuple(args.config),
        latency=args.latency,
        max_clients=args.max_clients,
        idle_timeout=args.idle_timeout,
        idle_reset=args.idle_reset,
        seed=args.seed,
        strict=args.strict,
        quirks=quirks,
        wire=args.wire,
        proxy=args.proxy,
        udp_port=args.udp_port,
        udp_reply_port=args.udp_reply_port,
        discovery=args.discovery,
        faults=tuple(Fault.parse(spec) for spec in args.fault),
        robot=args.robot,
        arm=args.arm,
        program=args.program,
        sps=args.sps,
        speed=args.speed,
        ipo=args.ipo,
        noise=args.noise,
        plant=args.plant,
        torque_noise=args.torque_noise,
        calibration_error=args.calibration_error,
        obstacles=tuple(Obstacle.parse(spec) for spec in args.obstacle),
    )


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
