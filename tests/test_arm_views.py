"""The views draw the arm they are connected to: the web pad's link and jog, the monitor.

Each test runs a real emulator of a KR 16 R2010-2 (``arm=``) over TCP; the views learn the arm
from its ``$MODEL_NAME[]`` and the catalogue (or from ``--robot``). The gateway's
MotionDevice is checked in tests/test_gateway_e2e.py.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from pyopenshowvar_apps.armpick import choose_arm, given_arm
from pyopenshowvar_apps.monitor.state import RobotState
from pyopenshowvar_apps.web.jog import JogController
from pyopenshowvar_apps.web.robotlink import RobotLink

from pyopenshowvar import Client
from pyopenshowvar.kinematics import KR6R900SIXX


async def test_web_link_and_jog_follow_the_robots_model_name(emulator_factory: Any) -> None:
    emu = await emulator_factory(arm="kr16_r2010_2", plant="ideal", program="none")
    link = RobotLink("127.0.0.1", emu.port, timeout=2.0)
    jog = JogController(link.client, link)
    try:
        await link.poll_once()
        snap = link.snapshot
        assert snap["model"]["name"] == "KUKA KR 16 R2010-2"
        assert snap["model"]["key"] == "kr16_r2010_2" and snap["model"]["reach"] > 1800
        assert jog.model is link.model and jog.model.name == "KUKA KR 16 R2010-2"
        # the drawn flange is the KR 16's at home (X 1173, Z 1650), where the robot says it is
        flange = np.array(snap["arm"][6][9:12])
        pose = snap["pose"]
        np.testing.assert_allclose(flange, [pose["X"], pose["Y"], pose["Z"]], atol=1e-2)
        np.testing.assert_allclose(flange, [1173.0, 0.0, 1650.0], atol=1e-2)
        assert snap["limits"]["hi"][1] == pytest.approx(65.0)  # the KR 16's A2
    finally:
        await link.client.close()


async def test_web_link_keeps_a_given_arm(emulator_factory: Any) -> None:
    emu = await emulator_factory(plant="ideal", program="none")  # a KR 6 ...
    link = RobotLink("127.0.0.1", emu.port, timeout=2.0, arm=given_arm("kr210_r2700_2"))
    try:
        await link.poll_once()  # ... drawn as the KR 210 the user named
        assert link.snapshot["model"]["name"] == "KUKA KR 210 R2700-2"
        assert link.snapshot["model"]["source"] == "--robot"
    finally:
        await link.client.close()


async def test_monitor_names_the_arm_and_falls_back_to_catalogue_limits(
    emulator_factory: Any,
) -> None:
    emu = await emulator_factory(arm="kr16_r2010_2", plant="ideal", program="none")
    state = RobotState()
    async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
        state.update(await kvp.read_many(state.names_to_read([])), [])
        assert state.arm is not None and state.arm.key == "kr16_r2010_2"
        assert state.upper is not None and state.upper[1] == pytest.approx(65.0)
        assert state.limits_from == "controller"
        # a controller that does not answer the software limits: the catalogue arm's
        other = RobotState()
        other.update(await kvp.read_many(["$AXIS_ACT", "$MODEL_NAME[]"]), [])
    assert other.limits_from == "catalogue"
    assert other.lower is not None and other.lower[1] == pytest.approx(-185.0)


def test_unknown_model_name_is_drawn_as_the_kr6_and_says_so() -> None:
    choice = choose_arm('"#KR1000L950 TITAN"')
    assert choice.model is KR6R900SIXX and choice.key == ""
    assert "not in the catalogue" in choice.source
    with pytest.raises(ValueError, match="not a KUKA six-axis arm"):
        given_arm("adept_cobra600")


def test_kvp_emulate_robot_and_refusals() -> None:
    """``kvp --emulate --robot`` embeds that arm; a crane is refused; demo stays on the KR 6."""
    import threading

    from pyopenshowvar_apps.cli import app
    from typer.testing import CliRunner

    runner = CliRunner()
    res = runner.invoke(
        app, ["--emulate", "--plant", "ideal", "read", "$MODEL_NAME[]", "--robot", "kr16_r2010_2"]
    )
    assert res.exit_code == 0, res.output
    assert res.stdout.strip() == '"#KR16R2010-2 C4 FLR"'
    assert not [t for t in threading.enumerate() if t.name == "kukavarproxy-emu"]
    res = runner.invoke(app, ["--robot", "knuckle_boom_crane", "read", "X"])
    assert res.exit_code == 2 and "kvp universal --arm knuckle_boom_crane" in res.output
    res = runner.invoke(app, ["--robot", "kr16_r2010_2", "demo", "--only", "heave"])
    assert res.exit_code == 2 and "KR 6 R900 sixx" in res.output


async def test_universal_kvp_arm_drives_a_kr10_emulator() -> None:
    """The universal architecture's KUKA path accepts an emulator of its own arm (a KR 10 runs
    KVP_JOG, its $MODEL_NAME[] is the KR 10's); before, every emulator was a KR 6."""
    from pyopenshowvar_apps.universal.kvparm import KvpArm
    from pyopenshowvar_apps.web.runner import KRL_DIR

    from kukavarproxy_emu import EmulatorConfig, EmulatorThread
    from pyopenshowvar.arms import load_arm

    config = EmulatorConfig(
        port=0, discovery=False, plant="ideal", arm="kr10_r1100_2",
        program=str(KRL_DIR / "kvp_jog.src"), config_files=(KRL_DIR / "kvp_jog_config.dat",),
    )  # fmt: skip
    emu = EmulatorThread(config).start()
    backend = KvpArm(load_arm("kr10_r1100_2"), "127.0.0.1", emu.port)
    try:
        await backend.start()  # raises BackendError for a robot that is not the arm
    finally:
        await backend.close()
        emu.stop()
