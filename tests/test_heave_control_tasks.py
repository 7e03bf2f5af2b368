"""The heave control server's own duties, each in well under a second and without a robot
where none is needed: the start-up waits (the program's ready flag on a static emulator, a
platform that fails its first read), the accelerometer samples it feeds to the estimator (the
board's clock mapped onto ours, roll and pitch), the platform task's heartbeat and period
against the real platform simulator over Modbus TCP, a prediction that stops at ``max_lead``
past a stale platform stream, and ``stop()``: requests in flight finish, a task that hangs is
cancelled after the timeout.

The tasks against the robot (start-up, the target the robot follows, the lag estimator's feed)
are in tests/test_heave_control_server.py.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator

import numpy as np
import pytest
from pyopenshowvar_apps.heave.accel import AccelReader, AccelSample
from pyopenshowvar_apps.heave.control import ControlConfig, ControlLaw, ControlServer
from pyopenshowvar_apps.heave.geometry import PlatformPose
from pyopenshowvar_apps.heave.master import PlatformClient
from pyopenshowvar_apps.heave.operator import OperatorCommand, OperatorInput
from pyopenshowvar_apps.heave.registers import PlatformState
from pyopenshowvar_apps.heave.simulator import PlatformConfig, PlatformSimulator
from pyopenshowvar_apps.heave.waves import WaveGenerator

from kukavarproxy_emu.testing import EmulatorFactory
from pyopenshowvar import Client

THETA0 = np.array([20.0, -80.0, 100.0, 15.0, 55.0, 20.0])


# --- start-up waits --------------------------------------------------------------------------------
@pytest.fixture
async def not_ready(emulator_factory: EmulatorFactory) -> AsyncIterator[ControlServer]:
    """A server on a controller whose heave data list is loaded but whose program has not said
    it is ready."""
    emu = await emulator_factory(dat_text="DECL GLOBAL BOOL HEAVE_READY=FALSE\n", robot=False)
    async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
        yield ControlServer(kvp, None, config=ControlConfig(attitude="plc"))


async def test_waiting_for_the_robot_program_times_out_naming_its_flag(
    not_ready: ControlServer,
) -> None:
    server = not_ready
    started = time.monotonic()
    with pytest.raises(
        TimeoutError,
        match=r"^HEAVE_READY did not become TRUE within 0\.2 s: is heave\.src running\?$",
    ):
        await server.wait_robot_ready(timeout=0.2)
    assert time.monotonic() - started >= 0.2


async def test_the_robot_program_is_seen_ready_at_the_next_poll(not_ready: ControlServer) -> None:
    server, kvp = not_ready, not_ready.kvp
    waiting = asyncio.create_task(server.wait_robot_ready(timeout=10.0))
    await asyncio.sleep(0.1)
    assert not waiting.done()  # FALSE: still waiting
    await kvp.write("HEAVE_READY", "TRUE")
    set_at = time.monotonic()
    async with asyncio.timeout(10.0):
        theta0 = await waiting
    # polled every 50 ms: seen within half a second, also on a busy machine
    assert time.monotonic() - set_at < 0.5
    axes = await kvp.read_value("$AXIS_ACT")
    assert theta0 == pytest.approx([axes.a1, axes.a2, axes.a3, axes.a4, axes.a5, axes.a6])


async def test_a_start_the_platform_fails_raises_its_error_and_leaves_no_task(
    emulator_factory: EmulatorFactory,
) -> None:
    emu = await emulator_factory(dat_text="DECL GLOBAL BOOL HEAVE_READY=TRUE\n", robot=False)
    async with PlatformSimulator(PlatformConfig(port=0, accel=False, seed=3)) as sim:
        plc = await PlatformClient("127.0.0.1", sim.port).connect()
    # the PLC went away after the connection was made: the platform task's first read fails
    try:
        async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
            server = ControlServer(kvp, plc, None, config=ControlConfig(attitude="plc"))
            started = time.monotonic()
            with pytest.raises(ConnectionError, match="platform PLC"):
                await server.start()
            # at once (not after the 5 s allowed for a first answer), and nothing left running
            assert time.monotonic() - started < 4.0
            assert server._tasks == []
            assert not [t for t in asyncio.all_tasks() if t.get_name() == "platform"]
    finally:
        plc.close()


async def test_a_fused_attitude_starts_only_once_the_board_has_spoken(
    emulator_factory: EmulatorFactory, plc_port: int
) -> None:
    ready = "DECL GLOBAL BOOL HEAVE_READY=TRUE\nDECL GLOBAL FRAME HEAVE_TGT={X 0.0}\n"
    emu = await emulator_factory(dat_text=ready, robot=False)
    plc = await PlatformClient("127.0.0.1", plc_port).connect()
    board = AccelReader("/dev/null")  # its lines are handed over below, as its device would
    try:
        async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
            server = ControlServer(kvp, plc, board, config=ControlConfig(attitude="fused"))
            starting = asyncio.create_task(server.start())
            await _wait_for_rows(server)
            await asyncio.sleep(0.1)
            assert not starting.done()  # the PLC answers, the board has not spoken yet
            board.feed(b"1000,0.000,0.000\n", time.monotonic())
            async with asyncio.timeout(10.0):
                await starting
            assert server.estimator.ready
            await server.stop()
    finally:
        plc.close()


async def _wait_for_rows(server: ControlServer) -> None:
    async with asyncio.timeout(10.0):
        while not server.platform_rows:  # noqa: ASYNC110 (a plain deque: polled)
            await asyncio.sleep(0.01)


async def test_waiting_for_a_data_source_polls_until_it_answers() -> None:
    polls: list[float] = []

    def answers_at_the_fourth_poll() -> bool:
        polls.append(time.monotonic())
        return len(polls) >= 4

    # polled every 10 ms within the 2 s it is given: three waits, not three seconds
    await ControlServer._wait_for(answers_at_the_fourth_poll, 2.0, "the accelerometer stream")
    assert len(polls) == 4


# --- the accelerometer path -----------------------------------------------------------------------
def test_board_samples_reach_the_estimator_on_our_clock() -> None:
    # attitude "accel": roll and pitch come from the board alone, shifted back by its filter lag
    server = ControlServer(None, None, accel=object(), config=ControlConfig(attitude="accel"))
    lag = server.estimator.accel_lag
    assert not server.estimator.phi.ready
    # the board's millis() from 0 to 990 ms, each line received 100 s + its millis later on our
    # clock (no transport delay): a roll ramp of 10 deg/s and a pitch of -3 deg
    for millis in range(0, 1000, 10):
        sample = AccelSample(millis, 2.0 + 0.01 * millis, -3.0, 100.0 + millis / 1000.0)
        server._on_accel(sample)
    # the newest sample counts at its board time mapped onto ours, less the filter's delay
    assert server.estimator.phi.last_time == pytest.approx(100.99 - lag, abs=1e-9)
    assert server.estimator.theta.last_time == pytest.approx(100.99 - lag, abs=1e-9)
    pose = server.estimator.pose_at(100.5 - lag)
    assert pose.phi == pytest.approx(2.0 + 5.0, abs=1e-6)  # the roll ramp at millis 500
    assert pose.theta == pytest.approx(-3.0, abs=1e-6)


def test_a_late_board_line_counts_when_it_was_taken() -> None:
    # the least-delayed line fixes the board's clock offset; a line that arrives 80 ms late
    # still counts at its own millis(), not when it arrived
    server = ControlServer(None, None, accel=object(), config=ControlConfig(attitude="accel"))
    lag = server.estimator.accel_lag
    server._on_accel(AccelSample(1000, 1.0, 0.0, 50.0))
    server._on_accel(AccelSample(1010, 1.0, 0.0, 50.09))
    assert server.estimator.phi.last_time == pytest.approx(50.01 - lag, abs=1e-4)


# --- the platform task ----------------------------------------------------------------------------
class SlowPlatform(PlatformClient):
    """A real Modbus client of the simulator whose state reads take ``delay`` s longer (a slow
    link), and which notes when each heartbeat and state read was sent and answered."""

    def __init__(self, host: str, port: int, delay: float = 0.0) -> None:
        super().__init__(host, port)
        self.delay = delay
        self.beats: list[float] = []
        self.reads: list[tuple[float, float]] = []
        self.states: list[PlatformState] = []
        self.set_points: list[tuple[float, PlatformPose]] = []

    async def heartbeat(self) -> None:
        self.beats.append(time.monotonic())
        await super().heartbeat()

    async def set_pose(self, pose: PlatformPose) -> None:
        self.set_points.append((time.monotonic(), pose))
        await super().set_pose(pose)

    async def read_state(self) -> PlatformState:
        sent = time.monotonic()
        await asyncio.sleep(self.delay)
        state = await super().read_state()
        self.reads.append((sent, time.monotonic()))
        self.states.append(state)
        return state


@pytest.fixture
async def sim() -> AsyncIterator[PlatformSimulator]:
    async with PlatformSimulator(PlatformConfig(port=0, accel=False, seed=3)) as sim:
        yield sim


@pytest.fixture
def plc_port(sim: PlatformSimulator) -> int:
    return sim.port


async def _run_platform_task(server: ControlServer, until: object, timeout: float = 10.0) -> None:
    task = asyncio.create_task(server._platform_task())
    try:
        async with asyncio.timeout(timeout):
            while not until():  # type: ignore[operator]  # noqa: ASYNC110 (plain lists: polled)
                await asyncio.sleep(0.01)
    finally:
        server._stopping = True
        async with asyncio.timeout(timeout):
            await task


async def test_platform_task_beats_the_watchdog_every_quarter_second(plc_port: int) -> None:
    plc = await SlowPlatform("127.0.0.1", plc_port).connect()
    try:
        server = ControlServer(None, plc, None, config=ControlConfig(attitude="plc"))
        await _run_platform_task(server, lambda: len(plc.beats) >= 3)
    finally:
        plc.close()
    # no waves: a heartbeat at once, then one every 0.25 s of the 50 Hz loop, not every pass
    gaps = np.diff(plc.beats)
    assert np.all(gaps >= 0.2), gaps
    assert np.all(gaps <= 1.0), gaps  # well inside the PLC's 1 s watchdog, also on a busy machine
    assert len(plc.reads) > len(plc.beats)
    assert server._first_state.is_set() and len(server.platform_rows) == len(plc.reads)


async def test_platform_task_logs_each_state_and_keeps_the_newest_rows(
    sim: PlatformSimulator,
) -> None:
    # the plate tilting towards roll 3 deg, pitch -2 deg: its three legs at different angles
    sim.plc.sp_pose = PlatformPose(5.0, 3.0, -2.0)
    sim.plc.set_enable(True)
    plc = await SlowPlatform("127.0.0.1", sim.port).connect()
    try:
        server = ControlServer(None, plc, None, config=ControlConfig(attitude="plc"), max_rows=4)
        await _run_platform_task(server, lambda: len(plc.reads) >= 8)
    finally:
        plc.close()
    assert len(server.platform_rows) == 4  # a bounded log: the newest rows
    for row, state in zip(server.platform_rows, plc.states[-4:], strict=True):
        assert (row["heave"], row["roll"], row["pitch"]) == (state.heave, state.roll, state.pitch)
        assert (row["beta1"], row["beta2"], row["beta3"]) == state.beta
        assert row["status"] == float(state.status)
    assert len({*plc.states[-1].beta}) == 3  # the legs did differ


async def test_platform_task_sends_the_waves_of_its_own_time(plc_port: int) -> None:
    plc = await SlowPlatform("127.0.0.1", plc_port).connect()
    waves = WaveGenerator.random(5)
    try:
        server = ControlServer(None, plc, None, config=ControlConfig(attitude="plc"), waves=waves)
        server.wave_t0 = time.monotonic() - 30.0  # 30 s into the waves
        await _run_platform_task(server, lambda: len(plc.set_points) >= 5)
    finally:
        plc.close()
    assert not plc.beats  # the set-points feed the watchdog: no heartbeat needed
    for sent, pose in plc.set_points:
        # the wave pose at the pass's own time (taken a moment before the request went out)
        due = waves.pose(sent - server.wave_t0)
        assert (pose.z, pose.phi, pose.theta) == pytest.approx((due.z, due.phi, due.theta), abs=0.5)


def test_the_control_log_keeps_the_newest_rows() -> None:
    server = ControlServer(None, None, config=ControlConfig(attitude="plc"), max_rows=3)
    server.law = ControlLaw(server.config, THETA0)
    server.estimator.add_plc(0.0, 0.0, 0.0, 0.0)
    for k in range(1, 6):
        server._control_step(0.02 * k, 0.02, THETA0)
    assert [r["t"] for r in server.rows] == pytest.approx([0.06, 0.08, 0.1])


async def test_platform_task_keeps_its_period_whatever_the_link_takes(plc_port: int) -> None:
    # each read takes 50 ms more: the task sleeps the rest of its 80 ms period, no longer
    plc = await SlowPlatform("127.0.0.1", plc_port, delay=0.05).connect()
    period = 0.08
    try:
        server = ControlServer(
            None, plc, None, config=ControlConfig(attitude="plc", platform_period=period)
        )
        await _run_platform_task(server, lambda: len(plc.reads) >= 7)
    finally:
        plc.close()
    sent = np.array([s for s, _ in plc.reads])
    link = np.array([done - s for s, done in plc.reads])
    gaps = np.diff(sent)
    assert np.median(gaps) >= 0.9 * period, gaps  # it waits out its period ...
    # ... counting the time the link took: a loop that slept a whole period after each read
    # would come round a period plus a read later (waking late on a busy machine adds to both)
    assert np.median(gaps) - period < np.median(link), (gaps, link)


# --- prediction -----------------------------------------------------------------------------------
def _server_rising(lead: float | None = None) -> ControlServer:
    """A law at THETA0 and a platform whose heave rose at 10 mm/s until its stream stopped."""
    server = ControlServer(None, None, config=ControlConfig(attitude="plc", lead=lead))
    server.law = ControlLaw(server.config, THETA0)
    for k in range(20):  # 50 Hz samples up to t = 0.38 s, then nothing more
        server.estimator.add_plc(0.02 * k, 10.0 * 0.02 * k, 0.0, 0.0)
    server.set_compensation(True)
    return server


@pytest.mark.parametrize("t", [0.8, 3.0])
def test_a_stale_platform_stream_is_not_extrapolated_past_max_lead(t: float) -> None:
    max_lead = ControlConfig().max_lead
    # a 50 ms step: the smoother reaches these few millimetres of target in one step
    held = _server_rising()
    target_held = held._control_step(0.38 + max_lead, 0.05, THETA0)
    late = _server_rising()
    target_late = late._control_step(t, 0.05, THETA0)
    # "now" stops at the newest sample + max_lead, and so does the predicted pose
    assert late.rows[-1]["est_z"] == pytest.approx(10.0 * (0.38 + max_lead), abs=1e-6)
    assert target_late == pytest.approx(target_held, abs=1e-9)


# --- stop() ---------------------------------------------------------------------------------------
class CountingOperator(OperatorInput):
    def __init__(self) -> None:
        self.polls = 0
        self.closed = False

    def poll(self, t: float) -> OperatorCommand:
        self.polls += 1
        return OperatorCommand()

    def close(self) -> None:
        self.closed = True


async def test_stop_lets_a_request_in_flight_finish() -> None:
    server = ControlServer(None, None, config=ControlConfig(attitude="plc"))
    operator = server.operator = CountingOperator()
    answered = asyncio.Event()
    done: list[str] = []

    async def request_in_flight() -> None:
        while not server._stopping:  # like the I/O tasks: one request per pass
            await answered.wait()
        done.append("answered")

    server._tasks = [
        asyncio.create_task(server._guard(request_in_flight())),
        asyncio.create_task(server._guard(server._operator_task())),
    ]
    await asyncio.sleep(0)
    stopping = asyncio.create_task(server.stop(timeout=30.0))
    await asyncio.sleep(0.05)
    assert not stopping.done()  # it waits for the answer, it does not cut the request
    answered.set()
    async with asyncio.timeout(10.0):
        await stopping
    assert done == ["answered"] and server._tasks == [] and operator.closed
    assert operator.polls >= 1


async def test_stop_cancels_a_task_that_hangs_after_its_timeout() -> None:
    server = ControlServer(None, None, config=ControlConfig(attitude="plc"))
    cancelled = asyncio.Event()

    async def hangs() -> None:
        try:
            await asyncio.Event().wait()  # a peer that never answers
        except asyncio.CancelledError:
            cancelled.set()
            raise

    task = asyncio.create_task(server._guard(hangs()))
    server._tasks = [task]
    await asyncio.sleep(0)
    started = time.monotonic()
    async with asyncio.timeout(10.0):
        await server.stop(timeout=0.1)  # no CancelledError leaks out of stop()
    assert time.monotonic() - started >= 0.1
    assert cancelled.is_set() and task.cancelled() and server.error is None
    assert server._tasks == []
