"""What one jog press asks of the KVP_JOG program, exactly (web/jogplan.py, pure).

The variables a press writes and in which order, the increment and accelerations for each
frame, step mode's equal increments, the credit never past a step's end, the zeroing writes of
a stop, and the request's bounds. The numbers are worked out by hand from the rules in the
module's docstring (an increment of ``v·T``, acceleration ``v/T``, T = 20 ms) and the KR 6 R900
sixx's data sheet accelerations; tests/test_web_jog.py checks the same rules for every request
(hypothesis) and drives the KRL program itself.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from pyopenshowvar_apps.web.jogplan import JogRequest, plan_jog

from pyopenshowvar.kinematics import KR6R900SIXX

AXES_ZERO = "{A1 0.0, A2 0.0, A3 0.0, A4 0.0, A5 0.0, A6 0.0}"
FRAME_ZERO = "{X 0.0, Y 0.0, Z 0.0, A 0.0, B 0.0, C 0.0}"


def test_an_axis_press_writes_accelerations_increment_credit_then_mode() -> None:
    # A2 at 50 %: 7.5 deg/s × 0.5 = 3.75 deg/s; 0.075 deg per 20 ms; 3.75 / 0.02 = 187.5
    # deg/s² of A2's 395 deg/s², as an INT %: 47
    plan = plan_jog(JogRequest("axis", "A2", -1, None, 50.0), KR6R900SIXX)
    assert (plan.mode, plan.target, plan.count, plan.speed) == (1, "JOG_AX", None, 3.75)
    assert plan.start_writes(17) == [
        ("JOG_ACC", "47"),
        ("JOG_ACC_CP", "1.0"),
        ("JOG_ACC_ORI", "100.0"),
        ("JOG_AX", "{A1 0.0, A2 -0.075, A3 0.0, A4 0.0, A5 0.0, A6 0.0}"),
        ("JOG_UNTIL", "17"),
        ("JOG_MODE", "1"),
    ]
    assert plan.stop_writes() == [("JOG_AX", AXES_ZERO), ("JOG_UNTIL", "0"), ("JOG_MODE", "0")]
    assert np.array_equal(plan.increment, [0.0, -0.075, 0.0, 0.0, 0.0, 0.0])


def test_cartesian_presses_set_the_path_or_the_orientation_acceleration() -> None:
    # base X at 100 %: 100 mm/s, 2 mm per 20 ms, 100 / 0.02 = 5000 mm/s² = 5 m/s²
    plan = plan_jog(JogRequest("base", "X", 1, None, 100.0), KR6R900SIXX)
    assert (plan.mode, plan.target, plan.acc, plan.speed) == (2, "JOG_FR", (100, 5.0, 100.0), 100.0)
    assert plan.start_writes(3) == [
        ("JOG_ACC", "100"),
        ("JOG_ACC_CP", "5.0"),
        ("JOG_ACC_ORI", "100.0"),
        ("JOG_FR", "{X 2.0, Y 0.0, Z 0.0, A 0.0, B 0.0, C 0.0}"),
        ("JOG_UNTIL", "3"),
        ("JOG_MODE", "2"),
    ]
    assert plan.stop_writes() == [("JOG_FR", FRAME_ZERO), ("JOG_UNTIL", "0"), ("JOG_MODE", "0")]
    # tool C at 10 %: 3 deg/s, 0.06 deg per 20 ms, 150 deg/s²
    plan = plan_jog(JogRequest("tool", "C", -1, None, 10.0), KR6R900SIXX)
    assert (plan.mode, plan.acc, plan.speed) == (3, (100, 1.0, 150.0), 3.0)
    assert plan.literal == "{X 0.0, Y 0.0, Z 0.0, A 0.0, B 0.0, C -0.06}"
    # Y and A: the speed of their kind (path, orientation)
    assert plan_jog(JogRequest("base", "Z", 1, None, 50.0), KR6R900SIXX).speed == 50.0
    assert plan_jog(JogRequest("base", "A", 1, None, 50.0), KR6R900SIXX).speed == 15.0
    # A, the first rotation: 15 deg/s / 0.02 s = 750 deg/s² of orientation acceleration, the
    # path acceleration left at its default (the boundary between path and orientation keys)
    assert plan_jog(JogRequest("base", "A", 1, None, 50.0), KR6R900SIXX).acc == (100, 1.0, 750.0)
    assert plan_jog(JogRequest("base", "Z", 1, None, 50.0), KR6R900SIXX).acc == (100, 2.5, 100.0)


def test_axis_accelerations_are_a_percentage_from_1_to_100() -> None:
    # A6 at 1 %: 0.45 deg/s over 20 ms is 0.15 % of 15 377 deg/s²: at least 1 %
    assert plan_jog(JogRequest("axis", "A6", 1, None, 1.0), KR6R900SIXX).acc[0] == 1
    # A1 at 100 %: 750 deg/s² on an arm that can do 100: at most 100 %
    slow = dataclasses.replace(KR6R900SIXX, max_accel=np.full(6, 100.0))
    assert plan_jog(JogRequest("axis", "A1", 1, None, 100.0), slow).acc[0] == 100
    # A1 at 100 % on the KR 6: 15 / 0.02 / 1241 = 60.4 %
    assert plan_jog(JogRequest("axis", "A1", 1, None, 100.0), KR6R900SIXX).acc[0] == 60


def test_a_step_is_equal_increments_and_the_credit_stops_at_its_end() -> None:
    # 1 deg of A1 at 0.3 deg per increment: 4 increments of 0.25
    plan = plan_jog(JogRequest("axis", "A1", 1, 1.0, 100.0), KR6R900SIXX)
    assert plan.count == 4 and plan.literal.startswith("{A1 0.25, ")
    assert plan.until(10, 10, 5) == 14  # never past the step
    assert plan.until(10, 12, 1) == 13  # the credit, when it ends first
    # a step of exactly one increment is one increment, not two (rounding aside)
    plan = plan_jog(JogRequest("axis", "A1", 1, 0.3, 100.0), KR6R900SIXX)
    assert plan.count == 1 and plan.increment[0] == 0.3
    # a step shorter than one increment is one shorter increment
    plan = plan_jog(JogRequest("axis", "A6", -1, 0.1, 100.0), KR6R900SIXX)
    assert plan.count == 1 and plan.increment[5] == -0.1
    # a tiny step: its number in exponent form, which needs no ".0" to be a REAL
    plan = plan_jog(JogRequest("axis", "A1", 1, 1e-6, 100.0), KR6R900SIXX)
    assert plan.literal == "{A1 1e-06, A2 0.0, A3 0.0, A4 0.0, A5 0.0, A6 0.0}"
    # continuous: the credit from what the robot has seen
    assert plan_jog(JogRequest("axis", "A1", 1), KR6R900SIXX).until(10, 12, 5) == 17


def test_labels_and_indices() -> None:
    assert JogRequest("axis", "A3", 1).label == "axis A3+"
    assert JogRequest("tool", "B", -1, 10.0).label == "tool B- step 10"
    assert JogRequest("base", "Y", 1, 0.1).label == "base Y+ step 0.1"
    assert [JogRequest("base", k, 1).index for k in ("X", "C")] == [0, 5]
    assert JogRequest("axis", "A6", 1).index == 5


@pytest.mark.parametrize(
    ("kw", "message"),
    [
        ({"frame": "world"}, "frame must be axis, base or tool, not 'world'"),
        ({"key": "X"}, "axis jog keys are A1, A2, A3, A4, A5, A6, not 'X'"),
        ({"frame": "base", "key": "A1"}, "base jog keys are X, Y, Z, A, B, C, not 'A1'"),
        ({"direction": 2}, "direction must be +1 or -1"),
        ({"direction": 0}, "direction must be +1 or -1"),
        ({"step": 0.0}, "step must be in (0, 10]"),
        ({"step": 10.001}, "step must be in (0, 10]"),
        ({"step": -1.0}, "step must be in (0, 10]"),
        ({"override": 0.99}, "override must be 1..100 %"),
        ({"override": 100.01}, "override must be 1..100 %"),
    ],
)
def test_requests_out_of_bounds_are_refused_with_the_rule(
    kw: dict[str, object], message: str
) -> None:
    args: dict[str, object] = {"frame": "axis", "key": "A1", "direction": 1, **kw}
    with pytest.raises(ValueError) as refused:
        JogRequest(**args)  # type: ignore[arg-type]
    assert str(refused.value) == message


def test_requests_at_their_bounds_are_taken() -> None:
    for kw in ({"step": 10.0}, {"step": 1e-6}, {"override": 1.0}, {"override": 100.0}):
        JogRequest("axis", "A1", -1, **kw)
