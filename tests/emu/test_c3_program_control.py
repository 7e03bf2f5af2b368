"""C3 Bridge's program control (#10) on the emulator, state by state: which command each state
of the robot and the submit interpreter accepts, what it leaves, and the reason a refusal
leaves in ``$EMU_MESSAGE[]`` (``program_state().message``), through the C3 client."""

from __future__ import annotations

import pytest

from kukavarproxy_emu import Emulator
from kukavarproxy_emu.testing import EmulatorFactory
from pyopenshowvar import Client
from pyopenshowvar.c3 import C3CommandError, ErrorCode, Interpreter

SRC = b"DEF HOLD()\n  WAIT SEC 60\nEND\n"
SUBMIT = Interpreter.SUBMIT


@pytest.fixture
async def c3(emulator_factory: EmulatorFactory) -> Emulator:
    return await emulator_factory(proxy="c3bridge", plant="ideal")


async def refused(call: object) -> int:
    with pytest.raises(C3CommandError) as info:
        await call  # type: ignore[misc]
    return int(info.value.code)


async def test_nothing_selected_start_stop_reset_are_refused_cancel_is_not(c3: Emulator) -> None:
    async with Client(c3.host, c3.port) as kvp:
        assert (await kvp.program_state()).state == "P_FREE"
        assert await refused(kvp.program_start(allow_motion=True)) == ErrorCode.GENERAL
        state = await kvp.program_state()
        assert (state.state, state.message) == ("P_FREE", "start refused: no program selected")
        assert await refused(kvp.program_stop()) == ErrorCode.GENERAL
        assert await refused(kvp.program_reset()) == ErrorCode.GENERAL
        await kvp.program_cancel()  # nothing to cancel: fine
        assert (await kvp.program_state()).state == "P_FREE"


async def test_the_robot_interpreter_state_by_state(c3: Emulator) -> None:
    async with Client(c3.host, c3.port) as kvp:
        path = await kvp.program_upload(SRC, "hold.src")
        await kvp.program_select(path)
        state = await kvp.program_state()
        assert (state.state, state.name) == ("P_RESET", "HOLD")
        assert await refused(kvp.program_stop()) == ErrorCode.GENERAL  # nothing runs
        await kvp.program_reset()  # already reset: stays
        assert (await kvp.program_state()).state == "P_RESET"
        await kvp.program_start(allow_motion=True)
        assert (await kvp.program_state()).state == "P_ACTIVE"
        await kvp.program_start(allow_motion=True)  # already running: fine, still running
        assert (await kvp.program_state()).state == "P_ACTIVE"
        assert await refused(kvp.program_reset()) == ErrorCode.GENERAL  # stop it first
        assert await refused(kvp.program_cancel()) == ErrorCode.GENERAL
        assert await refused(kvp.program_select(path)) == ErrorCode.GENERAL
        assert (await kvp.program_state()).message == (
            "select refused: stop the running program first"
        )
        await kvp.program_stop()
        assert (await kvp.program_state()).state == "P_STOP"
        await kvp.program_stop()  # stopped already: fine
        await kvp.program_start(allow_motion=True)  # resumes
        state = await kvp.program_state()
        assert (state.state, state.message) == ("P_ACTIVE", "")  # the old reason is gone
        await kvp.program_stop()
        await kvp.program_reset()
        assert (await kvp.program_state()).state == "P_RESET"
        await kvp.program_cancel()
        state = await kvp.program_state()
        assert (state.state, state.name) == ("P_FREE", "")
        await kvp.file_write(path, SRC)  # no longer selected: no longer locked


async def test_the_submit_interpreter_state_by_state(c3: Emulator) -> None:
    async with Client(c3.host, c3.port) as kvp:
        assert (await kvp.program_state()).submit_state == "P_ACTIVE"
        for command, after in (
            (kvp.program_stop, "P_STOP"),
            (kvp.program_start, "P_ACTIVE"),  # resumed
            (kvp.program_reset, "P_RESET"),
            (kvp.program_start, "P_ACTIVE"),  # from the first line
            (kvp.program_cancel, "P_FREE"),
            (kvp.program_start, "P_ACTIVE"),  # selected again and started
        ):
            await command(SUBMIT)
            state = await kvp.program_state()
            assert state.submit_state == after, (command, state)
            assert state.state == "P_FREE"  # the robot interpreter is not touched


async def test_without_a_submit_interpreter_its_commands_fail(
    emulator_factory: EmulatorFactory,
) -> None:
    emu = await emulator_factory(proxy="c3bridge", plant="ideal", sps="none")
    async with Client(emu.host, emu.port) as kvp:
        for command in (kvp.program_start, kvp.program_stop, kvp.program_reset):
            assert await refused(command(SUBMIT)) == ErrorCode.GENERAL
