"""The jog controller (:mod:`pyopenshowvar_apps.web.jog`) on its own, against the emulator.

No web server in between: each test drives a :class:`JogController` like the server does
(``press``, ``release``, ``stop``, the ``run`` watchdog) over real TCP to an emulator running
the shipped KVP_JOG program (ideal plant: the axes read back exactly), and checks what it wrote
to the robot and what it says. The end-to-end jogs through the WebSocket are in
tests/test_web_jog.py; these are the controller's rules one by one, each about a second at most.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest
from pyopenshowvar_apps.armpick import given_arm
from pyopenshowvar_apps.web.jog import HOLD_TIMEOUT, JogController, advance_pose
from pyopenshowvar_apps.web.jogplan import AXIS_SPEED, CREDIT, JogRequest, plan_jog
from pyopenshowvar_apps.web.robotlink import RobotLink, axes_of, frame6
from pyopenshowvar_apps.web.runner import KRL_DIR

from kukavarproxy_emu import Emulator, EmulatorConfig
from kukavarproxy_emu.faults import Fault
from kukavarproxy_emu.store import VariableStore
from kukavarproxy_emu.testing import wait_until
from pyopenshowvar import Client, E6Axis, Struct
from pyopenshowvar.kinematics import KR6R900SIXX, inverse, pose_to_matrix

A1_UP = JogRequest("axis", "A1", 1, None, 100.0)
#: A1's increment at 100 %: 15 deg/s for one 20 ms cadence.
A1_INC = AXIS_SPEED[0] * 0.020
#: A3's, which stands at 90 deg.
A3_INC = AXIS_SPEED[2] * 0.020
#: JOG_AX as the stop leaves it: the increment zeroed.
ZERO_AX = "{AXIS: A1 0.0, A2 0.0, A3 0.0, A4 0.0, A5 0.0, A6 0.0}"


@dataclass
class Cell:
    """An emulator running KVP_JOG, the link and control connections of a pad, the
    controller, and the test's own connection to look at the robot."""

    emu: Emulator
    link: RobotLink
    control: Client
    kvp: Client
    jog: JogController
    pages: list[object] = field(default_factory=lambda: [object(), object()])
    links: list[RobotLink] = field(default_factory=list)  # more pads' links, closed at the end

    async def number(self, name: str) -> int:
        return int(await self.kvp.read(name))

    def cut(self, after: int) -> None:
        """Cut the controller's connection in the middle of its ``after``-th next reply."""
        info = next(i for i in self.emu.connections() if i.index == 3)
        self.emu.faults.add(Fault("close", nth=info.received + after, connection=3))

    async def watchdog(self) -> asyncio.Task[None]:
        return asyncio.create_task(self.jog.run(0.005))

    async def step(self, req: JogRequest) -> None:
        """Run the step ``req`` (pressed by the second page) to its end, the arm still."""
        dog = await self.watchdog()
        try:
            assert await self.jog.press(self.pages[1], 1, req) is None

            async def done() -> bool:
                return self.jog.jog is None

            await wait_until(done, timeout=5)
        finally:
            dog.cancel()
        self.jog.forget(self.pages[1])
        await idle(self)


Factory = Callable[..., Awaitable[Cell]]


@pytest.fixture
async def cell() -> AsyncIterator[Factory]:
    """``await cell(softp={1: 2.9}, hold_timeout=..., ...)``: limits set before the pad's
    first poll, the rest passed to the controller (a lenient keep-alive timeout unless one
    is given: a loaded machine may hold the test's loop longer than the real 100 ms)."""
    made: list[tuple[Emulator, list[Client]]] = []
    cells: list[Cell] = []

    async def make(
        *, softp: dict[int, float] | None = None, softn: dict[int, float] | None = None,
        system: dict[str, str] | None = None, axes: E6Axis | None = None,
        auto_reconnect: bool = True, **kw: Any,
    ) -> Cell:  # fmt: skip
        emu = Emulator(
            EmulatorConfig(
                port=0,
                latency="none",
                discovery=False,
                plant="ideal",
                program=str(KRL_DIR / "kvp_jog.src"),
                config_files=(KRL_DIR / "kvp_jog_config.dat",),
            )
        )
        if axes is not None:  # where the arm stands when the robot starts
            emu.store.set_system("$AXIS_ACT", axes)
        await emu.start()
        clients: list[Client] = []
        made.append((emu, clients))
        for axis, value in (softp or {}).items():
            emu.store.set_system(f"$SOFTP_END[{axis}]", value)
        for axis, value in (softn or {}).items():
            emu.store.set_system(f"$SOFTN_END[{axis}]", value)
        for name, text in (system or {}).items():
            emu.store.write(name, text)
        link = RobotLink("127.0.0.1", emu.port, timeout=2.0)
        clients.append(link.client)
        await link.poll_once()  # connection 1
        kvp = Client("127.0.0.1", emu.port, timeout=2.0)
        clients.append(kvp)
        await kvp.connect()  # connection 2
        control = Client(
            "127.0.0.1", emu.port, timeout=2.0, auto_reconnect=auto_reconnect, keepalive=None
        )
        clients.append(control)
        await control.connect()  # connection 3: the controller's

        async def ready() -> bool:
            await link.poll_once()
            return link.jog_ready() is None

        await wait_until(ready, timeout=10)
        kw.setdefault("hold_timeout", 5.0)
        made_cell = Cell(emu, link, control, kvp, JogController(control, link, **kw))
        cells.append(made_cell)
        return made_cell

    yield make
    for made_cell in cells:
        for extra in made_cell.links:
            await extra.client.close()
    for emu, clients in made:
        for client in clients:
            await client.close()
        await emu.close()


