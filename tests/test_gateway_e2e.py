"""``kvp gateway`` end to end: three emulated KRCs behind one gateway, a stock asyncua client.

Everything is real: the emulators over TCP on ephemeral ports, the gateway's OPC UA server on
an ephemeral port, asyncua's client browsing, subscribing and calling methods. One gateway
serves the whole module (its start-up, asyncua's address space and the NodeSets, is the
expensive part).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncIterator
from typing import Any

import pytest
import pytest_asyncio

asyncua = pytest.importorskip("asyncua")
from asyncua import Client as UaClient  # noqa: E402
from asyncua import ua  # noqa: E402
from pyopenshowvar_apps.gateway.cell import parse_cell  # noqa: E402
from pyopenshowvar_apps.gateway.model import GATEWAY_URI, ROBOTICS_URI  # noqa: E402
from pyopenshowvar_apps.gateway.server import Gateway  # noqa: E402

from kukavarproxy_emu import Emulator, EmulatorConfig  # noqa: E402
from kukavarproxy_emu.faults import Fault  # noqa: E402
from pyopenshowvar import Client  # noqa: E402

pytestmark = [pytest.mark.asyncio(loop_scope="module"), pytest.mark.timeout(90)]

ROBOTS = ("r1", "r2", "r3")
# r4 has a snapshot group: a STRUC its controller fills (here: written by the test)
SNAPSHOT_DAT = """DEFDAT $CONFIG
STRUC GWSNAP_T E6AXIS AX, INT OV
DECL GWSNAP_T GW_SNAP={AX {A1 1.5, A2 -90.0, A3 90.0, A4 0.0, A5 0.0, A6 0.0, E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}, OV 55}
ENDDAT
"""


class Cell:
    def __init__(self, gw: Gateway, emus: dict[str, Emulator]) -> None:
        self.gw, self.emus = gw, emus


def _emu(port: int = 0, dat: str | None = None, arm: str = "") -> Emulator:
    # the ideal plant: exact set-points and the cheapest robot (the gateway is under test here)
    config = EmulatorConfig(
        port=port, discovery=False, idle_timeout=0, plant="ideal", dat_text=dat, arm=arm
    )
    return Emulator(config)


#: r3 is a KR 16 R2010-2: its MotionDevice follows its own $MODEL_NAME[]
ARMS = {"r3": "kr16_r2010_2"}


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def cell() -> AsyncIterator[Cell]:
    emus = {name: await _emu(arm=ARMS.get(name, "")).start() for name in ROBOTS}
    emus["r4"] = await _emu(dat=SNAPSHOT_DAT).start()
    snapshot = {"variable": "GW_SNAP", "members": {"$AXIS_ACT": "AX", "$ov_pro": "OV"}}
    config = parse_cell(
        {
            "cell": {"name": "testcell", "endpoint": "opc.tcp://127.0.0.1:0"},
            "robot": [
                {
                    "name": name,
                    "host": "127.0.0.1",
                    "port": emu.port,
                    "poll_hz": 20,
                    "timeout": 0.5,
                    "variables": ["$OV_JOG", "MYAXIS"],
                    "writable": ["$OV_PRO", "MYAXIS"] if name == "r1" else [],
                    "allow_motion_writes": True,
                    "snapshot": [snapshot] if name == "r4" else [],
                }
                for name, emu in emus.items()
            ],
        }
    )
    gw = Gateway(config)
    await gw.start()
    try:
        yield Cell(gw, emus)
    finally:
        await gw.stop()
        for emu in emus.values():
            await emu.close()


@contextlib.asynccontextmanager
async def ua_client(gw: Gateway) -> AsyncIterator[tuple[Any, int, int]]:
    async with UaClient(gw.url, timeout=10) as client:
        ours = await client.get_namespace_index(GATEWAY_URI)
        rob = await client.get_namespace_index(ROBOTICS_URI)
        yield client, ours, rob


def node_id(ours: int, path: str) -> Any:
    return ua.NodeId(f"testcell.{path}", ours)


async def wait_for(predicate: Any, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not await predicate():
        assert time.monotonic() < deadline, "condition not met in time"
        await asyncio.sleep(0.05)


async def test_motion_devices_are_found_by_their_type_definition(cell: Cell) -> None:
    async with ua_client(cell.gw) as (client, ours, rob):
        motion_device_type = ua.NodeId(1004, rob)  # OPC 40010-1 MotionDeviceType
        # start from DI's DeviceSet and walk down by type, as a generic Robotics client does
        device_set = await client.nodes.objects.get_child(
            f"{await client.get_namespace_index('http://opcfoundation.org/UA/DI/')}:DeviceSet"
        )
        systems = [
            n
            for n in await device_set.get_children()
            if await n.read_type_definition() == ua.NodeId(1002, rob)  # MotionDeviceSystemType
        ]
        assert len(systems) == 1
        folder = await systems[0].get_child(f"{rob}:MotionDevices")
        found = {}
        for child in await folder.get_children():
            if await child.read_type_definition() == motion_device_type:
                found[(await child.read_browse_name()).Name] = child
        assert sorted(found) == [*ROBOTS, "r4"]
        r1 = found["r1"]
        # mandatory properties carry the controller's identity ($MODEL_NAME[], $KR_SERIALNO)
        await wait_for(lambda: _is_good(r1, "2:Manufacturer"))
        manufacturer = await (await r1.get_child("2:Manufacturer")).read_value()
        model = await (await r1.get_child("2:Model")).read_value()
        serial = await (await r1.get_child("2:SerialNumber")).read_value()
        assert manufacturer.Text == "KUKA"
        assert model.Text == "KR6R900SIXX C4SR FLR"
        assert serial == "123456"
        axes = await (await r1.get_child(f"{rob}:Axes")).get_children()
        assert len(axes) == 6
        assert {await a.read_type_definition() for a in axes} == {ua.NodeId(16601, rob)}
        # the Controller Controls the MotionDevice (Robotics reference type, ns=Robotics i=4002)
        ctrl = client.get_node(node_id(ours, "Controllers.r1"))
        assert await ctrl.read_type_definition() == ua.NodeId(1003, rob)
        controlled = await ctrl.get_referenced_nodes(refs=ua.NodeId(4002, rob))
        assert [n.nodeid for n in controlled] == [r1.nodeid]
        state = client.get_node(node_id(ours, "SafetyStates.r1.ParameterSet.OperationalMode"))
        await wait_for(lambda: _is_good(state))
        assert await state.read_value() == 3  # #AUT -> AUTOMATIC
        # the robot interpreter runs the follow program: Executing, the type's own state node
        machine = "Controllers.r1.TaskControls.RobotInterpreter.TaskControlOperation"
        current = client.get_node(node_id(ours, f"{machine}.TaskControlStateMachine.CurrentState"))
        assert (await current.read_value()).Text == "Executing"
        state_id = await (await current.get_child("0:Id")).read_value()
        assert state_id == ua.NodeId(5042, rob)  # TaskControlStateMachineType/Executing
        name = client.get_node(node_id(ours, "Controllers.r1.TaskControls.RobotInterpreter"))
        program = await (
            await name.get_child(["2:ParameterSet", f"{rob}:TaskProgramName"])
        ).read_value()
        assert program  # $PRO_NAME1[]


async def _is_good(node: Any, child: str | None = None) -> bool:
    target = await node.get_child(child) if child else node
    dv = await target.read_data_value(raise_on_bad_status=False)
    return dv.StatusCode is not None and dv.StatusCode.is_good()


class _Changes:
    def __init__(self) -> None:
        self.values: dict[str, list[float]] = {}

    def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
        if isinstance(val, float):
            self.values.setdefault(node.nodeid.Identifier, []).append(val)


async def test_each_motion_device_shows_its_own_arm(cell: Cell) -> None:
    """Model and axis ranges from each robot's $MODEL_NAME[] and the catalogue: r1 a KR 6,
    r3 a KR 16 R2010-2 (A2 -185..65 deg against the KR 6's -190..45)."""
    async with ua_client(cell.gw) as (client, ours, _rob):

        async def arm_of(robot: str) -> tuple[str, list[tuple[float, float]]]:
            path = f"MotionDevices.{robot}"
            model = await client.get_node(node_id(ours, f"{path}.Model")).read_value()
            ranges = []
            for axis in ("A1", "A2"):
                node = node_id(ours, f"{path}.Axes.{axis}.ParameterSet.ActualPosition.EURange")
                value = await client.get_node(node).read_value()
                ranges.append((value.Low, value.High))
            return model.Text, ranges

        async def known() -> bool:
            return bool((await arm_of("r1"))[0] and (await arm_of("r3"))[0])

        await wait_for(known)
        assert await arm_of("r1") == ("KR6R900SIXX C4SR FLR", [(-170.0, 170.0), (-190.0, 45.0)])
        model, ranges = await arm_of("r3")
        assert model == "KR16R2010-2 C4 FLR"
        assert ranges == [pytest.approx((-185.0, 185.0)), pytest.approx((-185.0, 65.0))]
    poller = cell.gw.pollers["r3"]
    assert poller.max_speed == pytest.approx((200.0, 175.0, 190.0, 430.0, 430.0, 630.0))


async def test_subscribed_client_sees_three_robots_move(cell: Cell) -> None:
    targets = {"r1": 12.0, "r2": -15.0, "r3": 9.0}
    async with ua_client(cell.gw) as (client, ours, _):
        changes = _Changes()
        sub = await client.create_subscription(50, changes)
        nodes = [
            client.get_node(node_id(ours, f"MotionDevices.{r}.Axes.A1.ParameterSet.ActualPosition"))
            for r in ROBOTS
        ]
        await sub.subscribe_data_change(nodes, queuesize=50)
        for name, a1 in targets.items():
            async with Client("127.0.0.1", cell.emus[name].port) as kvp:
                await kvp.write("MYAXIS", f"{{A1 {a1}}}")  # the follow program moves there

        async def arrived() -> bool:
            last = {k.split(".")[2]: v[-1] for k, v in changes.values.items() if v}
            return all(abs(last.get(r, 1e9) - a1) < 0.01 for r, a1 in targets.items())

        await wait_for(arrived)
        for name in ROBOTS:
            seen = changes.values[
                f"testcell.MotionDevices.{name}.Axes.A1.ParameterSet.ActualPosition"
            ]
            assert len(set(seen)) >= 3, (name, seen)  # intermediate positions: it moved
        await sub.delete()
        for name in ROBOTS:  # back home for the other tests
            async with Client("127.0.0.1", cell.emus[name].port) as kvp:
                await kvp.write("MYAXIS", "{A1 0.0}")


async def test_dropped_robot_goes_bad_and_comes_back_good(
    cell: Cell, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="pyopenshowvar_apps.gateway")
    async with ua_client(cell.gw) as (client, ours, _):
        a2 = client.get_node(node_id(ours, "MotionDevices.r3.Axes.A2.ParameterSet.ActualPosition"))
        other = client.get_node(
            node_id(ours, "MotionDevices.r2.Axes.A2.ParameterSet.ActualPosition")
        )
        connected = client.get_node(node_id(ours, "Controllers.r3.ParameterSet.Connected"))
        await wait_for(lambda: _is_good(a2))
        # a subscriber is told of the drop and the return too, not only a client that reads
        statuses = _Statuses()
        sub = await client.create_subscription(50, statuses)
        await sub.subscribe_data_change([a2], queuesize=50)
        port = cell.emus["r3"].port
        await cell.emus["r3"].close()

        async def bad() -> bool:
            dv = await a2.read_data_value(raise_on_bad_status=False)
            return dv.StatusCode.value == ua.StatusCodes.BadNoCommunication

        await wait_for(bad)
        assert await connected.read_value() is False
        assert await _is_good(other)  # the other robots are not affected
        cell.emus["r3"] = await _emu(port).start()  # the same controller comes back
        await wait_for(lambda: _is_good(a2))
        assert await a2.read_value() == pytest.approx(-90.0)
        assert await connected.read_value() is True
        await wait_for(lambda: statuses.seen(ua.StatusCodes.Good, after_bad=True))
        await sub.delete()
        # the log says what the poller does: it reconnects (the client's advice to call
        # connect() by hand is for a client without a poller)
        lost = [r.getMessage() for r in caplog.records if "robot r3 (" in r.getMessage()]
        assert lost and all("reconnecting in" in m for m in lost), lost
        assert not any("auto_reconnect" in r.getMessage() for r in caplog.records)
        assert statuses.codes[0] == ua.StatusCodes.Good  # the value when it subscribed
        assert ua.StatusCodes.BadNoCommunication in statuses.codes
        assert all(stamp is not None for stamp in statuses.stamps)


class _Statuses:
    def __init__(self) -> None:
        self.codes: list[int] = []
        self.stamps: list[Any] = []

    def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
        dv = data.monitored_item.Value
        self.codes.append(dv.StatusCode.value)
        self.stamps.append(dv.SourceTimestamp)

    async def seen(self, code: int, after_bad: bool) -> bool:
        bad = ua.StatusCodes.BadNoCommunication
        later = self.codes[self.codes.index(bad) :] if bad in self.codes else []
        return code in (later if after_bad else self.codes)


async def test_stalled_robot_goes_bad_within_its_timeout_and_others_keep_polling(
    cell: Cell,
) -> None:
    """Abuse: a controller that stops answering must not stall the gateway's other robots."""
    async with ua_client(cell.gw) as (client, ours, _):
        a1 = client.get_node(node_id(ours, "MotionDevices.r2.Axes.A1.ParameterSet.ActualPosition"))
        await wait_for(lambda: _is_good(a1))
        poller = cell.gw.pollers["r1"]
        polls = poller.polls
        cell.emus["r2"].faults.add(Fault("drop", count=None))  # every reply swallowed
        try:
            started = time.monotonic()

            async def bad() -> bool:
                return not await _is_good(a1)

            await wait_for(bad)
            assert time.monotonic() - started < 3.0  # timeout 0.5 s, then Bad
            assert poller.polls > polls  # r1 kept polling meanwhile
        finally:
            cell.emus["r2"].faults.clear()
        await wait_for(lambda: _is_good(a1))


async def test_writes_only_through_the_method_and_only_listed_variables(cell: Cell) -> None:
    async with ua_client(cell.gw) as (client, ours, _):
        ctrl = client.get_node(node_id(ours, "Controllers.r1"))
        method = node_id(ours, "Controllers.r1.WriteVariable")
        # a variable the cell file does not list writable: refused, nothing sent
        with pytest.raises(ua.UaStatusCodeError) as refused:
            await ctrl.call_method(method, "$OV_JOG", "50")
        assert refused.value.code == ua.StatusCodes.BadUserAccessDenied
        async with Client("127.0.0.1", cell.emus["r1"].port) as kvp:
            assert await kvp.read("$OV_JOG") == "100"
        # a listed one: written, echoed, and the model shows it
        assert await ctrl.call_method(method, "$OV_PRO", "40") == ["40", ""]
        override = client.get_node(node_id(ours, "MotionDevices.r1.ParameterSet.SpeedOverride"))
        await wait_for(lambda: _equals(override, 40.0))
        # a literal of the wrong type or no KRL at all is refused before sending
        with pytest.raises(ua.UaStatusCodeError) as bad_type:
            await ctrl.call_method(method, "$OV_PRO", "#T1")
        assert bad_type.value.code == ua.StatusCodes.BadTypeMismatch
        for junk in ("{A1", "1" * 5000):  # not KRL; absurdly long (bounded work per call)
            with pytest.raises(ua.UaStatusCodeError) as not_krl:
                await ctrl.call_method(method, "$OV_PRO", junk)
            assert not_krl.value.code == ua.StatusCodes.BadInvalidArgument
        # the Write service is refused on every variable the gateway serves
        jog = client.get_node(node_id(ours, "Controllers.r1.ParameterSet.$OV_JOG"))
        with pytest.raises(ua.UaStatusCodeError) as write:
            await jog.write_value(ua.DataValue(ua.Variant(10, ua.VariantType.Int32)))
        assert write.value.code in (
            ua.StatusCodes.BadNotWritable,
            ua.StatusCodes.BadUserAccessDenied,
        )
        # r2 lists nothing writable: it has no write method at all
        assert cell.gw.robots["r2"].write_method is None
        assert await ctrl.call_method(method, "$OV_PRO", "100") == ["100", ""]
        # a motion variable (allowed by the cell file) whose value stops the program: written,
        # and the stop is reported like kvp write's exit 7 (this leaves r1's program stopped)
        echo, stop = await ctrl.call_method(method, "MYAXIS", "{A1 9999.0}")
        assert "9999" in echo and "#P_STOP" in stop


async def _equals(node: Any, value: float) -> bool:
    dv = await node.read_data_value(raise_on_bad_status=False)
    return dv.StatusCode.is_good() and dv.Value.Value == value


async def test_a_snapshot_group_is_read_as_one_struc_and_fanned_out(cell: Cell) -> None:
    """r4's $AXIS_ACT and $OV_PRO come from GW_SNAP (one KVP request), not from themselves."""
    assert cell.gw.pollers["r4"].poll_names()[0] == "GW_SNAP"
    assert "$AXIS_ACT" not in cell.gw.pollers["r4"].poll_names()
    async with ua_client(cell.gw) as (client, ours, _):
        override = client.get_node(node_id(ours, "MotionDevices.r4.ParameterSet.SpeedOverride"))
        a1 = client.get_node(node_id(ours, "MotionDevices.r4.Axes.A1.ParameterSet.ActualPosition"))
        await wait_for(lambda: _equals(override, 55.0))  # the real $OV_PRO is 100
        assert await a1.read_value() == 1.5  # the real $AXIS_ACT.A1 is 0
        async with Client("127.0.0.1", cell.emus["r4"].port) as kvp:
            await kvp.write("GW_SNAP.OV", "33")
        await wait_for(lambda: _equals(override, 33.0))


async def test_near_miss_names_are_not_the_writable_variable(cell: Cell) -> None:
    """Only a name the cell file lists, as a whole: case aside, nothing else is the same."""
    async with ua_client(cell.gw) as (client, ours, _):
        ctrl = client.get_node(node_id(ours, "Controllers.r1"))
        method = node_id(ours, "Controllers.r1.WriteVariable")
        async with Client("127.0.0.1", cell.emus["r1"].port) as kvp:
            before = await kvp.read("$OV_PRO")
            for name in (
                "$OV _PRO",
                " $OV_PRO",
                "$OV_PRO ",
                "$OV_PRO\n",
                "$OV_PRO[]",
                "$OV_PRO[1]",
                "$OV_PROX",
                "$OV_PR",
                "OV_PRO",
                "$OV_PRO.A1",
                "$OV_PRO;",
                "MYAXIS.A1",
                "",
            ):
                with pytest.raises(ua.UaStatusCodeError) as refused:
                    await ctrl.call_method(method, name, "37")
                assert refused.value.code == ua.StatusCodes.BadUserAccessDenied, name
            assert await kvp.read("$OV_PRO") == before  # nothing was sent
            # KRL is case-insensitive: the listed variable, written under its listed name
            assert await ctrl.call_method(method, "$ov_Pro", "37") == ["37", ""]
            assert await kvp.read("$OV_PRO") == "37"
            assert await ctrl.call_method(method, "$OV_PRO", before) == [before, ""]


async def test_nodes_are_named_after_themselves_and_the_server_after_the_gateway(
    cell: Cell,
) -> None:
    async with ua_client(cell.gw) as (client, ours, _):
        for path, name in (
            ("MotionDevices.r1", "r1"),
            ("MotionDevices.r2", "r2"),  # a copy of r1's nodes (gateway/clone.py)
            ("Controllers.r3", "r3"),
            ("SafetyStates.r2", "r2"),
            ("MotionDevices.r2.Axes.A4", "A4"),
            ("MotionDevices.r1.PowerTrains.PowerTrain2", "PowerTrain2"),
            ("MotionDevices.r1.PowerTrains.PowerTrain2.Motor2", "Motor2"),
            ("Controllers.r1.TaskControls.RobotInterpreter", "RobotInterpreter"),
            ("Controllers.r1.Software.KSS", "KSS"),
            ("SafetyStates.r1.EmergencyStopFunctions.EmergencyStop", "EmergencyStop"),
            ("MotionDevices.r1.PowerTrains.PowerTrain1.Motor1.ParameterSet.ActualTorque",
             "ActualTorque"),
            ("MotionDevices.r1.Axes.A1.ParameterSet.ActualPosition", "ActualPosition"),
        ):  # fmt: skip
            shown = await client.get_node(node_id(ours, path)).read_display_name()
            assert shown.Text == name, path
        root = client.get_node(ua.NodeId("testcell", ours))
        assert (await root.read_display_name()).Text == "testcell"
        build = await client.get_node(
            ua.NodeId(ua.ObjectIds.Server_ServerStatus_BuildInfo)
        ).read_value()
        assert build.ProductName == "pyopenshowvar kvp gateway"
        assert build.ManufacturerName == "pyopenshowvar"
        assert build.ProductUri == GATEWAY_URI
        assert "FreeOpcUa" not in f"{build}"
        temp = client.get_node(
            node_id(
                ours,
                "MotionDevices.r1.PowerTrains.PowerTrain1.Motor1.ParameterSet.MotorTemperature",
            )
        )
        await wait_for(lambda: _is_good(temp))
        assert await temp.read_value() == 26.85  # 300 K, not 26.850000000000023
