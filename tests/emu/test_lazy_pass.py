"""Lazy SPS passes (``kukavarproxy_emu.krl.lazy_pass``): nobody can tell them from eager ones.

Each comparison runs two robots in lockstep from the same configuration and seed (dynamic
plant, fresh sensor noise every cycle): one whose submit interpreter runs passes lazily, one
that runs every pass statement by statement (``sps.lazy = False``, the executor before). What
either shows at any moment, to a read of the store, a text read, a write from outside, the
robot program or a client over TCP, must be the same.
"""

from __future__ import annotations

import asyncio
import itertools
from dataclasses import replace
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from kukavarproxy_emu import Emulator, EmulatorConfig
from kukavarproxy_emu.krl.executor import KrlSubmit, load_module
from kukavarproxy_emu.plant.sensors import Sensors
from kukavarproxy_emu.responder import build_store
from kukavarproxy_emu.robot_task import Robot
from kukavarproxy_emu.store import UnknownVariable, VariableStore, WriteRefused
from kukavarproxy_emu.testing import TEST_CONFIG, wait_until
from pyopenshowvar import Client, Snapshot
from pyopenshowvar.krl import Struct

CELL = Snapshot("CELL", ["$AXIS_ACT", "$POS_ACT", "$TORQUE_AXIS_ACT[]"])  # README's snapshot
CFG = replace(TEST_CONFIG, seed=11)
_ids = itertools.count()


def _robot(cfg: EmulatorConfig = CFG, program: str = "none", sps: str | None = None) -> Robot:
    return Robot(build_store(cfg), program=program, sps=sps, plant="dynamic", seed=11)


@pytest.fixture(scope="module")
def pair() -> tuple[Robot, Robot]:
    """Two resting robots in lockstep (no SPS yet: each example installs its own)."""
    lazy, eager = _robot(), _robot()
    for r in (lazy, eager):
        r.begin()
        for _ in range(5):
            r.tick()
    return lazy, eager


# --- random SPS passes ------------------------------------------------------------------------
# The statements a pass is made of: the snapshot's forms (a counter, copies of readings and of
# globals, the structure published whole) and a few others (a carried REAL, a statement that is
# no plan, which makes the whole pass eager). {W}, {G}, {X}, {Y} are the example's globals.
STATEMENTS = [
    "IF {W}.C < {L} THEN\n{W}.C = {W}.C + 1\nELSE\n{W}.C = 1\nENDIF",
    "{W}.A = $AXIS_ACT",
    "{W}.P = $POS_ACT",
    "{W}.R = $TORQUE_AXIS_ACT[2]",
    "{W}.R = $VEL_ACT",
    "{W}.R = {Y}",
    "{W}.C = {X}",
    "{W}.R = 1.5",
    "{G} = {W}",
    "{G}.C = {W}.C",
    "{X} = {X} + 1",
    "{Y} = $TORQUE_AXIS_ACT[4]",
    "{W}.R = {W}.R + 0.5",
    "{W}.R = {W}.R * 2",
]


def _install(robot: Robot, tmp: Path, body: list[str], n: int) -> dict[str, str]:
    names = {"W": f"W{n}", "G": f"G{n}", "X": f"X{n}", "Y": f"Y{n}", "L": "4"}
    src = tmp / f"p{n}.sub"
    dat = tmp / f"p{n}.dat"
    lines = [s.format(**names) for s in body]
    src.write_text("\n".join([f"DEF P{n}()", "LOOP", *lines, "ENDLOOP", "END", ""]))
    dat.write_text(
        "\n".join(
            [
                f"DEFDAT P{n}",
                f"STRUC T{n}_T INT C, REAL R, E6AXIS A, E6POS P, BOOL B",
                f"DECL GLOBAL T{n}_T {names['W']}={{C 0, R 0.0}}",
                f"DECL GLOBAL T{n}_T {names['G']}",
                f"DECL GLOBAL INT {names['X']}=0",
                f"DECL GLOBAL REAL {names['Y']}=0.25",
                "ENDDAT",
                "",
            ]
        )
    )
    sps = KrlSubmit(load_module(src), robot.store, ipo=robot.kernel.ipo)
    sps.start()
    robot.sps = sps
    return names


def _observe(robot: Robot, action: tuple[str, str, str]) -> object:
    """One look at (or write into) the robot from outside; what it returned or raised."""
    kind, name, text = action
    store = robot.store
    try:
        if kind == "get":
            return store.get(name)
        if kind == "read":
            return store.read(name)
        return store.write(name, text)
    except (UnknownVariable, WriteRefused) as exc:
        return type(exc).__name__


