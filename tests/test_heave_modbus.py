"""The platform PLC read and written by a stock Modbus TCP client (pymodbus), over real TCP."""

from __future__ import annotations

import asyncio

import pytest
from pymodbus.client import AsyncModbusTcpClient
from pyopenshowvar_apps.heave import registers as reg
from pyopenshowvar_apps.heave.geometry import PlatformPose
from pyopenshowvar_apps.heave.master import PlatformClient, PlatformError
from pyopenshowvar_apps.heave.simulator import PlatformConfig, PlatformSimulator


async def test_stock_client_drives_the_platform() -> None:
    async with PlatformSimulator(PlatformConfig(port=0, accel=False)) as sim:
        client = AsyncModbusTcpClient("127.0.0.1", port=sim.port, timeout=2, retries=0)
        assert await client.connect()
        try:
            state = reg.decode_state((await client.read_input_registers(0, count=17)).registers)
            assert state.heave == 0.0 and state.status == 0 and not state.flag("enabled")
            assert (await client.write_coil(reg.COILS["ENABLE"], True)).isError() is False
            assert (await client.read_coils(0, count=2)).bits[:2] == [True, False]
            words = [reg.to_register(40.0, reg.SCALE_MM), reg.to_register(1.5, reg.SCALE_DEG),
                     reg.to_register(-2.0, reg.SCALE_DEG)]  # fmt: skip
            assert not (await client.write_registers(0, words)).isError()
            assert (await client.read_holding_registers(0, count=3)).registers == words
            for _ in range(100):  # the motors take their time (speed/acceleration limits)
                await asyncio.sleep(0.05)
                await client.write_register(reg.HOLDING["HEARTBEAT"], 1)
                state = reg.decode_state((await client.read_input_registers(0, count=17)).registers)
                if not state.flag("moving") and state.heave > 39:
                    break
            assert (state.heave, state.roll, state.pitch) == pytest.approx(
                (40.0, 1.5, -2.0), abs=0.02
            )
            assert state.flag("enabled") and state.fault == 0 and state.time > 0.5
            # the same state mirrored into holding registers 100.. for holding-only masters
            mirror = reg.decode_state(
                (await client.read_holding_registers(100, count=17)).registers
            )
            assert mirror.heave == state.heave and mirror.beta == state.beta
            bits = (await client.read_discrete_inputs(0, count=6)).bits
            assert bits[reg.STATUS["enabled"]] is True
            # out-of-range value: refused as a whole (exception 3), the old set-point stays
            bad = await client.write_registers(0, [words[0], reg.to_register(25.0, reg.SCALE_DEG)])
            assert bad.isError() and bad.exception_code == 3
            assert (await client.read_holding_registers(0, count=3)).registers == words
            assert (await client.write_register(reg.HOLDING["MODE"], 7)).exception_code == 3
            # the state block is read-only; unknown addresses are refused
            assert (await client.write_register(105, 1)).exception_code == 2
            assert (await client.read_holding_registers(20, count=2)).isError()
            # the watchdog: no master write for 0.2 s stops the drives with fault 1
            await client.write_register(reg.HOLDING["WATCHDOG"], 200)
            await asyncio.sleep(0.5)
            state = reg.decode_state((await client.read_input_registers(0, count=17)).registers)
            assert state.fault == reg.FAULT_WATCHDOG and not state.flag("enabled")
            await client.write_coil(reg.COILS["RESET"], True)
            assert (await client.read_coils(2, count=1)).bits[0] is False
        finally:
            client.close()
        assert sim.refused >= 3


async def test_platform_client_units_and_errors() -> None:
    async with PlatformSimulator(PlatformConfig(port=0, accel=False)) as sim:
        async with PlatformClient("127.0.0.1", sim.port, timeout=2.0) as plc:
            await plc.configure(watchdog=0.5, speed=100)
            await plc.enable(True)
            await plc.set_pose(PlatformPose(-20.0, 0.5, 0.25))
            assert sim.plc.sp_pose == PlatformPose(-20.0, 0.5, 0.25)
            with pytest.raises(ValueError, match="outside the register range"):
                await plc.set_pose(PlatformPose(200.0, 0.0, 0.0))
            with pytest.raises(PlatformError, match="exception 3"):
                await plc.configure(speed=0)
            state = await plc.read_state()
            assert state.flag("enabled")
    with pytest.raises(ConnectionError, match="cannot connect"):
        await PlatformClient("127.0.0.1", sim.port, timeout=0.5).connect()


