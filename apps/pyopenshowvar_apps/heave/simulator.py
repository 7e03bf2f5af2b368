"""The wave platform as its own component: the PLC on Modbus TCP plus the Arduino's serial stream.

:class:`PlatformSimulator` runs on an asyncio loop: a PLC scan every ``scan`` seconds
(:class:`~.plc.PlatformPLC`), a pymodbus TCP server whose register reads and writes go straight
to the PLC (see :mod:`.registers` for the map), and the accelerometer board writing its lines
into a pseudo-terminal at 100 Hz (:mod:`.accel`). ``kvp platform`` runs one in the foreground;
:class:`PlatformThread` runs one in a background thread for the embedded experiment.

``on_scan`` callbacks run after every scan with the simulator, on its loop: the experiment's
ground-truth recorder hangs there (the true pose is :attr:`PlatformSimulator.pose`, never a
Modbus register).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Self, TypeVar

from pyopenshowvar.loopthread import LoopThread

from . import registers as reg
from .accel import AccelFirmware, format_line
from .geometry import THESIS_PLATFORM, PlatformGeometry, PlatformPose
from .plc import MotorLimits, PlatformPLC

__all__ = ["PlatformConfig", "PlatformSimulator", "PlatformThread"]

log = logging.getLogger(__name__)

T = TypeVar("T")


@dataclass(frozen=True)
class PlatformConfig:
    """Options of one simulated platform (``kvp platform --help`` lists the same)."""

    host: str = "127.0.0.1"
    #: Modbus TCP port; 0 picks a free one (502 is the standard port, but needs root).
    port: int = 5020
    scan: float = 0.01
    motors: MotorLimits = field(default_factory=MotorLimits)
    geometry: PlatformGeometry = THESIS_PLATFORM
    watchdog: float = 1.0
    accel_rate: float = 100.0
    accel_noise: float = 0.01
    accel_cutoff: float = 5.0
    #: Create the accelerometer pseudo-terminal (POSIX only).
    accel: bool = True
    seed: int | None = None
    #: Start with the drives on and the PLC's own wave generator running (stand-alone use).
    wave: bool = False

    def __post_init__(self) -> None:
        if not 0 <= self.port <= 0xFFFF:
            raise ValueError("port must be in 0..65535")
        if not (0 < self.scan <= 0.1 and 0 < self.accel_rate <= 1000):
            raise ValueError("scan must be in (0, 0.1] s and accel_rate in (0, 1000] Hz")


class PlatformSimulator:
    """PLC + Modbus server + accelerometer stream; ``async with PlatformSimulator(cfg) as sim``."""

    def __init__(self, config: PlatformConfig | None = None) -> None:
        self.config = config or PlatformConfig()
        cfg = self.config
        self.plc = PlatformPLC(cfg.geometry, cfg.motors, watchdog=cfg.watchdog)
        self.plc.wave_seed = (cfg.seed or 0) & 0xFFFF
        self.firmware = AccelFirmware(
            noise=cfg.accel_noise, cutoff=cfg.accel_cutoff, rate=cfg.accel_rate, seed=cfg.seed
        )
        self.on_scan: list[Callable[[PlatformSimulator], None]] = []
        self.host, self.port = cfg.host, cfg.port
        #: The accelerometer's serial device (the pty's slave side) while running.
        self.accel_path: str | None = None
        self.requests = 0
        self.refused = 0
        self._server: Any = None
        self._tasks: list[asyncio.Task[None]] = []
        self._pty: tuple[int, int] | None = None
        self._t0 = 0.0
        self._t0_loop = 0.0

    # --- ground truth ----------------------------------------------------------------------------
    @property
    def pose(self) -> PlatformPose:
        """The platform's true pose now (from the motors, not from any register)."""
        return self.plc.pose

    @property
    def clock(self) -> float:
        """The monotonic time of the last scan (s, same clock as ``time.monotonic``)."""
        return self._t0 + self.plc.time

    # --- life cycle ------------------------------------------------------------------------------
    async def start(self) -> Self:
        from pymodbus.server import ModbusTcpServer
        from pymodbus.simulator import DataType, SimData, SimDevice

        if self.config.wave:
            self.plc.set_enable(True)
            self.plc.set_wave(True)
        coils = [SimData(0, values=[False] * 16, datatype=DataType.BITS)]
        discrete = [SimData(0, values=[False] * 16, datatype=DataType.BITS)]
        holding = [
            SimData(0, values=self.plc.command_words(), datatype=DataType.REGISTERS),
            SimData(reg.STATE_MIRROR, values=[0] * reg.INPUT_COUNT, datatype=DataType.REGISTERS),
        ]
        inputs = [SimData(0, values=[0] * reg.INPUT_COUNT, datatype=DataType.REGISTERS)]
        device = SimDevice(id=0, simdata=(coils, discrete, holding, inputs), action=self._action)
        self._server = ModbusTcpServer(device, address=(self.config.host, self.config.port))
        await self._server.serve_forever(background=True)
        sock = self._server.transport.sockets[0]
        self.host, self.port = sock.getsockname()[:2]
        if self.config.accel:
            self._open_pty()
        self._t0 = time.monotonic()
        loop = asyncio.get_running_loop()
        self._t0_loop = loop.time()
        self._tasks.append(loop.create_task(self._scan_loop(), name="plc-scan"))
        if self._pty is not None:
            self._tasks.append(loop.create_task(self._accel_loop(), name="accel-stream"))
        log.info(
            "wave platform PLC on Modbus TCP %s:%d, accelerometer on %s",
            self.host,
            self.port,
            self.accel_path,
        )
        return self

    async def close(self) -> None:
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        self._tasks.clear()
        if self._server is not None:
            await self._server.shutdown()
            self._server = None
        if self._pty is not None:
            for fd in self._pty:
                with contextlib.suppress(OSError):
                    os.close(fd)
            self._pty = None

    async def __aenter__(self) -> Self:
        return await self.start()

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    # --- PLC scans ---------------------------------------------------------------------------------
    async def _scan_loop(self) -> None:
        # A PLC's scan time varies and its clock is wall time: each scan steps by the time that
        # really passed (at most 50 ms, so a stalled machine does not make the motors jump).
        scan = self.config.scan
        loop = asyncio.get_running_loop()
        start = last = loop.time()
        n = 0
        while True:
            n += 1
            delay = start + n * scan - loop.time()
            if delay > 0:
                await asyncio.sleep(delay)
            elif delay < -0.25:  # far behind: re-base the schedule instead of catching up
                start, n = loop.time(), 0
            now = loop.time()
            self.plc.step(min(now - last, 0.05))
            self.plc.time = now - self._t0_loop
            last = now
            for callback in list(self.on_scan):
                try:
                    callback(self)
                except Exception:  # a broken observer must not stop the PLC
                    log.exception("on_scan callback failed; removed")
                    self.on_scan.remove(callback)

    # --- accelerometer -----------------------------------------------------------------------------
    def _open_pty(self) -> None:
        import termios
        import tty

        master, slave = os.openpty()
        tty.setraw(slave)  # a serial line: no echo, no line discipline
        attrs = termios.tcgetattr(slave)
        attrs[3] &= ~termios.ECHO
        termios.tcsetattr(slave, termios.TCSANOW, attrs)
        os.set_blocking(master, False)
        self._pty = (master, slave)
        self.accel_path = os.ttyname(slave)

    async def _accel_loop(self) -> None:
        assert self._pty is not None
        master = self._pty[0]
        period = 1.0 / self.config.accel_rate
        loop = asyncio.get_running_loop()
        start = loop.time()
        n = 0
        while True:
            n += 1
            delay = start + n * period - loop.time()
            if delay > 0:
                await asyncio.sleep(delay)
            elif delay < -0.25:  # far behind: the board does not send a backlog
                start, n = loop.time(), 0
            roll, pitch = self.firmware.sample(self.plc.pose, self.plc.heave_accel)
            millis = int((loop.time() - self._t0_loop) * 1000.0)  # the board's own clock
            line = format_line(millis, roll, pitch)
            try:
                os.write(master, line)
            except BlockingIOError:
                pass  # nobody reads: a UART drops the bytes too
            except OSError:  # the pty went away (closing)
                return
            if self._pty is not None:
                self._drain_echo(master)

    @staticmethod
    def _drain_echo(master: int) -> None:
        # Anything a reader writes back (it should not) must not fill the pty's input queue.
        with contextlib.suppress(BlockingIOError, OSError):
            os.read(master, 4096)

    # --- Modbus ------------------------------------------------------------------------------------
    async def _action(
        self,
        function_code: int,
        start_address: int,
        address: int,
        count: int,
        registers: list[int],
        values: list[int] | list[bool] | None,
    ) -> Any:
        from pymodbus.constants import ExcCodes

        self.requests += 1
        plc = self.plc
        if function_code in (1, 5, 15):  # coils, bit-packed: registers[0] holds coils 0..15
            # Only the coils of the map may be written (pymodbus gives a bit block's count in
            # 16-bit words, so a write's own length is the one to check; reads of 3..15 give 0).
            if values is not None and address + len(values) > len(reg.COILS):
                self.refused += 1
                return ExcCodes.ILLEGAL_ADDRESS
            if values is not None:
                for i, on in enumerate(values):
                    self._coil(address + i, bool(on))
            registers[0] = int(plc.enabled) | int(plc.wave_on) << 1
            return None
        if function_code == 2:  # discrete inputs: the STATUS bits
            registers[0] = plc.status
            return None
        if function_code == 4:
            registers[: reg.INPUT_COUNT] = plc.state_words()
            return None
        # holding registers: commands at 0.., the state mirror at STATE_MIRROR..
        if address >= reg.STATE_MIRROR:
            if values is not None:
                self.refused += 1
                return ExcCodes.ILLEGAL_ADDRESS
            base = reg.STATE_MIRROR - start_address
            registers[base : base + reg.INPUT_COUNT] = plc.state_words()
            return None
        if address + count > reg.HOLDING_COUNT:
            self.refused += 1
            return ExcCodes.ILLEGAL_ADDRESS
        words = plc.command_words()
        if values is not None:
            for i, value in enumerate(values):
                words[address + i] = int(value) & 0xFFFF
            why = plc.check_commands(words)
            if why is not None:
                self.refused += 1
                log.info("refused Modbus write: %s", why)
                return ExcCodes.ILLEGAL_VALUE
            plc.apply_commands(words)
            words = plc.command_words()
        registers[: reg.HOLDING_COUNT] = words
        if values is not None:  # pymodbus stores the request's values after us: make them ours
            values[:] = words[address : address + len(values)]  # type: ignore[assignment]
        return None

    def _coil(self, index: int, on: bool) -> None:
        plc = self.plc
        plc.master_alive()
        if index == reg.COILS["ENABLE"]:
            plc.set_enable(on)
        elif index == reg.COILS["WAVE"]:
            plc.set_wave(on)
        elif index == reg.COILS["RESET"] and on:
            plc.reset_fault()


class PlatformThread(LoopThread[PlatformSimulator]):
    """A :class:`PlatformSimulator` on its own event loop in a daemon thread."""

    NAME = "wave-platform"
    LABEL = "the platform simulator"

    def __init__(self, config: PlatformConfig | None = None) -> None:
        super().__init__()
        self.config = config or PlatformConfig(port=0)

    def _make(self) -> PlatformSimulator:
        return PlatformSimulator(self.config)

    @property
    def sim(self) -> PlatformSimulator:
        return self.service

    def call(self, fn: Callable[..., T], *args: Any) -> T:
        """Run ``fn(sim)`` on the simulator's loop (ordering with scans) and return its result."""
        return super().call(fn, self.sim, *args)
