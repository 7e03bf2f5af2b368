"""The jog pad's security rules (web/policy.py), pinned exactly: every refusal, clamp and bound.

Pure functions, no I/O: the end-to-end behaviour over real sockets is in test_web_hostile.py.
"""

from __future__ import annotations

import json
import logging
import re
import time
from typing import Any

import pytest
from pyopenshowvar_apps.web import policy
from pyopenshowvar_apps.web.jogplan import AXIS_SPEED, CADENCE, CART_SPEED, JogRequest, plan_jog
from pyopenshowvar_apps.web.policy import (
    BURST,
    JOG_VARIABLES,
    MAX_DEPTH,
    MAX_NAME,
    MAX_PRESS,
    RATE,
    TokenBucket,
    Violation,
    jog_request,
    json_depth,
    parse_message,
    refuse_connection,
    variable_name,
    write_refusal,
)
from pyopenshowvar_apps.web.runner import KRL_DIR

from pyopenshowvar.kinematics import KR6R900SIXX

MOTION = (
    "can move the robot or change how it moves: refused unless kvp web runs with"
    " --allow-motion-writes"
)


# --- connecting -----------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("origin", "given", "token", "why"),
    [
        (None, None, None, None),  # no Origin (not a browser), no token needed
        ("http://pad:8080", None, None, None),
        ("https://pad:8080", None, None, None),
        ("http://pad:8081", None, None, "wrong origin"),
        ("http://evil.example", "secret-token", "secret-token", "wrong origin"),
        ("http://pad", None, None, "wrong origin"),  # the port is part of the origin
        ("null", None, None, "wrong origin"),
        (None, None, "secret-token", "token missing or wrong"),
        (None, "", "secret-token", "token missing or wrong"),
        (None, "secret-tokeN", "secret-token", "token missing or wrong"),
        (None, "secret-token ", "secret-token", "token missing or wrong"),
        (None, "secret-token", "secret-token", None),
        ("http://pad:8080", "secret-token", "secret-token", None),
        (None, "anything", None, None),  # no token required: whatever is given is ignored
    ],
)
def test_who_may_connect(
    origin: str | None, given: str | None, token: str | None, why: str | None
) -> None:
    assert refuse_connection(origin, "pad:8080", given, token) == why


# --- messages -------------------------------------------------------------------------------
def test_the_message_budget_is_exact() -> None:
    bucket = TokenBucket(100.0)
    assert (RATE, BURST) == (100.0, 200.0)
    assert all(bucket.allow(100.0) for _ in range(200))  # a burst of exactly BURST
    assert not bucket.allow(100.0)
    assert not bucket.allow(100.0 + 0.5 / RATE)  # half a message earned: not enough
    assert bucket.allow(100.0 + 1.0 / RATE + 1e-9)  # one more earned: one more allowed
    assert not bucket.allow(100.0 + 1.0 / RATE + 1e-9)
    assert all(bucket.allow(1000.0) for _ in range(200))  # refills up to the burst, not beyond
    assert not bucket.allow(1000.0)
    slow = TokenBucket(0.0, rate=2.0, burst=1.0)
    assert slow.allow(0.0) and not slow.allow(0.25) and slow.allow(0.5) and not slow.allow(0.5)


@pytest.mark.parametrize(
    ("text", "depth"),
    [
        ("{}", 1),
        ('{"a": [1, 2]}', 2),
        ('{"a": [[{"b": []}]]}', 5),
        ('{"a": "[[[[[["}', 1),  # brackets in strings do not count
        ('{"a": "\\"[[[[["}', 1),  # nor after an escaped quote
        ('{"a": "\\\\", "b": [[[]]]}', 4),  # an escaped backslash ends before the quote
        ("[][][]", 1),
        ("]]]", 0),
        ("", 0),
    ],
)
def test_json_depth(text: str, depth: int) -> None:
    assert json_depth(text) == depth


def test_a_page_message_parses() -> None:
    msg = '{"t": "jog", "press": 3, "ov": 50.5, "step": null, "x": [[[1]]], "y": -1e308}'
    assert parse_message(msg) == {
        "t": "jog", "press": 3, "ov": 50.5, "step": None, "x": [[[1]]], "y": -1e308,
    }  # fmt: skip
    assert MAX_DEPTH == 4 and parse_message('{"a": [[[1]]]}') == {"a": [[[1]]]}
    many = '{"a": [1], "b": [2], "c": {"d": [3]}, "e": "[[[[[["}'  # many brackets, depth 3
    assert parse_message(many) == {"a": [1], "b": [2], "c": {"d": [3]}, "e": "[[[[[["}


