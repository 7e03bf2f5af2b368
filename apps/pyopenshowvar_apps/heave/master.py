"""The control server's side of the platform link: a Modbus TCP master for the PLC's register map.

Thin over pymodbus' ``AsyncModbusTcpClient``: physical units in, registers out (and back), one
request per call with the client's timeout, Modbus exception responses raised as
:class:`PlatformError` naming the register, a dead link as ``ConnectionError``.
"""

from __future__ import annotations

import logging
from typing import Any, Self

from . import registers as reg
from .geometry import PlatformPose

__all__ = ["PlatformClient", "PlatformError"]

log = logging.getLogger(__name__)


class PlatformError(RuntimeError):
    """The PLC refused a request (a Modbus exception response)."""


class PlatformClient:
    """``async with PlatformClient(host, port) as plc: await plc.read_state()``."""

    def __init__(
        self, host: str, port: int = 5020, *, timeout: float = 1.0, device_id: int = 1
    ) -> None:
        self.host, self.port, self.timeout, self.device_id = host, port, timeout, device_id
        self._client: Any = None
        self._heartbeat = 0

    async def connect(self) -> Self:
        from pymodbus.client import AsyncModbusTcpClient

        # No automatic reconnects and no retries: a control loop must see a dead link at once.
        self._client = AsyncModbusTcpClient(
            self.host, port=self.port, timeout=self.timeout, retries=0, reconnect_delay=0
        )
        if not await self._client.connect():
            self._client.close()
            self._client = None
            raise ConnectionError(f"platform PLC {self.host}:{self.port}: cannot connect")
        return self

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None

    async def __aenter__(self) -> Self:
        return await self.connect()

    async def __aexit__(self, *exc: object) -> None:
        self.close()

    async def _call(self, what: str, method: str, *args: Any, **kw: Any) -> Any:
        from pymodbus.exceptions import ModbusException

        if self._client is None:
            raise ConnectionError(f"platform PLC {self.host}:{self.port}: not connected")
        try:
            response = await getattr(self._client, method)(*args, device_id=self.device_id, **kw)
        except ModbusException as exc:
            raise ConnectionError(f"platform PLC {self.host}:{self.port}: {what}: {exc}") from exc
        if response.isError():
            code = getattr(response, "exception_code", "?")
            raise PlatformError(f"platform PLC refused {what} (Modbus exception {code})")
        return response

    async def read_state(self) -> reg.PlatformState:
        """One read of the 17 state registers."""
        response = await self._call("read state", "read_input_registers", 0, count=reg.INPUT_COUNT)
        return reg.decode_state(response.registers)

    async def set_pose(self, pose: PlatformPose) -> None:
        """Write the heave/roll/pitch set-points (one request, registers 0–2)."""
        lo_h, hi_h = reg.HOLDING_LIMITS[0]
        lo_a, hi_a = reg.HOLDING_LIMITS[1]
        words = [
            reg.to_register(pose.z, reg.SCALE_MM, lo_h, hi_h),
            reg.to_register(pose.phi, reg.SCALE_DEG, lo_a, hi_a),
            reg.to_register(pose.theta, reg.SCALE_DEG, lo_a, hi_a),
        ]
        await self._call("set-point write", "write_registers", 0, words)

    async def configure(self, *, watchdog: float = 1.0, speed: int = 100, mode: int = 0) -> None:
        await self._call("mode write", "write_register", reg.HOLDING["MODE"], mode)
        await self._call(
            "watchdog write", "write_register", reg.HOLDING["WATCHDOG"], round(watchdog * 1000)
        )
        await self._call("speed write", "write_register", reg.HOLDING["SPEED"], speed)

    async def heartbeat(self) -> None:
        self._heartbeat = (self._heartbeat + 1) & 0xFFFF
        await self._call("heartbeat", "write_register", reg.HOLDING["HEARTBEAT"], self._heartbeat)

    async def enable(self, on: bool = True) -> None:
        """Drives on/off; switching on first acknowledges a latched fault."""
        if on:
            await self._call("fault reset", "write_coil", reg.COILS["RESET"], True)
        await self._call("enable", "write_coil", reg.COILS["ENABLE"], on)

    async def wave(self, on: bool, seed: int | None = None) -> None:
        """The PLC's own wave generator (stand-alone mode)."""
        if seed is not None:
            await self._call(
                "seed write", "write_register", reg.HOLDING["WAVE_SEED"], seed & 0xFFFF
            )
        await self._call("wave", "write_coil", reg.COILS["WAVE"], on)
