"""The control server with simulated arms: the thesis' modes, switching at run time, stopping.

The server, the simulated arm and the scripted input share one simulated clock stepped by the
test (20 ms per tick), so the loop's behaviour does not depend on the machine's load; the
solvers' budgets count CPU time for the same reason.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from pyopenshowvar_apps.universal.inputs import ScriptedInput, circle, hold
from pyopenshowvar_apps.universal.server import ControlServer, Tick
from pyopenshowvar_apps.universal.sim import SimulatedArm

from pyopenshowvar.arms import load_arm

DT = 0.02


class Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


#: Start away from the stretched-out home where it has one (the SCARA's is singular).
START = {
    "adept_cobra600": (30.0, 60.0, 100.0, 0.0),
    "kuka_youbot_arm": (169.0, 40.0, -100.0, 100.0, 167.5),
}


async def rig(
    arm: str, device: ScriptedInput, *, engine: str = "auto", **kw: object
) -> tuple[ControlServer, Clock]:
    clock = Clock()
    backend = SimulatedArm(load_arm(arm), engine=engine, clock=clock, q0=START.get(arm))  # type: ignore[arg-type]
    options = {"clock": time.process_time, "seed": 1}
    server = ControlServer(backend, device, clock=clock, solver_options=options, **kw)  # type: ignore[arg-type]
    await server.start()
    return server, clock


async def run(server: ControlServer, clock: Clock, seconds: float) -> list[Tick]:
    out = []
    for _ in range(round(seconds / DT)):
        clock.t += DT
        out.append(await server.tick())
    return out


def _shape_error(ticks: list[Tick], ideal: np.ndarray) -> float:
    """RMS distance between the tip's path and the ideal one at the best constant lag
    (≤ 0.4 s) and offset: velocity mode has no memory of position, so what the drives lose
    while they accelerate from rest stays lost; the path's shape is what must match."""
    tips = np.array([t.tip for t in ticks])
    best = math.inf
    for lag in range(0, 21):
        shifted = ideal[: len(ideal) - lag] if lag else ideal
        d = tips[lag:] - shifted
        d = d - d.mean(axis=0)
        best = min(best, float(np.sqrt(np.mean(np.sum(d**2, axis=1)))))
    return best


@pytest.mark.parametrize(
    ("arm", "solver"),
    [("kr6_r900_sixx", "dls"), ("knuckle_boom_crane", "closed-form"), ("adept_cobra600", "dls")],
)
async def test_velocity_mode_tracks_a_scripted_circle(arm: str, solver: str) -> None:
    period, level = 4.0, 0.5
    server, clock = await rig(arm, ScriptedInput(circle(level, period), duration=period),
                              solver=solver, mode="velocity", k_v=None)  # fmt: skip
    ticks = await run(server, clock, period + 1.0)
    kv = server.mapping.k_v
    # the ideal tip: x0 + ∫ ẋ_ds dt with ẋ_ds = k_v·s(t) (eq. 2.8), the circle's velocity
    t = np.arange(1, len(ticks) + 1) * DT
    w = 2 * math.pi / period
    radius = kv * level / w
    on = np.minimum(t, period)
    ideal = ticks[0].tip + np.stack([radius * np.sin(w * on), radius * (1 - np.cos(w * on)),
                                     0 * on], axis=1)  # fmt: skip
    diameter = 2 * radius
    n = round(period / DT)
    assert _shape_error(ticks[:n], ideal[:n]) < 0.03 * diameter
    # released after one turn: the arm stops where it is, near where it started
    final = [tk for tk in ticks if tk.t - ticks[0].t > period + 0.6]
    assert np.linalg.norm(final[-1].tip - final[0].tip) < 0.01 * diameter  # (in 0.4 s)
    assert np.linalg.norm(final[-1].tip - ticks[0].tip) < 0.15 * diameter


async def test_position_mode_returns_to_the_start_on_release() -> None:
    device = ScriptedInput(hold((0.5, 0.0, 0.0), until=2.0))
    server, clock = await rig("kr6_r900_sixx", device, solver="closed-form", mode="position",
                              k_p=100.0)  # fmt: skip
    tip0 = server.solver.fk((await server.backend.feedback()).q)
    ticks = await run(server, clock, 2.0)
    assert (
        np.linalg.norm(ticks[-1].tip - (tip0 + np.array([50.0, 0, 0]))) < 0.5
    )  # x_ds = k_p·s + x_w
    ticks = await run(server, clock, 2.0)
    assert np.linalg.norm(ticks[-1].tip - tip0) < 0.5  # released: back to the start