def _actions(names: dict[str, str]) -> st.SearchStrategy[list[tuple[str, str, str]]]:
    w, g, x, y = names["W"], names["G"], names["X"], names["Y"]
    looks = st.sampled_from([
        ("get", g, ""), ("get", w, ""), ("read", g, ""), ("read", f"{w}.C", ""),
        ("get", f"{g}.A", ""), ("get", x, ""), ("get", "$AXIS_ACT", ""),
        ("write", f"{w}.C", "2147483646"), ("write", f"{w}.R", "3.0"), ("write", x, "7"),
        ("write", y, "-1.5"), ("write", g, "{C 5}"), ("write", x, "2147483647"),
    ])  # fmt: skip
    ticks = st.integers(1, 9).map(lambda k: ("tick", str(k), ""))
    return st.lists(st.one_of(looks, ticks), min_size=1, max_size=12)


@settings(
    max_examples=30,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(
    # a counter most of the time, as a snapshot has (it makes the pass change every cycle)
    counter=st.sampled_from([[STATEMENTS[0]], [STATEMENTS[0]], []]),
    body=st.lists(st.sampled_from(STATEMENTS[1:]), min_size=1, max_size=6),
    data=st.data(),
)
def test_a_lazy_pass_shows_what_an_eager_one_shows(
    pair: tuple[Robot, Robot], tmp_path_factory: pytest.TempPathFactory, counter: list[str],
    body: list[str], data: st.DataObject,
) -> None:  # fmt: skip
    """Random passes of the snapshot's forms and others, random looks and writes between
    random runs of ticks: every look gets the same answer from both robots, and the SPS stops
    (an INT overflow) at the same pass with the same message."""
    lazy, eager = pair
    tmp = tmp_path_factory.mktemp("p")
    n = next(_ids)
    body = counter + body
    names = _install(lazy, tmp, body, n)
    _install(eager, tmp, body, n)
    assert lazy.sps is not None and eager.sps is not None
    eager.sps.lazy = False
    for action in data.draw(_actions(names)):
        if action[0] == "tick":
            for _ in range(int(action[1])):
                lazy.tick()
                eager.tick()
            continue
        assert _observe(lazy, action) == _observe(eager, action), action
        if action[0] == "write":  # and what the write left there, at once
            look = ("get", action[1].split(".")[0], "")
            assert _observe(lazy, look) == _observe(eager, look), action
    for name in ("W", "G", "X", "Y"):
        look = ("get", names[name], "")
        assert _observe(lazy, look) == _observe(eager, look), name
    assert lazy.store.get("$PRO_STATE0") == eager.store.get("$PRO_STATE0")
    assert lazy.sps.message == eager.sps.message


def test_what_a_pass_defers(pair: tuple[Robot, Robot], tmp_path: Path) -> None:
    """The snapshot's shape: the counter runs, the copies wait. A write on one way of an IF
    kills nothing: the pass publishing W keeps that IF running."""
    lazy, eager = pair
    for body, carried, deferred in (
        ([STATEMENTS[0], "{W}.A = $AXIS_ACT", "{W}.R = {Y}", "{G} = {W}"], 1, 3),
        (["IF {Y} > 0.5 THEN\n{W}.R = 1.0\nENDIF", "{G} = {W}"], 1, 1),
    ):
        _install(lazy, tmp_path, body, next(_ids))
        assert lazy.sps is not None
        for _ in range(2):
            lazy.tick()
            eager.tick()  # the pair stays in lockstep (same plant cycle, same noise)
        lazy_pass = lazy.sps._lazy
        assert lazy_pass is not None, body
        assert (len(lazy_pass.carried), len(lazy_pass.deferred)) == (carried, deferred)


# --- the snapshot -----------------------------------------------------------------------------
def _snapshot_robots(tmp_path: Path, program: str = "none") -> tuple[Robot, Robot]:
    dat, sub = CELL.write_krl(tmp_path)
    cfg = replace(CFG, config_files=(dat,))
    robots = _robot(cfg, sps=str(sub), program=program), _robot(cfg, sps=str(sub), program=program)
    assert robots[1].sps is not None
    robots[1].sps.lazy = False
    for r in robots:
        r.begin()
    return robots


def test_the_snapshot_runs_lazily_and_copies_nothing_nobody_reads(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """README's snapshot at rest: no reading is computed while nobody reads (not the noise,
    not the forward kinematics), the clock may coast, and a read gets exactly the pass the
    eager robot made: the counter and the members of the same cycle."""
    lazy, eager = _snapshot_robots(tmp_path)
    poses: list[int] = []
    values = Sensors._pose_values

    def counted(self: Sensors, *args: object) -> dict[str, object]:
        poses.append(self.ticks)
        return values(self, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(Sensors, "_pose_values", counted)
    lazy.tick()  # the first pass runs as before (the interpreter reaches its LOOP's end)
    poses.clear()
    for _ in range(40):
        versions = [lazy.store.version(name) for name in ("CELL", "CELL_W")]
        lazy.tick()
        # both count as changed every pass, as when the pass runs (a KRL pass that read
        # them is not skipped as a repeat)
        assert all(
            lazy.store.version(n) > v for n, v in zip(("CELL", "CELL_W"), versions, strict=True)
        )
    assert poses == []  # 40 passes, no $POS_ACT computed for them
    assert lazy._quiet
    for _ in range(41):
        eager.tick()
    poses.clear()
    cell = lazy.store.get("CELL")
    assert len(poses) == 1  # the last pass's, made now
    assert cell == eager.store.get("CELL")
    assert isinstance(cell, Struct) and cell["CYCLE"] == 41
    assert cell["AXIS_ACT"] != lazy.store.get("$AXIS_ACT")  # a cycle older, fresh noise


def test_a_write_from_outside_lands_on_the_current_pass(tmp_path: Path) -> None:
    """A client writing the work copy or the published structure while a pass waits: the
    waiting pass is made first, the write lands on it, the next pass counts on from it."""
    lazy, eager = _snapshot_robots(tmp_path)
    for name, text in (("CELL_W.CYCLE", "1000"), ("CELL.CYCLE", "7"), ("CELL_W", "{CYCLE 5}")):
        for _ in range(4):
            lazy.tick()
            eager.tick()
        for robot in (lazy, eager):
            robot.store.write(name, text)
        assert lazy.store.get("CELL") == eager.store.get("CELL"), name
        assert lazy.store.get("CELL_W") == eager.store.get("CELL_W"), name
    lazy.tick()
    eager.tick()
    assert lazy.store.get("CELL") == eager.store.get("CELL")
    assert lazy.store.get("CELL.CYCLE") == 6


def test_the_robot_program_reads_the_current_pass(tmp_path: Path) -> None:
    """A robot program reading the snapshot every cycle (before the SPS runs) sees, cycle by
    cycle, what it sees on the eager robot: the pass of the cycle before."""
    (tmp_path / "watch.src").write_text(
        "DEF WATCH()\nWAIT FOR CELL_W.CYCLE > 2\nLOOP\nSEEN = CELL.CYCLE\n"
        "SEEN_A1 = CELL.AXIS_ACT.A1\nWAIT SEC 0\nENDLOOP\nEND\n"
    )
    (tmp_path / "watch.dat").write_text(
        "DEFDAT WATCH PUBLIC\nDECL GLOBAL INT SEEN=0\nDECL GLOBAL REAL SEEN_A1=0.0\nENDDAT\n"
    )
    lazy, eager = _snapshot_robots(tmp_path, program=str(tmp_path / "watch.src"))
    seen: list[tuple[object, object]] = []
    for _ in range(25):
        lazy.tick()
        eager.tick()
        a = (lazy.store.get("SEEN"), lazy.store.get("SEEN_A1"))
        assert a == (eager.store.get("SEEN"), eager.store.get("SEEN_A1"))
        seen.append(a)
    assert len({s[0] for s in seen}) > 15  # it did count along


async def test_over_tcp_every_read_is_one_whole_pass_of_its_cycle(tmp_path: Path) -> None:
    """A client reading README's snapshot at random moments of a resting robot (which coasts
    in between): each reply is exactly the structure an eager twin, ticked by hand to that
    pass, holds (counter and members of one pass, the same sensor noise), and the counter
    moved by one per tick of the robot's clock: no pass skipped, none twice."""
    dat, sub = CELL.write_krl(tmp_path)
    cfg = replace(CFG, config_files=(dat,), sps=str(sub))
    texts: list[str] = []
    counted: list[tuple[int, int]] = []
    async with Emulator(cfg) as emu:
        robot = emu.robot
        assert robot is not None
        await wait_until(lambda: robot.clock.coasted > 0, what="a coast")
        async with Client("127.0.0.1", emu.port, timeout=5.0, keepalive=None) as kvp:
            for pause in (0.03, 0.11, 0.0, 0.05, 0.13, 0.02):
                await asyncio.sleep(pause)
                texts.append(await kvp.read("CELL"))
                # the reply is computed once the due ticks ran: clock and counter agree
                cycle = emu.store.get("CELL.CYCLE")
                assert isinstance(cycle, int)
                counted.append((robot.clock.ticks, cycle))
    steps = [(t1 - t0, c1 - c0) for (t0, c0), (t1, c1) in itertools.pairwise(counted)]
    assert all(dt == dc for dt, dc in steps), steps
    twin = Robot(build_store(cfg), program=cfg.robot_program, sps=str(sub), plant="dynamic",
                 seed=cfg.seed)  # fmt: skip
    assert twin.sps is not None
    twin.sps.lazy = False
    twin.begin()
    at = 0
    for text in texts:
        cycle = int(text.split("CYCLE ", 1)[1].split(",", 1)[0])
        while at < cycle:
            twin.tick()
            at += 1
        assert text == twin.store.read("CELL"), cycle


# --- KRL semantics of structure members (the store's copy-on-write) ---------------------------
MEMBER_OPS = st.lists(
    st.tuples(
        st.sampled_from(["A", "B", "C"]),
        st.one_of(
            st.tuples(st.just("member"), st.sampled_from(["X", "Y"]), st.integers(-5, 5)),
            st.tuples(st.just("whole"), st.sampled_from(["A", "B", "C"]), st.just(0)),
        ),
    ),
    min_size=1,
    max_size=12,
)


def _run_once(tmp: Path, lines: list[str]) -> tuple[VariableStore, KrlSubmit]:
    """A submit program running ``lines`` once (then an empty LOOP) over three structures
    ``A``, ``B``, ``C`` of a user STRUC (the placeholder ``{n}`` in ``lines``: a fresh name)."""
    n = next(_ids)
    (tmp / f"m{n}.sub").write_text(
        "\n".join([f"DEF M{n}()", *(line.format(n=n) for line in lines), "LOOP", "ENDLOOP",
                   "END", ""])
    )  # fmt: skip
    (tmp / f"m{n}.dat").write_text(
        "\n".join([
            f"DEFDAT M{n}", f"STRUC S{n}_T INT X, INT Y",
            *(f"DECL GLOBAL S{n}_T {v}{n}={{X 0, Y 0}}" for v in "ABC"), "ENDDAT", "",
        ])
    )  # fmt: skip
    store = build_store(CFG)
    sps = KrlSubmit(load_module(tmp / f"m{n}.sub"), store)
    sps.start()
    sps.step()
    assert sps.running, sps.message
    return store, sps


@settings(max_examples=30, deadline=None)
@given(ops=MEMBER_OPS)
def test_member_assignments_copy_on_write(
    tmp_path_factory: pytest.TempPathFactory, ops: list[tuple[str, tuple[str, str, int]]]
) -> None:
    """``A = B`` then ``B.X = 1`` leaves A alone, and every other mix of member and whole
    assignments between three structures ends as plain value semantics say (a Python model
    of dict copies)."""
    model = {v: {"X": 0, "Y": 0} for v in "ABC"}
    lines = []
    for var, (kind, what, value) in ops:
        if kind == "member":
            lines.append(f"{var}{{n}}.{what} = {value}")
            model[var] = {**model[var], what: value}
        else:
            lines.append(f"{var}{{n}} = {what}{{n}}")
            model[var] = dict(model[what])
    store, sps = _run_once(tmp_path_factory.mktemp("m"), lines)
    n = sps.module.name[1:]
    for v in "ABC":
        got = store.get(f"{v}{n}")
        assert isinstance(got, Struct)
        assert dict(got.members) == model[v], (v, lines)


def test_a_copied_structure_keeps_its_members(tmp_path: Path) -> None:
    """The case by hand: B copied into A, then B's members changed."""
    store, sps = _run_once(tmp_path, ["B{n}.X = 3", "A{n} = B{n}", "B{n}.X = 4", "B{n}.Y = 5"])
    n = sps.module.name[1:]
    assert store.get(f"A{n}.X") == 3 and store.get(f"A{n}.Y") == 0
    assert store.get(f"B{n}.X") == 4 and store.get(f"B{n}.Y") == 5


async def test_with_a_latency_profile_passes_run_as_before(tmp_path: Path) -> None:
    """Replies first: a reply computed at its deadline must not make a waiting pass (the
    readings, the copies), so with a latency profile every pass runs in its tick."""
    dat, sub = CELL.write_krl(tmp_path)
    cfg = replace(CFG, config_files=(dat,), sps=str(sub), latency="kvp")
    async with Emulator(cfg) as emu:
        robot = emu.robot
        assert robot is not None and robot.sps is not None
        ticks = robot.clock.ticks
        await wait_until(lambda: robot.clock.ticks >= ticks + 10)
        assert not emu.store.is_stale("CELL") and not emu.store.is_stale("CELL_W")
        assert robot.sps._lazy is None or robot.sps._lazy.pending is None