@pytest.mark.parametrize(
    ("data", "code", "reason"),
    [
        (b'{"t": "release"}', 1003, "binary frames are not accepted: send JSON text"),
        (None, 1003, "binary frames are not accepted: send JSON text"),
        ('{"a": [[[[1]]]]}', 1007, "JSON nested deeper than 4"),
        ("[" * 2000 + "]" * 2000, 1007, "JSON nested deeper than 4"),
        ('{"ov": NaN}', 1007, "not a JSON number: NaN"),
        ('{"ov": Infinity}', 1007, "not a JSON number: Infinity"),
        ('{"ov": -Infinity}', 1007, "not a JSON number: -Infinity"),
        ('{"ov": 1e999}', 1007, "number out of range: 1e999"),
        ('{"ov": -1e999}', 1007, "number out of range: -1e999"),
        ('{"ov": 1' + "0" * 400 + ".5}", 1007, "number out of range: 1" + "0" * 19),
        ("not json", 1007, "not JSON: Expecting value: line 1 column 1 (char 0)"),
        ('{"t": "jog"} x', 1007, "not JSON: Extra data"),
        ('["t", "jog"]', 1007, "a message is a JSON object"),
        ('"jog"', 1007, "a message is a JSON object"),
        ("3", 1007, "a message is a JSON object"),
    ],
)
def test_what_no_page_sends_is_a_violation(
    data: str | bytes | None, code: int, reason: str
) -> None:
    with pytest.raises(Violation) as info:
        parse_message(data)
    assert info.value.code == code and info.value.reason.startswith(reason)
    assert str(info.value) == info.value.reason and len(info.value.reason.encode()) <= 123


# --- names and writes -----------------------------------------------------------------------
@pytest.mark.parametrize(
    "name",
    ["$OV_PRO", "$POS_ACT.X", "$TORQUE_AXIS_ACT[]", "$OUT[12]", "MYE6ARRAY[3].A1", "A[1,2]",
     "A[1,2,3]", "@PROXY_VERSION", "my_var_2", "$ACC.CP", "X" * MAX_NAME, " $OV_PRO "],
)  # fmt: skip
def test_variable_names_a_page_may_use(name: str) -> None:
    assert variable_name(name) == name.strip()


@pytest.mark.parametrize(
    "name",
    ["", " ", "X" * (MAX_NAME + 1), "$OV PRO", "A[1,2,3,4]", "A[-1]", "A[x]", "1ABC", "A.1",
     "(JOG_MODE)", "JOG_MODE;", "A[1].", "A..B", "$$", "A[]]", "A[1]B", "\tA\n B", "ÄBC", "AÄB"],
)  # fmt: skip
def test_variable_names_a_page_may_not_use(name: str) -> None:
    with pytest.raises(ValueError, match="bad variable name"):
        variable_name(name)


@pytest.mark.parametrize("value", [None, 3, ["$OV_PRO"], {"n": 1}])
def test_a_variable_name_is_a_string(value: Any) -> None:
    with pytest.raises(ValueError, match=r"^a variable name is a string$"):
        variable_name(value)


def test_the_jog_variables_are_exactly_the_jog_programs_globals() -> None:
    dat = (KRL_DIR / "kvp_jog_config.dat").read_text(encoding="latin-1")
    declared = set(re.findall(r"^DECL \w+ (JOG_\w+)", dat, re.MULTILINE))
    assert declared == JOG_VARIABLES


@pytest.mark.parametrize("allow", [False, True])
@pytest.mark.parametrize("name", [*sorted(JOG_VARIABLES), "jog_mode", "JOG_AX.A1", "Jog_Fr.X"])
def test_no_page_writes_the_jog_programs_variables(name: str, allow: bool) -> None:
    base = name.split(".")[0].upper()
    assert write_refusal(name, allow_motion=allow) == (
        f"{base} belongs to the jog program: only the server's jog logic writes it"
    )