async def test_position_mode_does_not_return_when_the_device_falls_silent() -> None:
    device = ScriptedInput(hold((0.5, 0.0, 0.0)), duration=2.0, end="silent")
    server, clock = await rig("kr6_r900_sixx", device, solver="closed-form", mode="position",
                              k_p=100.0)  # fmt: skip
    tip0 = server.solver.fk((await server.backend.feedback()).q)
    ticks = await run(server, clock, 2.0)
    held = ticks[-1].tip
    assert np.linalg.norm(held - (tip0 + np.array([50.0, 0, 0]))) < 0.5
    ticks = await run(server, clock, 1.5)
    silent = [tk for tk in ticks if not tk.alive]
    # stopped once the last sample is older than the deadline, and stays where it was
    assert silent[0].t - ticks[0].t <= server.deadline + DT
    assert all(np.all(tk.command == 0) for tk in silent)
    assert np.linalg.norm(ticks[-1].tip - held) < 0.5 and np.all(np.abs(ticks[-1].qdot) < 1e-3)


async def test_a_disconnected_device_stops_the_arm_within_the_deadline() -> None:
    device = ScriptedInput(hold((0.6, 0.0, 0.3)), duration=1.0, end="disconnect")
    server, clock = await rig("adept_cobra600", device, solver="dls", mode="velocity")
    ticks = await run(server, clock, 2.0)
    moving = [tk for tk in ticks if tk.alive]
    assert moving and np.linalg.norm(moving[-1].qdot) > 1.0
    stop_at = next(tk.t for tk in ticks if not tk.alive)
    assert stop_at - ticks[0].t <= 1.0 + 2 * DT
    # every command after the disconnect is zero, and the simulated drives come to rest
    assert all(np.all(tk.command == 0) for tk in ticks if tk.t >= stop_at)
    assert np.all(np.abs(ticks[-1].qdot) < 1e-3)


async def test_switching_solver_mode_and_arm_mid_run() -> None:
    device = ScriptedInput(circle(0.4, 4.0), duration=6.0,
                           commands=[(1.0, "solver", "pso"), (2.0, "solver", "next"),
                                     (3.0, "mode", "toggle"), (4.0, "arm", "adept_cobra600")])  # fmt: skip
    server, clock = await rig("knuckle_boom_crane", device, solver="dls", mode="velocity",
                              arms=["knuckle_boom_crane", "adept_cobra600"])  # fmt: skip
    speed = server.speed.copy()
    ticks = await run(server, clock, 5.0)
    seen = [(tk.solver, tk.mode, len(tk.q)) for tk in ticks]
    assert seen[10] == ("dls", "velocity", 3)
    assert seen[60] == ("pso", "velocity", 3)
    assert seen[110] == ("closed-form", "velocity", 3)  # next after pso: round again
    assert seen[160] == ("closed-form", "position", 3)
    assert seen[-1][2] == 4 and server.backend.arm.key == "adept_cobra600"
    # no switch jerks the crane: between two ticks no joint moves faster than its limit
    crane = [tk for tk in ticks if len(tk.q) == 3]
    steps = np.abs(np.diff(np.array([tk.q for tk in crane]), axis=0)) / DT
    assert np.all(steps <= speed * 1.05)
    # and every solver kept the tip moving with the input
    for a, b in ((5, 45), (55, 95), (105, 145)):
        assert np.linalg.norm(crane[b].tip - crane[a].tip) > 100.0


async def test_a_refused_switch_is_reported_not_fatal() -> None:
    device = ScriptedInput(circle(0.3), commands=[(0.1, "solver", "newton"), (0.2, "mode", "fast")])
    server, clock = await rig("kuka_youbot_arm", device, solver="dls", mode="velocity")
    await run(server, clock, 0.5)
    assert server.solver_name == "dls" and "fast" in server.message


async def test_mujoco_arm_follows_velocity_commands_with_its_own_dynamics() -> None:
    device = ScriptedInput(hold((0.0, 0.0, -0.5)), duration=1.5)
    server, clock = await rig("kuka_youbot_arm", device, solver="dls", mode="velocity")
    assert server.backend.name.endswith("(mujoco)")
    ticks = await run(server, clock, 2.0)
    tips = np.array([tk.tip for tk in ticks])
    drop = tips[0, 2] - tips[75, 2]
    expected = server.mapping.k_v * 0.5 * 1.5
    assert 0.6 * expected < drop < 1.1 * expected  # down, at about the commanded speed
    assert np.all(np.abs(tips[75, :2] - tips[0, :2]) < 0.1 * expected)
    # a plant of its own: the measured joint speeds are not the commands
    live = [tk for tk in ticks if tk.alive][5:]
    assert any(not np.allclose(tk.qdot, tk.command, atol=1e-6) for tk in live)
