"""``WriteVariable``'s rules, one by one, against a real emulated KRC (gateway/writes.py).

The poller's part in a write is its configuration, its client and whether it is connected;
a :class:`_Poller` holds exactly those (a real :class:`Client` on a real emulator), so each
rule is checked without an OPC UA server around it. tests/test_gateway_e2e.py calls the same
method through OPC UA.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import pytest

pytest.importorskip("asyncua")
from asyncua import Server, ua
from pyopenshowvar_apps.gateway.cell import RobotConfig
from pyopenshowvar_apps.gateway.writes import WriteError, add_write_method, write_variable

from kukavarproxy_emu import Emulator
from pyopenshowvar import Client

CFG = RobotConfig(
    "r1",
    "127.0.0.1",
    writable=("$OV_PRO", "MYAXIS", "OUTPUT_VARS[3]", "$KR_SERIALNO"),
    allow_motion_writes=True,
)


@dataclass
class _Poller:
    cfg: RobotConfig
    client: Client | None
    connected: bool = True


async def _code(poller: _Poller, name: object, literal: object) -> int:
    with pytest.raises(WriteError) as refused:
        await write_variable(poller, name, literal)  # type: ignore[arg-type]
    return refused.value.code


async def test_the_listed_variable_is_written_and_echoed(
    ideal_emulator: Emulator, caplog: pytest.LogCaptureFixture
) -> None:
    async with Client("127.0.0.1", ideal_emulator.port) as kvp:
        poller = _Poller(replace(CFG, port=ideal_emulator.port), kvp)
        with caplog.at_level(logging.INFO, logger="pyopenshowvar_apps.gateway.writes"):
            assert await write_variable(poller, "$OV_PRO", "40") == ("40", "")  # type: ignore[arg-type]
        assert await kvp.read("$OV_PRO") == "40"
        assert any(
            "WriteVariable r1: $OV_PRO = 40 (echo 40)" in r.getMessage() for r in caplog.records
        )
        # case aside, the listed name; an index with a blank is the listed index
        assert await write_variable(poller, "$ov_Pro", "41") == ("41", "")  # type: ignore[arg-type]
        assert await write_variable(poller, "output_vars[ 3]", "TRUE") == ("TRUE", "")  # type: ignore[arg-type]
        assert await kvp.read("OUTPUT_VARS[3]") == "TRUE"
        # a literal of exactly 1024 characters is still taken
        padded = "{A1 10.0" + " " * (1024 - len("{A1 10.0}")) + "}"
        assert len(padded) == 1024
        echo, _ = await write_variable(poller, "MYAXIS", padded)  # type: ignore[arg-type]
        assert "10.0" in echo


async def test_names_not_listed_are_refused_and_nothing_is_sent(ideal_emulator: Emulator) -> None:
    async with Client("127.0.0.1", ideal_emulator.port) as kvp:
        poller = _Poller(replace(CFG, port=ideal_emulator.port), kvp)
        before = await kvp.read("$OV_PRO")
        for name in (
            "$OV _PRO",
            "$OV_PRO ",
            "$OV_PRO[]",
            "$OV_JOG",
            "OUTPUT_VARS[4]",
            "OUTPUT_VARS[3]x",
            "",
        ):
            assert await _code(poller, name, "37") == ua.StatusCodes.BadUserAccessDenied, name
        assert await kvp.read("$OV_PRO") == before
        assert await kvp.read("$OV_JOG") == "100"


async def test_bad_arguments_and_non_literals_are_refused_before_sending(
    ideal_emulator: Emulator,
) -> None:
    async with Client("127.0.0.1", ideal_emulator.port) as kvp:
        poller = _Poller(replace(CFG, port=ideal_emulator.port), kvp)
        invalid = ua.StatusCodes.BadInvalidArgument
        assert await _code(poller, 5, "1") == invalid  # not a name
        assert await _code(poller, "$OV_PRO", 50) == invalid  # not text
        assert await _code(poller, "$OV_PRO", "5" * 1025) == invalid  # over 1024 characters
        assert await _code(poller, "$OV_PRO", "{A1") == invalid  # not KRL
        assert await _code(poller, "$OV_PRO", "") == invalid
        # checked in this order: the arguments' types and length, the list, the literal
        assert await _code(poller, "$OV_JOG", 50) == invalid
        assert await _code(poller, "$OV_JOG", "{A1") == ua.StatusCodes.BadUserAccessDenied
        assert await kvp.read("$OV_PRO") == "100"


async def test_refusals_by_the_controller_say_why(ideal_emulator: Emulator) -> None:
    async with Client("127.0.0.1", ideal_emulator.port) as kvp:
        poller = _Poller(replace(CFG, port=ideal_emulator.port), kvp)
        assert await _code(poller, "$OV_PRO", "#T1") == ua.StatusCodes.BadTypeMismatch
        assert await _code(poller, "$KR_SERIALNO", "5") == ua.StatusCodes.BadNotWritable


async def test_a_robot_that_is_not_connected_gets_no_write(ideal_emulator: Emulator) -> None:
    async with Client("127.0.0.1", ideal_emulator.port) as kvp:
        cfg = replace(CFG, port=ideal_emulator.port)
        no_comm = ua.StatusCodes.BadNoCommunication
        assert await _code(_Poller(cfg, kvp, connected=False), "$OV_PRO", "30") == no_comm
        assert await _code(_Poller(cfg, None, connected=True), "$OV_PRO", "30") == no_comm
        assert await kvp.read("$OV_PRO") == "100"
        # connected as far as the poller knew, and the connection is gone: not retried
        await kvp.close()
        lost = await _code(_Poller(cfg, kvp), "$OV_PRO", "30")
        assert lost == ua.StatusCodes.BadCommunicationError


async def _refusal(poller: _Poller, name: object, literal: object) -> str:
    """What the gateway logs as the reason of a refused write (the client sees its code)."""
    with pytest.raises(WriteError) as refused:
        await write_variable(poller, name, literal)  # type: ignore[arg-type]
    return str(refused.value)


async def test_each_refusal_says_which_robot_and_why(ideal_emulator: Emulator) -> None:
    async with Client("127.0.0.1", ideal_emulator.port) as kvp:
        cfg = replace(CFG, port=ideal_emulator.port)
        poller = _Poller(cfg, kvp)
        assert await _refusal(poller, 5, "1") == "r1: bad arguments"
        assert await _refusal(poller, "$OV_JOG", "1") == (
            "r1: '$OV_JOG' is not listed writable in the cell file"
        )
        text = await _refusal(poller, "$OV_PRO", "{A1")
        assert text.startswith("r1: '{A1' is not a KRL literal: ") and len(text) > 32
        assert await _refusal(_Poller(cfg, kvp, connected=False), "$OV_PRO", "1") == (
            "r1 is not connected"
        )
        text = await _refusal(poller, "$OV_PRO", "#T1")
        assert text.startswith("r1: write refused: '$OV_PRO'") and "wrong type" in text
        assert (await _refusal(poller, "$KR_SERIALNO", "5")).startswith(
            "r1: write refused: '$KR_SERIALNO'"
        )
        await kvp.close()
        assert (await _refusal(poller, "$OV_PRO", "30")).startswith("r1: ")


async def test_a_write_that_stops_the_program_is_echoed_with_the_stop(
    ideal_emulator: Emulator, caplog: pytest.LogCaptureFixture
) -> None:
    """Beyond a software limit: written (the echo), and the program stop described beside it,
    as ``kvp write`` reports it (its exit 7), and logged."""
    async with Client("127.0.0.1", ideal_emulator.port) as kvp:
        poller = _Poller(replace(CFG, port=ideal_emulator.port), kvp)
        with caplog.at_level(logging.INFO, logger="pyopenshowvar_apps.gateway.writes"):
            echo, stop = await write_variable(poller, "MYAXIS", "{A1 9999.0}")  # type: ignore[arg-type]
        assert "9999" in echo and "#P_STOP" in stop
        line = [r.getMessage() for r in caplog.records if r.name.endswith("gateway.writes")]
        assert len(line) == 1 and line[0].endswith(f"; the program stopped: {stop}")


@pytest.mark.timeout(60)
async def test_the_opc_ua_method_its_arguments_and_its_answers(ideal_emulator: Emulator) -> None:
    """``WriteVariable`` as an OPC UA client meets it, on an in-process asyncua server (not
    started: the method is called through the server's own session): its argument names and
    types, two strings out, and a refusal as the status code of the call. Over 3 s: asyncua
    loads its standard address space first (7 s on the shared 2-core machine at load 10), the
    only way to meet the method without a whole gateway; tests/test_gateway_e2e.py calls it
    over the network, in a gateway that takes longer still to start."""
    server = Server()
    await server.init()
    ns = await server.register_namespace("urn:test:writes")
    ctrl = await server.nodes.objects.add_object(ua.NodeId("r1", ns), ua.QualifiedName("r1", ns))
    async with Client("127.0.0.1", ideal_emulator.port) as kvp:
        poller = _Poller(replace(CFG, port=ideal_emulator.port), kvp)
        method_id = ua.NodeId("r1.WriteVariable", ns)
        await add_write_method(ctrl, method_id, ns, poller)  # type: ignore[arg-type]
        method = server.get_node(method_id)
        assert await method.read_browse_name() == ua.QualifiedName("WriteVariable", ns)
        args = {
            (await node.read_browse_name()).Name: await node.read_value()
            for node in await method.get_children()
        }
        string = ua.NodeId(ua.ObjectIds.String)
        # what a client shows of each argument: its name and its description, word for word
        described = {
            "InputArguments": [
                ("Variable", "KRL variable listed writable in the cell file, e.g. $OV_PRO"),
                ("Value", "KRL literal, e.g. 50 or {A1 10.0}"),
            ],
            "OutputArguments": [
                ("Echo", "the value as the controller answered it"),
                ("ProgramStop", "empty, or how the robot program stopped right after the write"),
            ],
        }
        for key, expected in described.items():
            assert [(a.Name, a.Description.Text) for a in args[key]] == expected
            assert all(a.DataType == string and a.ValueRank == -1 for a in args[key])
        assert await ctrl.call_method(method_id, "$OV_PRO", "40") == ["40", ""]
        assert await kvp.read("$OV_PRO") == "40"
        with pytest.raises(ua.UaStatusCodeError) as refused:
            await ctrl.call_method(method_id, "$OV_JOG", "40")
        assert refused.value.code == ua.StatusCodes.BadUserAccessDenied
        with pytest.raises(ua.UaStatusCodeError) as bad:
            await ctrl.call_method(method_id, "$OV_PRO", "#T1")
        assert bad.value.code == ua.StatusCodes.BadTypeMismatch
        echo, stop = await ctrl.call_method(method_id, "MYAXIS", "{A1 9999.0}")
        assert "9999" in echo and "#P_STOP" in stop