async def test_garbage_on_the_modbus_port_does_not_stop_the_plc() -> None:
    async with PlatformSimulator(PlatformConfig(port=0, accel=False)) as sim:
        _reader, writer = await asyncio.open_connection("127.0.0.1", sim.port)
        # a valid header announcing 65535 bytes, then 200 kB of noise in one go
        writer.write(b"\x00\x01\x00\x00\xff\xff\x01\x03" + bytes(range(256)) * 800)
        await writer.drain()
        await asyncio.sleep(0.3)
        writer.close()
        cycle = sim.plc.cycle
        client = AsyncModbusTcpClient("127.0.0.1", port=sim.port, timeout=2, retries=0)
        assert await client.connect()
        try:
            state = reg.decode_state((await client.read_input_registers(0, count=17)).registers)
        finally:
            client.close()
        await asyncio.sleep(0.05)
        assert state.cycle >= cycle and sim.plc.cycle > cycle  # still serving, still scanning


async def test_watchdog_and_undefined_coils_are_not_any_clients_to_change() -> None:
    """WATCHDOG = 0 (or longer than the start-up value) and coils the map does not define are
    refused; only a start-up option switches the watchdog off."""
    async with PlatformSimulator(PlatformConfig(port=0, accel=False)) as sim:
        client = AsyncModbusTcpClient("127.0.0.1", port=sim.port, timeout=2, retries=0)
        assert await client.connect()
        try:
            wd = reg.HOLDING["WATCHDOG"]
            assert (await client.write_register(wd, 0)).exception_code == 3
            assert (await client.write_register(wd, 1001)).exception_code == 3
            assert not (await client.write_register(wd, 400)).isError()
            assert sim.plc.watchdog == 0.4
            assert (await client.write_register(wd, 1000)).isError() is False
            for address in (3, 5, 15, 100):
                assert (await client.write_coil(address, True)).exception_code == 2
            assert (await client.write_coils(0, [False] * 4)).exception_code == 2
            assert (await client.write_coils(2, [False, True])).exception_code == 2
            assert not (await client.write_coils(0, [False, False, False])).isError()
            assert (await client.read_coils(0, count=8)).bits[:8] == [False] * 8
        finally:
            client.close()
        assert sim.plc.watchdog == 1.0 and sim.refused == 7  # coil 100: pymodbus refuses it
    async with PlatformSimulator(PlatformConfig(port=0, accel=False, watchdog=0)) as sim:
        async with PlatformClient("127.0.0.1", sim.port, timeout=2.0) as plc:
            await plc.configure(watchdog=0.0)  # started off: the master may keep it off
            await plc.configure(watchdog=2.0)  # or switch it on
        assert sim.plc.watchdog == 2.0


async def test_silent_master_stops_the_waves_over_modbus() -> None:
    """A master switches the PLC's waves on, feeds the watchdog, then goes silent: the drives
    stop one watchdog period after its last write (in the PLC's own clock)."""
    async with PlatformSimulator(PlatformConfig(port=0, accel=False)) as sim:
        stops: list[tuple[float, float]] = []  # (PLC time of the fault, of the last write)

        def watch(s: PlatformSimulator) -> None:
            if s.plc.fault and not stops:
                stops.append((s.plc.time, s.plc.last_master))

        sim.on_scan.append(watch)
        async with PlatformClient("127.0.0.1", sim.port, timeout=2.0) as master:
            await master.configure(watchdog=0.5)
            await master.enable(True)
            await master.wave(True)
            for _ in range(5):
                await master.heartbeat()
                await asyncio.sleep(0.1)
        async with asyncio.timeout(5):
            while not stops or sim.plc.status & 1 << reg.STATUS["moving"]:  # noqa: ASYNC110
                await asyncio.sleep(0.02)
        fault_at, last_write = stops[0]
        assert 0.5 < fault_at - last_write <= 0.5 + 0.06  # a scan may take up to 50 ms
        assert not sim.plc.enabled and sim.plc.wave_on  # the waves are still "on"