def requests(c: Cell) -> int:
    """Requests the emulator has had on the controller's connection (the third)."""
    return next(i.received for i in c.emu.connections() if i.index == 3)


async def idle(c: Cell) -> None:
    async def program_idle() -> bool:
        return await c.kvp.read("JOG_MODE") == "0" and not c.emu.robot.kernel.moving  # type: ignore[union-attr]

    await wait_until(program_idle, timeout=5)


async def increment(c: Cell, axis: str) -> float:
    """JOG_AX's member ``axis``: the increment the program plans next."""
    value = await c.kvp.read_value("JOG_AX")
    assert isinstance(value, Struct)
    return float(value[axis])  # type: ignore[arg-type]


# --- pure: where a Cartesian jog's increments lead ------------------------------------------
def test_advance_pose_in_base_and_in_tool() -> None:
    pose = np.array([400.0, 50.0, 300.0, 90.0, 0.0, 180.0])
    rot = pose_to_matrix(pose)[:3, :3]
    step = np.array([2.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    base = advance_pose(pose, step, 3, tool=False)
    assert np.allclose(base[:3], [406.0, 50.0, 300.0])  # along $BASE x, n increments
    assert np.allclose(pose_to_matrix(base)[:3, :3], rot)
    tool = advance_pose(pose, step, 3, tool=True)
    assert np.allclose(tool[:3], pose[:3] + 6.0 * rot[:, 0])  # along the TCP's own x
    assert np.allclose(pose_to_matrix(tool)[:3, :3], rot)
    turn = np.array([0.0, 0.0, 0.0, 10.0, 0.0, 0.0])  # A: about z
    about_base = advance_pose(pose, turn, 2.5, tool=False)
    assert np.allclose(about_base[:3], pose[:3])  # turns about the base axes *at the TCP*
    rz = pose_to_matrix([0, 0, 0, 25.0, 0, 0])[:3, :3]
    assert np.allclose(pose_to_matrix(about_base)[:3, :3], rz @ rot)
    about_tool = advance_pose(pose, turn, 2.5, tool=True)
    assert np.allclose(about_tool[:3], pose[:3])
    assert np.allclose(pose_to_matrix(about_tool)[:3, :3], rot @ rz)
    assert about_tool.dtype == np.float64 and about_base.shape == (6,)


# --- a press ---------------------------------------------------------------------------------
async def test_press_writes_the_plan_and_a_credit_ahead_of_the_count(cell: Factory) -> None:
    c = await cell()
    me, other = c.pages
    count = await c.number("JOG_COUNT")  # the program stands still: the count does not move
    assert c.jog.describe(me) == {"active": False, "mine": False, "label": None}
    req = JogRequest("axis", "A2", -1, None, 33.3)  # 2.4975 deg/s, shown as 2.5
    assert await c.jog.press(me, 1, req) is None
    assert await c.number("JOG_UNTIL") == count + CREDIT
    assert await c.kvp.read("JOG_MODE") == "1"
    assert await increment(c, "A2") == pytest.approx(-AXIS_SPEED[1] * 0.333 * 0.02)
    assert c.jog.describe(me) == {
        "active": True, "mine": True, "label": "axis A2-", "speed": 2.5, "unit": "deg/s",
    }  # fmt: skip
    assert c.jog.describe(other)["mine"] is False
    # another page can neither jog nor release it
    assert await c.jog.press(other, 1, A1_UP) == "another page is jogging"
    await c.jog.release(other)
    assert await c.kvp.read("JOG_MODE") == "1" and c.jog.jog is not None
    await c.jog.release(me)
    assert [await c.kvp.read(n) for n in ("JOG_MODE", "JOG_UNTIL")] == ["0", "0"]
    assert await c.kvp.read("JOG_AX") == ZERO_AX
    assert c.jog.describe(me) == {
        "active": False, "mine": False, "label": None, "stopped": "released",
    }  # fmt: skip
    # the same press (a keep-alive that arrives late) never starts again ...
    assert await c.jog.press(me, 1, req) is None
    assert await c.kvp.read("JOG_MODE") == "0" and c.jog.jog is None
    # ... until the page is forgotten (it went away: a new page counts from 1 again)
    c.jog.forget(other)
    assert await c.jog.press(me, 1, req) is None and c.jog.jog is None
    c.jog.forget(me)
    assert await c.jog.press(me, 1, req) is None
    assert await c.kvp.read("JOG_MODE") == "1"
    await c.jog.stop(other, "not its jog")  # stop() of another owner leaves it alone
    assert c.jog.jog is not None
    await c.jog.stop(None, "server shutting down")  # None: whoever jogs
    assert c.jog.jog is None and c.jog.last_stop is not None
    assert c.jog.last_stop[0] == "server shutting down"


async def test_units_and_speeds_of_the_page(cell: Factory) -> None:
    c = await cell(credit=1)
    me = c.pages[0]
    # credit 1: each press moves at most one increment, wherever the arm stands
    for press, (frame, key, unit) in enumerate(
        [("axis", "A6", "deg/s"), ("base", "Z", "mm/s"), ("tool", "A", "deg/s"),
         ("base", "C", "deg/s"), ("tool", "X", "mm/s")], start=1,
    ):  # fmt: skip
        await c.jog.press(me, press, JogRequest(frame, key, 1, None, 40.0))  # type: ignore[arg-type]
        jog = c.jog.jog
        if jog is not None:  # a Cartesian jog at HOME may be refused: the describe is the point
            assert c.jog.describe(me)["unit"] == unit, (frame, key)
            assert c.jog.describe(me)["speed"] == round(jog.plan.speed, 2)
        await c.jog.release(me)


async def test_a_press_that_changes_its_button_is_stopped(cell: Factory) -> None:
    c = await cell()
    me = c.pages[0]
    count = await c.number("JOG_COUNT")
    assert await c.jog.press(me, 3, A1_UP) is None
    changed = JogRequest("axis", "A1", -1, None, 100.0)  # the other direction, same press
    refused = await c.jog.press(me, 3, changed)
    assert refused == "a held press cannot change its button: press again"
    assert c.jog.jog is None and c.jog.last_stop is not None
    assert c.jog.last_stop[0] == "the press changed its button"
    assert await c.kvp.read("JOG_MODE") == "0"
    assert await c.jog.press(me, 3, changed) is None and c.jog.jog is None  # it stays ended
    # a new press of the same page replaces the old one
    assert await c.jog.press(me, 4, A1_UP) is None
    step = JogRequest("axis", "A1", 1, 1.0, 100.0)  # 4 increments of 0.25 deg
    assert await c.jog.press(me, 5, step) is None
    assert c.jog.last_stop is not None and c.jog.last_stop[0] == "new press"
    assert c.jog.jog is not None and c.jog.jog.press == 5
    count = await c.number("JOG_COUNT")
    until = await c.number("JOG_UNTIL")
    assert until == c.jog.jog.start + 4 and count <= until  # the step, not the credit of 5
    await c.jog.release(me)


async def test_keep_alive_may_change_the_override_only(cell: Factory) -> None:
    c = await cell()
    me = c.pages[0]
    slow = JogRequest("axis", "A3", 1, None, 20.0)
    assert await c.jog.press(me, 1, slow) is None
    until = await c.number("JOG_UNTIL")
    acc = await c.number("JOG_ACC")
    fast = JogRequest("axis", "A3", 1, None, 60.0)
    assert await c.jog.press(me, 1, fast) is None  # a keep-alive with a new override
    plan = plan_jog(fast, KR6R900SIXX)
    assert await c.number("JOG_ACC") == plan.acc[0] != acc  # the acceleration follows
    assert await increment(c, "A3") == pytest.approx(AXIS_SPEED[2] * 0.6 * 0.02)
    # ... and nothing else is rewritten: JOG_UNTIL and JOG_MODE stay
    assert await c.number("JOG_UNTIL") == until and await c.kvp.read("JOG_MODE") == "1"
    assert c.jog.describe(me)["speed"] == pytest.approx(9.0)
    await c.jog.release(me)
    # a step keeps the increment of its press: the step's count was planned with it
    step = JogRequest("axis", "A3", -1, 10.0, 20.0)
    assert await c.jog.press(me, 2, step) is None
    before = await c.kvp.read("JOG_AX")
    assert await c.jog.press(me, 2, JogRequest("axis", "A3", -1, 10.0, 90.0)) is None
    assert await c.kvp.read("JOG_AX") == before
    assert c.jog.jog is not None and c.jog.jog.req.override == 20.0
    await c.jog.release(me)


async def test_a_press_the_robot_cannot_take_is_refused_once(cell: Factory) -> None:
    c = await cell()
    me = c.pages[0]
    # no connection to the robot yet: the link's reason, and the press counts as ended
    unlinked = JogController(c.control, RobotLink("127.0.0.1", c.emu.port))
    assert await unlinked.press(me, 1, A1_UP) == "no connection to the robot"
    assert await unlinked.press(me, 1, A1_UP) is None
    assert await unlinked.press(me, 2, A1_UP) == "no connection to the robot"
    await unlinked.link.client.close()
    # the controller's own connection fails
    dead = Client("127.0.0.1", 1, timeout=1.0, auto_reconnect=False)
    cut = JogController(dead, c.link)
    refused = await cut.press(me, 1, A1_UP)
    assert refused is not None and refused.startswith("cannot read the robot: ")
    assert len(refused) > len("cannot read the robot: ")
    assert await cut.press(me, 1, A1_UP) is None and cut.jog is None
    assert await c.kvp.read("JOG_MODE") == "0"


async def test_press_failing_to_write_zeroes_what_it_wrote(cell: Factory) -> None:
    c = await cell()
    me = c.pages[0]
    c.cut(3 + 5)  # the 3 reads of the press go through; its writes are cut at JOG_UNTIL
    refused = await c.jog.press(me, 1, A1_UP)
    assert refused is not None and refused.startswith("jog write failed: ")
    assert c.jog.jog is None
    assert await c.kvp.read("JOG_MODE") == "0"
    assert await c.kvp.read("JOG_AX") == ZERO_AX
    assert await c.jog.press(me, 1, A1_UP) is None and c.jog.jog is None  # ended


# --- the software limits, at the press --------------------------------------------------------
@pytest.mark.parametrize(
    ("increments", "credit"),
    [(8, CREDIT), (7.99, 4), (7, 4), (5, 2), (4.01, 1), (3.99, None), (3, None)],
)
@pytest.mark.parametrize("direction", [1, -1])
async def test_axis_credit_stops_short_of_the_software_limit(
    cell: Factory, increments: float, credit: int | None, direction: int
) -> None:
    """A3 stands at 90 deg with room for ``increments`` increments before the 0.5 deg margin
    of the limit ahead (the one behind is far), of which 3 may be in flight beyond the count
    the pad saw: the press gives the rest as credit, or is refused."""
    room, far = 0.5 + increments * A3_INC, 0.5 + 30 * A3_INC
    ahead, behind = 90.0 + direction * room, 90.0 - direction * far
    lo, hi = min(ahead, behind), max(ahead, behind)
    c = await cell(softp={3: hi}, softn={3: lo})
    me = c.pages[0]
    count = await c.number("JOG_COUNT")
    refused = await c.jog.press(me, 1, JogRequest("axis", "A3", direction, None, 100.0))
    if credit is None:
        assert refused == f"software limit {'+' if direction > 0 else '-'}A3 ahead"
        assert await c.kvp.read("JOG_MODE") == "0"
        assert await c.jog.press(me, 1, A1_UP) is None and c.jog.jog is None  # ended
    else:
        assert refused is None
        assert await c.number("JOG_UNTIL") == count + credit
        await c.jog.release(me)


@pytest.mark.parametrize(("room", "ok"), [(1.0, True), (0.99, False)])
async def test_a_step_is_checked_whole_against_the_limit(
    cell: Factory, room: float, ok: bool
) -> None:
    c = await cell(softp={1: 0.5 + room})
    me = c.pages[0]
    count = await c.number("JOG_COUNT")
    refused = await c.jog.press(me, 1, JogRequest("axis", "A1", 1, 1.0, 100.0))
    if ok:  # the whole step fits (no increments in flight to reserve: it ends by itself)
        assert refused is None and await c.number("JOG_UNTIL") == count + 4
    else:
        assert refused == "software limit +A1 ahead"


# --- the watchdog ---------------------------------------------------------------------------
async def test_held_jog_moves_on_and_stops_before_the_limit(cell: Factory) -> None:
    c = await cell(softp={1: 0.5 + 12 * A1_INC})
    me = c.pages[0]
    count = await c.number("JOG_COUNT")
    dog = await c.watchdog()
    try:
        assert await c.jog.press(me, 1, A1_UP) is None
        assert await c.number("JOG_UNTIL") == count + CREDIT

        async def held() -> bool:
            await c.jog.press(me, 1, A1_UP)  # the page's keep-alive
            return c.jog.jog is None

        await wait_until(held, timeout=5)
        assert c.jog.last_stop is not None
        assert c.jog.last_stop[0] == "software limit +A1 ahead"
        assert await c.number("JOG_COUNT") > count + CREDIT  # JOG_UNTIL was moved on
        await idle(c)
        a1 = (await c.kvp.read_joint_angles())[0]
        assert 12 * A1_INC - 3 * A1_INC - 1e-6 <= a1 <= 12 * A1_INC + 1e-6
    finally:
        dog.cancel()


async def test_step_ends_by_itself(cell: Factory) -> None:
    """Two steps in a row (the second starts from a count that is not 0): each ends by itself
    after exactly its increments, more than one credit's worth."""
    c = await cell()
    me = c.pages[0]
    dog = await c.watchdog()

    async def done() -> bool:
        return c.jog.jog is None

    try:
        for press in (1, 2):
            step = JogRequest("axis", "A6", -1, 10.0, 100.0)  # 12 increments at 45 deg/s
            assert await c.jog.press(me, press, step) is None
            start = c.jog.jog.start  # type: ignore[union-attr]
            await wait_until(done, timeout=5)
            assert c.jog.last_stop is not None and c.jog.last_stop[0] == "step done"
            await idle(c)
            assert await c.number("JOG_COUNT") == start + 12
            a6 = (await c.kvp.read_joint_angles())[5]
            assert a6 == pytest.approx(-10.0 * press, abs=1e-4)
    finally:
        dog.cancel()


@pytest.mark.parametrize("finds", ["step done", "read failed", "limit"])
async def test_a_stale_top_up_never_ends_another_pages_jog(cell: Factory, finds: str) -> None:
    """A top-up reads the robot, and the page releases and another page presses while the
    answer is on its way (the controller's next reply held back 0.3 s): what the stale top-up
    finds (its step done, its connection failed, no room left before the limit) ends no jog
    but its own page's."""
    c = await cell(softp={3: 90.0 + 0.5 + 4.01 * A3_INC})
    me, other = c.pages
    if finds == "limit":  # room for one increment beyond those in flight: it runs, no more
        mine, ran = JogRequest("axis", "A3", 1, None, 100.0), 1
    else:
        mine, ran = JogRequest("axis", "A6", -1, 1.0, 100.0), 2
    assert await c.jog.press(me, 1, mine) is None
    start = c.jog.jog.start  # type: ignore[union-attr]

    async def moved() -> bool:
        return await c.number("JOG_COUNT") == start + ran and not c.emu.robot.kernel.moving  # type: ignore[union-attr]

    await wait_until(moved, timeout=5)  # it ran; no watchdog has noticed yet
    info = next(i for i in c.emu.connections() if i.index == 3)
    c.emu.faults.add(Fault("delay", nth=info.received + 1, connection=3, seconds=0.3))
    if finds == "read failed":
        c.emu.faults.add(Fault("close", nth=info.received + 1, connection=3))
    dog = await c.watchdog()
    try:
        await asyncio.sleep(0.05)  # the watchdog's first top-up is out: its reply held
        release = asyncio.create_task(c.jog.release(me))
        await asyncio.sleep(0)  # the release holds the controller first
        theirs = JogRequest("axis", "A1", 1, None, 100.0)
        assert await c.jog.press(other, 1, theirs) is None
        await release
        await asyncio.sleep(0.1)  # the stale top-up has come back
        assert c.jog.jog is not None and c.jog.jog.owner is other, c.jog.last_stop
        assert c.jog.last_stop is not None and c.jog.last_stop[0] == "released"
        await c.jog.release(other)
    finally:
        dog.cancel()


async def test_silent_page_is_stopped_after_the_hold_timeout(cell: Factory) -> None:
    """The watchdog as the server runs it (its default period): a jog without keep-alives
    stops once the hold timeout has passed, not before, and names it; and again for the next
    silent press."""
    c = await cell(hold_timeout=0.55)
    me = c.pages[0]
    dog = asyncio.create_task(c.jog.run())
    loop = asyncio.get_running_loop()

    async def stopped() -> bool:
        return c.jog.jog is None

    try:
        for press in range(1, 4):  # a loaded machine may hold the loop: tried up to 3 times
            pressed = loop.time()
            assert await c.jog.press(me, press, A1_UP) is None
            await wait_until(stopped, timeout=5, interval=0.002)
            took = loop.time() - pressed
            assert took >= 0.55
            assert c.jog.last_stop is not None
            assert c.jog.last_stop[0] == "no keep-alive from the page for 550 ms"
            if took < 0.55 + 0.4:  # the watchdog looks every 10 ms
                break
        else:
            pytest.fail(f"the silent jog was stopped only after {took:.2f} s")
        await idle(c)
        c.jog.hold_timeout = HOLD_TIMEOUT  # the real 100 ms
        assert await c.jog.press(me, 9, A1_UP) is None
        await wait_until(stopped, timeout=5)
        assert c.jog.last_stop[0] == "no keep-alive from the page for 100 ms"
        assert await c.kvp.read("JOG_MODE") == "0"
    finally:
        dog.cancel()


async def test_top_ups_give_only_the_room_left(cell: Factory) -> None:
    """At override 0 the program plans but the arm does not move, so every top-up sees the
    same axes: a jog with room for 4 increments keeps JOG_UNTIL exactly 1 ahead of the count
    (3 may be in flight) and goes on; one without a limit near keeps it 5 ahead; a step never
    past its end."""
    c = await cell(softp={3: 90.0 + 0.5 + 4.01 * A3_INC})
    me = c.pages[0]
    await c.kvp.write("$OV_PRO", "0")
    dog = await c.watchdog()
    loop = asyncio.get_running_loop()
    try:
        for press, req, ahead in (
            (1, JogRequest("axis", "A3", 1, None, 100.0), 1),
            (2, JogRequest("axis", "A1", 1, None, 100.0), CREDIT),
        ):
            assert await c.jog.press(me, press, req) is None
            sent = requests(c)
            t0 = loop.time()
            end = t0 + 0.3  # several top-ups (one every 40 ms)
            while loop.time() < end:
                await c.jog.press(me, press, req)
                await asyncio.sleep(0.02)
            # each top-up is 3 reads and a write, never more often than every 40 ms
            assert requests(c) - sent <= 4 * ((loop.time() - t0) / 0.04 + 2)
            assert c.jog.jog is not None, c.jog.last_stop
            count, until = await c.number("JOG_COUNT"), await c.number("JOG_UNTIL")
            assert until == count + ahead
            await c.jog.release(me)
        step = JogRequest("axis", "A1", 1, 1.0, 100.0)  # 4 increments
        assert await c.jog.press(me, 3, step) is None
        start = c.jog.jog.start  # type: ignore[union-attr]
        end = loop.time() + 0.3
        while loop.time() < end:
            await c.jog.press(me, 3, step)
            await asyncio.sleep(0.02)
        assert await c.number("JOG_UNTIL") == start + 4
        await c.jog.release(me)
    finally:
        dog.cancel()


async def test_keep_alives_hold_the_jog(cell: Factory) -> None:
    """Keep-alives every 20 ms hold a jog for three times the hold timeout. A loaded machine
    may stall the loop beyond the timeout: the try is repeated with a new press then."""
    timeout = 0.25
    c = await cell(hold_timeout=timeout)
    me = c.pages[0]
    dog = await c.watchdog()
    loop = asyncio.get_running_loop()
    try:
        for press in range(1, 6):
            assert await c.jog.press(me, press, A1_UP) is None
            t0 = last = loop.time()
            gap = 0.0
            while loop.time() - t0 < 3 * timeout and c.jog.jog is not None:
                await asyncio.sleep(0.02)
                gap = max(gap, loop.time() - last)
                last = loop.time()
                await c.jog.press(me, press, A1_UP)
            if gap < timeout / 2:  # the keep-alives really came in time
                assert c.jog.jog is not None, c.jog.last_stop
                break
            await c.jog.release(me)
        else:
            pytest.skip("the machine never gave the loop 125 ms in time")
        await c.jog.release(me)
    finally:
        dog.cancel()


async def test_lost_link_or_control_connection_stops_the_jog(cell: Factory) -> None:
    c = await cell(auto_reconnect=False)
    me = c.pages[0]
    dog = await c.watchdog()
    try:
        assert await c.jog.press(me, 1, A1_UP) is None
        c.link.connected = False  # what the link's poll loop records when the robot is lost

        async def stopped() -> bool:
            return c.jog.jog is None

        await wait_until(stopped, timeout=5)
        assert c.jog.last_stop is not None
        assert c.jog.last_stop[0] == "the live state of the robot is lost"
        await idle(c)
        c.link.connected = True
        assert await c.jog.press(me, 2, A1_UP) is None
        await c.control.close()  # the controller's connection goes (no reconnect here)
        await wait_until(stopped, timeout=5)
        reason = c.jog.last_stop[0]
        assert reason.startswith("cannot read JOG_COUNT: ") and len(reason) > 23, reason
    finally:
        dog.cancel()


async def test_failed_topup_write_ends_the_jog(cell: Factory) -> None:
    c = await cell()
    me = c.pages[0]
    assert await c.jog.press(me, 1, A1_UP) is None
    c.cut(3 + 1)  # the first top-up's three reads go through, its JOG_UNTIL is cut
    dog = await c.watchdog()
    try:

        async def stopped() -> bool:
            await c.jog.press(me, 1, A1_UP)
            return c.jog.jog is None

        await wait_until(stopped, timeout=5)
        assert c.jog.last_stop is not None
        assert c.jog.last_stop[0].startswith("write failed: "), c.jog.last_stop
        assert await c.jog.press(me, 1, A1_UP) is None and c.jog.jog is None  # ended
        await idle(c)  # zeroed on the new connection
        assert await c.kvp.read("JOG_UNTIL") == "0"
    finally:
        dog.cancel()


#: A tool and a base that are not the identity: a Cartesian jog must solve with both.
TOOL = "{X 20.0, Y -10.0, Z 150.0, A 15.0, B 5.0, C 0.0}"
BASE = "{X 50.0, Y 30.0, Z -20.0, A 25.0, B 0.0, C 0.0}"


async def cartesian_cell(cell: Factory, tool: str = TOOL, base: str = BASE) -> Cell:
    """A cell with ``tool`` and ``base``, the arm out of HOME's wrist singularity (an A5 step
    of 10 degrees), standing still."""
    c = await cell(system={"$TOOL": tool, "$BASE": base})
    await c.step(JogRequest("axis", "A5", 1, 10.0, 100.0))
    return c


async def pad_with_limits(c: Cell, lo: np.ndarray, hi: np.ndarray) -> JogController:
    """A new pad (link and controller) that sees the software limits ``lo``, ``hi``."""
    for i in range(6):
        c.emu.store.set_system(f"$SOFTN_END[{i + 1}]", float(lo[i]))
        c.emu.store.set_system(f"$SOFTP_END[{i + 1}]", float(hi[i]))
    link = RobotLink("127.0.0.1", c.emu.port, timeout=2.0)
    await link.poll_once()
    jog = JogController(c.control, link, hold_timeout=5.0)
    c.links.append(link)
    return jog


async def ahead(c: Cell, req: JogRequest, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The axes now, and where ``n`` increments of ``req`` lead (the TCP moved in $BASE or
    $TOOL, solved with the tool and base from the axes now)."""
    got = await c.kvp.read_many(["$AXIS_ACT", "$POS_ACT", "$TOOL", "$BASE"], typed=True)
    q, pose = axes_of(got["$AXIS_ACT"].value), frame6(got["$POS_ACT"].value)
    tool, base = frame6(got["$TOOL"].value), frame6(got["$BASE"].value)
    assert q is not None and pose is not None and tool is not None and base is not None
    plan = plan_jog(req, KR6R900SIXX)
    target = advance_pose(pose, plan.increment, n, tool=req.frame == "tool")
    return q, inverse(KR6R900SIXX, target, current=q, tool=tool, base=base)


@pytest.mark.parametrize(
    "req",
    [
        JogRequest("base", "X", 1, None, 100.0),
        JogRequest("base", "X", -1, None, 100.0),
        JogRequest("tool", "Z", 1, None, 100.0),
        JogRequest("tool", "Z", -1, None, 100.0),
    ],
    ids=["base X+", "base X-", "tool Z+", "tool Z-"],
)
async def test_cartesian_press_needs_the_pose_ahead_within_the_limits(
    cell: Factory, req: JogRequest
) -> None:
    """The TCP :data:`CREDIT` + 3 increments ahead (those that may be in flight), solved from
    the axes now, must stay 0.5 deg inside every software limit. Limits just wide enough: the
    jog starts; a hair narrower on the axis that moves most: it is refused."""
    c = await cartesian_cell(cell)
    q, q8 = await ahead(c, req, CREDIT + 3)
    _, q7 = await ahead(c, req, CREDIT + 2)
    lo, hi = np.minimum(q, q8) - 0.5 - 1e-3, np.maximum(q, q8) + 0.5 + 1e-3
    jog = await pad_with_limits(c, lo, hi)
    count = await c.number("JOG_COUNT")
    assert await jog.press(c.pages[0], 1, req) is None
    assert await c.number("JOG_UNTIL") == count + CREDIT
    assert await c.kvp.read("JOG_MODE") == str(2 if req.frame == "base" else 3)
    await jog.release(c.pages[0])
    await idle(c)
    # the axis that turns up most, then the one that turns down most: its limit between 7 and
    # 8 increments ahead (the others wide), each limit refuses the jog on its own
    q, q8 = await ahead(c, req, CREDIT + 3)
    _, q7 = await ahead(c, req, CREDIT + 2)
    moves = q8 - q
    for press, i in enumerate((int(np.argmax(moves)), int(np.argmin(moves))), start=2):
        if abs(moves[i]) < 0.01:
            continue  # no axis turns that way noticeably
        lo, hi = np.minimum(q, q8) - 0.5 - 1e-3, np.maximum(q, q8) + 0.5 + 1e-3
        middle = (q7[i] + q8[i]) / 2
        if moves[i] > 0:
            hi[i] = middle + 0.5
        else:
            lo[i] = middle - 0.5
        jog = await pad_with_limits(c, lo, hi)
        refused = await jog.press(c.pages[0], press, req)
        sign = "+" if req.direction > 0 else "-"
        assert refused == f"{req.key} {sign}: out of reach or a singularity ahead", i
        assert await c.kvp.read("JOG_MODE") == "0"


async def test_cartesian_step_is_checked_whole(cell: Factory) -> None:
    """A step needs its own end within the limits, no increments in flight beyond it."""
    c = await cartesian_cell(cell)
    req = JogRequest("base", "X", 1, 10.0, 100.0)  # 5 increments of 2 mm
    q, q5 = await ahead(c, req, 5)
    _, q6 = await ahead(c, req, 6)
    i = int(np.argmax(np.abs(q6 - q)))
    lo, hi = np.minimum(q, q5) - 0.5 - 1e-3, np.maximum(q, q5) + 0.5 + 1e-3
    middle = (q5[i] + q6[i]) / 2  # the 6th increment would pass the limit, the step's 5 not
    if q6[i] > q5[i]:
        hi[i] = middle + 0.5
    else:
        lo[i] = middle - 0.5
    jog = await pad_with_limits(c, lo, hi)
    count = await c.number("JOG_COUNT")
    assert await jog.press(c.pages[0], 1, req) is None
    assert await c.number("JOG_UNTIL") == count + 5
    await jog.release(c.pages[0])


@pytest.mark.parametrize(("low", "high", "ok"), [(16.5, 23.5, True), (24.5, 31.5, False)])
async def test_cartesian_jog_stops_before_a_joint_would_jump(
    cell: Factory, low: float, high: float, ok: bool
) -> None:
    """Near the wrist singularity a small turn of the TCP swings A4 and A6 far: a jog whose
    8 increments ahead move a joint more than 20 deg + 0.5 deg per increment (24 deg) is
    refused. The override picks how far a base A+ turn goes."""
    c = await cartesian_cell(cell)
    for ov in np.arange(100.0, 1.0, -1.0):
        req = JogRequest("base", "A", 1, None, float(ov))
        q, q8 = await ahead(c, req, CREDIT + 3)
        if low < np.max(np.abs(q8 - q)) < high:
            break
    else:
        pytest.fail(f"no override swings a joint by {low}..{high} deg")
    refused = await c.jog.press(c.pages[0], 1, req)
    if ok:
        assert refused is None
    else:
        assert refused == "A +: out of reach or a singularity ahead"
    await c.jog.release(c.pages[0])


async def test_cartesian_jog_out_of_reach_is_refused(cell: Factory) -> None:
    """With a 4 m tool a turn about the TCP swings the flange out of the arm's reach."""
    c = await cartesian_cell(cell, tool="{X 0.0, Y 0.0, Z 4000.0, A 0.0, B 0.0, C 0.0}")
    refused = await c.jog.press(c.pages[0], 1, JogRequest("tool", "B", 1, None, 100.0))
    assert refused == "B +: out of reach or a singularity ahead"
    assert await c.kvp.read("JOG_MODE") == "0"


async def test_the_solution_nearest_the_arm_is_the_one_checked(cell: Factory) -> None:
    """A wrist turned far (A4 100, A6 -100) is nearer the other wrist solution for HOME: the
    pose ahead must be solved nearest the axes now, or a small base move would look like a
    180 deg swing of A4."""
    c = await cell(axes=E6Axis(a1=0.0, a2=-90.0, a3=90.0, a4=100.0, a5=10.0, a6=-100.0))
    await c.step(JogRequest("axis", "A1", 1, 0.1, 100.0))  # the robot publishes its pose
    assert await c.jog.press(c.pages[0], 1, JogRequest("base", "X", 1, None, 100.0)) is None
    assert await c.kvp.read("JOG_MODE") == "2"
    await c.jog.release(c.pages[0])


@pytest.mark.parametrize("missing", ["$POS_ACT", "$AXIS_ACT"])
async def test_a_position_the_robot_does_not_give_means_no_jog(cell: Factory, missing: str) -> None:
    """A controller without $POS_ACT (or $AXIS_ACT): no jog, and no crash. The pad's
    controller talks to a robot-less emulator that has the jog globals and only the other
    of the two; the link (whose program state allows jogging) is the real cell's."""
    c = await cell()
    store = VariableStore(system=False, default_config=False)
    store.declare("JOG_COUNT", "INT", init="0")
    if missing == "$POS_ACT":
        store.declare("$AXIS_ACT", "E6AXIS", init="{A1 0, A2 -90, A3 90, A4 0, A5 10, A6 0}")
    else:
        store.declare("$POS_ACT", "E6POS", init="{X 500, Y 0, Z 800, A 0, B 90, C 0}")
    config = EmulatorConfig(port=0, latency="none", discovery=False, robot=False)
    async with (
        Emulator(config, store=store) as odd,
        Client("127.0.0.1", odd.port, timeout=2.0) as client,
    ):
        jog = JogController(client, c.link)
        refused = await jog.press(c.pages[0], 1, JogRequest("base", "X", 1, None, 100.0))
        assert refused == "X +: out of reach or a singularity ahead"
        if missing == "$AXIS_ACT":
            assert await jog.press(c.pages[0], 2, A1_UP) == "software limit +A1 ahead"
        assert jog.jog is None


async def test_the_arm_jogged_is_the_one_given_else_the_links(cell: Factory) -> None:
    """``model=`` (``kvp web --robot``) plans with that arm's accelerations."""
    c = await cell()
    assert c.jog.model is c.link.model
    other = given_arm("kr10_r1100_2").model
    jog = JogController(c.control, c.link, model=other)
    assert jog.model is other
    assert await jog.press(c.pages[0], 1, A1_UP) is None
    assert await c.number("JOG_ACC") == plan_jog(A1_UP, other).acc[0]
    assert plan_jog(A1_UP, other).acc[0] != plan_jog(A1_UP, c.link.model).acc[0]
    await jog.release(c.pages[0])


async def test_the_first_top_up_comes_a_top_up_period_after_the_press(cell: Factory) -> None:
    """The press itself gave the credit: the watchdog reads the robot again only 40 ms later
    (a loaded machine may stretch the look, so it is repeated until it lands inside 30 ms)."""
    c = await cell()
    me = c.pages[0]
    dog = await c.watchdog()
    loop = asyncio.get_running_loop()
    try:
        for press in range(1, 8):
            t0 = loop.time()
            assert await c.jog.press(me, press, A1_UP) is None
            sent = requests(c)
            await asyncio.sleep(0.015)  # the watchdog looks every 5 ms
            if loop.time() - t0 < 0.03:
                assert requests(c) == sent  # no top-up yet
                break
            await c.jog.release(me)
        else:
            pytest.skip("the machine never gave the loop 30 ms in time")
        await c.jog.release(me)
    finally:
        dog.cancel()