@pytest.mark.parametrize("allow", [False, True])
def test_restart_only_by_its_button(allow: bool) -> None:
    assert write_refusal("EMU_RESTART", allow_motion=allow) == "use the Restart program button"
    assert write_refusal("emu_restart", allow_motion=allow) == "use the Restart program button"


@pytest.mark.parametrize(
    ("name", "base"),
    [("$OV_PRO", "$OV_PRO"), ("$out[3]", "$OUT"), ("$SOFTP_END[1]", "$SOFTP_END"),
     ("$ACC.CP", "$ACC"), ("@PROXY_VERSION", "@PROXY_VERSION"), ("EMU_WRENCH", "EMU_WRENCH"),
     ("OUTPUT_VARS[2]", "OUTPUT_VARS"), ("MYAXIS", "MYAXIS"), ("mye6array[3].A1", "MYE6ARRAY"),
     ("PATH_START", "PATH_START"), ("$TOOL", "$TOOL")],
)  # fmt: skip
def test_motion_writes_need_the_flag(name: str, base: str) -> None:
    assert write_refusal(name, allow_motion=False) == f"writing {base} {MOTION}"
    assert write_refusal(name, allow_motion=True) is None


@pytest.mark.parametrize("name", ["MYINT", "MYREAL", "MYSTRING[]", "JOGGER", "EMUX", "PATH"])
def test_other_writes_are_left_to_kvp_writes_checks(name: str) -> None:
    assert write_refusal(name, allow_motion=False) is None
    assert write_refusal(name, allow_motion=True) is None


# --- jog presses ----------------------------------------------------------------------------
def _jog(**kw: Any) -> dict[str, Any]:
    return {"t": "jog", "press": 7, "frame": "axis", "key": "A1", "dir": 1, **kw}


def test_a_jog_press_as_the_page_sends_it() -> None:
    press, req = jog_request(_jog(step=None, ov=30))
    assert press == 7 and req == JogRequest("axis", "A1", 1, None, 30.0)
    assert jog_request(_jog(step=1.0, ov=100))[1] == JogRequest("axis", "A1", 1, 1.0, 100.0)
    assert jog_request(_jog(dir=-1, step=0))[1] == JogRequest("axis", "A1", -1, None, 50.0)
    assert jog_request(_jog(frame="tool", key="C", step=10))[1].step == 10.0
    assert jog_request(_jog(press=0))[0] == 0 and jog_request(_jog(press=MAX_PRESS))[0] == MAX_PRESS


@pytest.mark.parametrize(
    ("ov", "clamped"),
    [(0, 1.0), (-5, 1.0), (0.999, 1.0), (1, 1.0), (1.5, 1.5), (99.9, 99.9), (100, 100.0),
     (100.01, 100.0), (1000, 100.0), (1e300, 100.0), (-1e300, 1.0)],
)  # fmt: skip
def test_the_jog_override_is_clamped(ov: float, clamped: float) -> None:
    assert jog_request(_jog(ov=ov))[1].override == clamped


@pytest.mark.parametrize(
    ("kw", "error"),
    [
        ({"press": True}, "press must be an integer in 0..2147483647"),
        ({"press": 1.0}, "press must be an integer in 0..2147483647"),
        ({"press": "1"}, "press must be an integer in 0..2147483647"),
        ({"press": -1}, "press must be an integer in 0..2147483647"),
        ({"press": MAX_PRESS + 1}, "press must be an integer in 0..2147483647"),
        ({"press": None}, "press must be an integer in 0..2147483647"),
        ({"dir": 2}, "dir must be an integer in -1..1"),
        ({"dir": -2}, "dir must be an integer in -1..1"),
        ({"dir": 1.0}, "dir must be an integer in -1..1"),
        ({"dir": True}, "dir must be an integer in -1..1"),
        ({"dir": 0}, "direction must be +1 or -1"),
        ({"frame": 1}, "frame and key must be strings"),
        ({"key": None}, "frame and key must be strings"),
        ({"frame": "joint"}, "frame must be axis, base or tool"),
        ({"key": "X"}, "axis jog keys are A1, A2, A3, A4, A5, A6"),
        ({"ov": "50"}, "ov must be a number"),
        ({"ov": True}, "ov must be a number"),
        ({"ov": None}, "ov must be a number"),
        ({"step": "1"}, "step must be a number"),
        ({"step": True}, "step must be a number"),
        ({"step": 10.001}, "step must be in"),
        ({"step": -1}, "step must be in"),
    ],
)
def test_malformed_jog_presses_are_refused(kw: dict[str, Any], error: str) -> None:
    with pytest.raises(ValueError, match="^" + re.escape(error)):  # what the page shows
        jog_request(_jog(**kw))


def test_a_missing_press_or_direction_is_refused() -> None:
    for key in ("press", "dir"):
        msg = _jog()
        del msg[key]
        with pytest.raises(ValueError, match=f"{key} must be an integer"):
            jog_request(msg)


@pytest.mark.parametrize("frame", ["axis", "base", "tool"])
@pytest.mark.parametrize("index", range(6))
def test_no_press_asks_for_more_than_the_jog_speeds(frame: str, index: int) -> None:
    """Whatever a page sends, the increments and accelerations written to the robot are those
    of the configured jog speeds at most (the override cannot go past 100 %)."""
    key = ("A" if frame == "axis" else "XYZABC"[index]) + (
        str(index + 1) if frame == "axis" else ""
    )
    _, req = jog_request(_jog(frame=frame, key=key, ov=1e308))
    plan = plan_jog(req, KR6R900SIXX)
    limit = AXIS_SPEED[index] if frame == "axis" else CART_SPEED[0 if index < 3 else 1]
    assert plan.speed == limit
    assert abs(plan.increment[index]) == pytest.approx(limit * CADENCE)
    acc, acc_cp, acc_ori = plan.acc
    assert 1 <= acc <= 100 and acc_cp <= CART_SPEED[0] / CADENCE / 1000.0 + 1e-12
    assert acc_ori <= CART_SPEED[1] / CADENCE + 1e-9


def test_the_policy_constants() -> None:
    # What docs/web.md promises, in one place: change both together.
    assert (policy.MAX_DEPTH, policy.MAX_NAME, policy.MAX_PRESS) == (4, 64, 2**31 - 1)
    assert policy.MOTION_PREFIXES == ("$", "@", "EMU_")
    assert json.loads(json.dumps(sorted(JOG_VARIABLES)))  # plain names


def test_log_limit_keeps_attackers_out_of_the_log(caplog: pytest.LogCaptureFixture) -> None:
    from pyopenshowvar_apps.web.httpguard import LogLimit

    logger = logging.getLogger("test.loglimit")
    limit = LogLimit(logger, period=0.2)
    with caplog.at_level(logging.WARNING, logger="test.loglimit"):
        for _ in range(50):
            limit.warning("a", "refused %s", "a")
        limit.warning("b", "refused %s", "b")
        time.sleep(0.25)
        limit.warning("a", "refused %s", "a")
    assert [r.getMessage() for r in caplog.records] == [
        "refused a",
        "refused b",
        "refused a (and 49 more like it)",
    ]


def test_a_missing_token_never_matches_whatever_the_token() -> None:
    for token in ("XXXX", "x", "None"):
        assert refuse_connection(None, "pad:8080", None, token) == "token missing or wrong"
        assert refuse_connection(None, "pad:8080", token, token) is None


@pytest.mark.parametrize(
    ("text", "depth"),
    [
        ("XX[1]XX", 1),  # only brackets count, not other characters
        ("[X[", 2),
        ("[[]][[[]]]", 3),  # every closing bracket undoes exactly one level
        ("{}{{}}{{{}}}", 3),
    ],
)
def test_json_depth_counts_brackets_only(text: str, depth: int) -> None:
    assert json_depth(text) == depth


def test_the_depth_limit_is_inclusive_however_many_brackets() -> None:
    msg = '{"a": [[[1]]], "b": [2], "c": {}}'  # depth 4 (the limit), 7 brackets
    assert parse_message(msg) == {"a": [[[1]]], "b": [2], "c": {}}


def test_violation_reasons_are_cut_to_their_length() -> None:
    with pytest.raises(Violation) as info:
        parse_message('{"ov": 1' + "0" * 400 + ".5}")
    assert info.value.reason == "number out of range: 1" + "0" * 19
    with pytest.raises(Violation) as info:
        parse_message('{"a": ' + "1" * 5000 + "}")  # beyond Python's integer digit limit
    assert info.value.reason.startswith("not JSON: Exceeds the limit")
    assert len(info.value.reason) == len("not JSON: ") + 80
