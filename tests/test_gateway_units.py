"""The gateway's pure parts: the cell file, password hashes and the KRC-to-Robotics mapping
(no sockets, no server)."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pyopenshowvar_apps.gateway.cell import CellError, load_cell, parse_cell
from pyopenshowvar_apps.gateway.mapping import poll_values, task_state
from pyopenshowvar_apps.gateway.schedule import next_slot
from pyopenshowvar_apps.gateway.security import check_hash_format, hash_password, verify_password

from pyopenshowvar import KrlEnum, parse_value

ROBOT = {"name": "r1", "host": "10.0.0.5"}


def cell(**kw: object) -> dict[str, object]:
    return {"cell": {"endpoint": "opc.tcp://127.0.0.1:0"}, "robot": [dict(ROBOT)], **kw}


def test_a_minimal_cell_gets_the_documented_defaults() -> None:
    c = parse_cell({"robot": [dict(ROBOT)]})
    assert c.endpoint == "opc.tcp://127.0.0.1:4840"
    assert not c.security.enabled
    r = c.robots[0]
    assert (r.port, r.poll_hz, r.timeout, r.variables, r.writable) == (7000, 10.0, 1.0, (), ())


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"robot": []}, "at least one [[robot]]"),
        (cell(extra=1), "unknown key(s) ['extra']"),
        ({"robot": [{**ROBOT, "polhz": 5}]}, "unknown key(s) ['polhz']"),
        ({"robot": [{**ROBOT, "poll_hz": 0}]}, "poll_hz must be > 0"),
        ({"robot": [{**ROBOT, "port": 70000}]}, "port must be an integer in 1..65535"),
        ({"robot": [dict(ROBOT), dict(ROBOT)]}, "robot names must be unique"),
        ({"robot": [{**ROBOT, "name": "a b"}]}, "letters, digits"),
        ({"robot": [{**ROBOT, "variables": ["$OV PRO;"]}]}, "is not a KRL variable name"),
        ({"robot": [{**ROBOT, "writable": ["$OV_PRO"]}]}, "set allow_motion_writes = true"),
        ({"robot": [{**ROBOT, "max_axis_speed": [1, 2]}]}, "needs 6 numbers"),
        ({"cell": {"endpoint": "http://x:1"}, "robot": [dict(ROBOT)]}, "expected opc.tcp://"),
        # beyond loopback: security is required, and cannot be switched off
        (
            {"cell": {"endpoint": "opc.tcp://0.0.0.0:4840"}, "robot": [dict(ROBOT)]},
            "beyond loopback",
        ),
        (
            {
                "cell": {"endpoint": "opc.tcp://192.168.1.2:4840"},
                "security": {"enabled": False},
                "robot": [dict(ROBOT)],
            },
            "only allowed on a loopback endpoint",
        ),
        (cell(security={"users": []}), "security.users is empty"),
        (cell(security={"users": [{"name": "a", "password_hash": "secret"}]}), "expected pbkdf2"),
    ],
)
def test_bad_cells_are_refused_with_the_key_named(data: dict[str, object], message: str) -> None:
    with pytest.raises(CellError) as err:
        parse_cell(data)
    assert message in str(err.value)


def test_a_cell_file_on_disk(tmp_path: Path) -> None:
    path = tmp_path / "cell.toml"
    path.write_text(
        '[cell]\nname = "line-1"\n[[robot]]\nname = "r1"\nhost = "127.0.0.1"\n'
        'writable = ["$OV_PRO"]\nallow_motion_writes = true\nvariables = ["$OV_JOG"]\n'
        '[[robot.snapshot]]\nvariable = "GW_SNAP"\nmembers = { "$AXIS_ACT" = "AX" }\n'
    )
    c = load_cell(path)
    assert c.name == "line-1" and c.security.pki_dir == tmp_path / "pki"
    r = c.robots[0]
    assert r.exposed == ("$OV_JOG", "$OV_PRO") and r.writable_name("$ov_pro") == "$OV_PRO"
    assert r.writable_name("$OV_JOG") is None
    assert r.snapshots[0].members == {"$AXIS_ACT": "AX"}
    path.write_text("[cell\n")
    with pytest.raises(CellError, match="not valid TOML"):
        load_cell(path)


@settings(max_examples=10, deadline=None)
@given(st.text(min_size=0, max_size=40))
def test_password_hashes_verify_only_their_password(password: str) -> None:
    stored = hash_password(password, iterations=10_000)
    assert check_hash_format(stored) is None
    assert verify_password(password, stored)
    assert not verify_password(password + "x", stored)


def test_poll_values_map_krc_variables_onto_the_robotics_model() -> None:
    texts = {
        "$AXIS_ACT": "{E6AXIS: A1 1.0, A2 -90.0, A3 90.0, A4 0.0, A5 0.5, A6 0.0, E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}",
        "$VEL_AXIS_ACT[]": "50.0 0.0 0.0 0.0 0.0 -10.0 0.0 0.0 0.0 0.0 0.0 0.0",
        "$TORQUE_AXIS_ACT[]": "0.0 -24.78 -25.5 -0.8 -0.6 0.0 0.0 0.0 0.0 0.0 0.0 0.0",
        "$MOT_TEMP[]": "300 301 302 303 304 305 0 0 0 0 0 0",
        "$OV_PRO": "75",
        "$DRIVES_ON": "TRUE",
        "$MODE_OP": "#EX",
        "$ALARM_STOP": "FALSE",
        "$USER_SAF": "FALSE",
        "$STOPMESS": "FALSE",
        "$PRO_STATE1": "#P_STOP",
        "$PRO_NAME1[]": '"FOLLOW"',
    }
    values = {k: parse_value(v) for k, v in texts.items()}
    out = poll_values(values, [360.0] * 6)
    assert out["position"] == [1.0, -90.0, 90.0, 0.0, 0.5, 0.0]
    assert out["speed"][0] == pytest.approx(180.0) and out["speed"][5] == pytest.approx(-36.0)
    assert out["torque"][1] == -24.78
    assert out["temperature"][0] == 26.85  # rounded: not 26.850000000000023
    assert (out["override"], out["in_control"], out["mode"]) == (75.0, True, 4)
    assert out["estop"] is True  # $ALARM_STOP is active low
    assert out["opsafe_fn_active"] and out["pstop"]  # guard open in #EX
    assert (out["robot_state"], out["robot_loaded"], out["robot_program"]) == (
        "Ready",
        True,
        "FOLLOW",
    )
    # in T1 the guard is not monitored, and only what changed is recomputed
    values["$MODE_OP"] = KrlEnum("T1")
    out = poll_values(values, [360.0] * 6, changed={"$MODE_OP"})
    assert out == {
        "mode": 1,
        "estop": True,
        "estop_fn_active": True,
        "opsafe_fn_enabled": False,
        "opsafe_fn_active": False,
        "stopmess_fn_enabled": True,
        "stopmess_fn_active": False,
        "pstop": False,
    }


@pytest.mark.parametrize(
    ("state", "expected"),
    [
        ("#P_FREE", "Idle"),
        ("#P_RESET", "Ready"),
        ("#P_ACTIVE", "Executing"),
        ("#P_STOP", "Ready"),
        ("#P_END", "Ready"),
    ],
)
def test_interpreter_states_map_onto_the_task_control_state_machine(
    state: str, expected: str
) -> None:
    assert task_state(parse_value(state)) == expected


def test_the_server_certificate_is_generated_once_and_renewed_when_the_cell_changes(
    tmp_path: Path,
) -> None:
    pytest.importorskip("asyncua")
    from cryptography import x509
    from pyopenshowvar_apps.gateway.security import ensure_certificate

    cert, key, first = ensure_certificate(tmp_path, "urn:cell:a", "127.0.0.1")
    assert key.stat().st_mode & 0o077 == 0  # the private key is its owner's only
    assert ensure_certificate(tmp_path, "urn:cell:a", "127.0.0.1")[2] == first
    san = x509.load_der_x509_certificate(cert.read_bytes()).extensions
    names = san.get_extension_for_class(x509.SubjectAlternativeName).value
    assert names.get_values_for_type(x509.UniformResourceIdentifier) == ["urn:cell:a"]
    assert [str(ip) for ip in names.get_values_for_type(x509.IPAddress)] == ["127.0.0.1"]
    key_before = key.read_bytes()
    assert ensure_certificate(tmp_path, "urn:cell:b", "127.0.0.1")[2] != first  # renamed cell
    assert key.read_bytes() == key_before  # same key, new certificate


def test_the_cell_file_in_docs_gateway_md_is_valid() -> None:
    doc = (Path(__file__).resolve().parents[1] / "docs" / "gateway.md").read_text()
    text = doc.split("```toml\n", 1)[1].split("```", 1)[0]
    text = text.replace("pbkdf2-sha256$200000$...$...", hash_password("pw", iterations=10_000))
    import tomllib

    c = parse_cell(tomllib.loads(text))
    assert c.security.enabled and [r.name for r in c.robots] == ["r1", "r2"]
    assert c.robots[0].snapshots[0].variable == "GW_SNAP"


@given(
    st.floats(0.0, 1e7),
    st.sampled_from([0.02, 0.05, 0.1, 1 / 3, 1.0]),
    st.sampled_from([0.0, 0.2, 0.4, 0.6, 0.8]),
)
def test_poll_slots_are_on_the_grid_and_one_period_apart(
    now: float, period: float, phase: float
) -> None:
    """The poll schedule: the next slot is strictly later, within one period, on the robot's
    phase of the grid; from a slot the next is exactly one period on (never a double poll)."""
    slot = next_slot(now, period, phase)
    assert now < slot <= now + period * (1 + 1e-6)
    assert (slot / period - phase) == pytest.approx(round(slot / period - phase), abs=1e-6)
    assert next_slot(slot, period, phase) - slot == pytest.approx(period, rel=1e-6)


def test_writable_names_match_whole_and_case_insensitively() -> None:
    r = parse_cell(
        cell(
            robot=[
                {
                    **ROBOT,
                    "writable": ["$OV_PRO", "OUTPUT_VARS[3]", "MYAXIS.A1", "$TOOL_DATA[1, 2]"],
                    "allow_motion_writes": True,
                }
            ]
        )
    ).robots[0]
    for name, listed in {
        "$OV_PRO": "$OV_PRO",
        "$ov_pro": "$OV_PRO",
        "$Ov_PrO": "$OV_PRO",
        "OUTPUT_VARS[3]": "OUTPUT_VARS[3]",
        "output_vars[ 3]": "OUTPUT_VARS[3]",
        "OUTPUT_VARS[3 ]": "OUTPUT_VARS[3]",
        "myaxis.a1": "MYAXIS.A1",
        "$TOOL_DATA[1,2]": "$TOOL_DATA[1, 2]",
        "$tool_data[ 1 , 2 ]": "$TOOL_DATA[1, 2]",
    }.items():
        assert r.writable_name(name) == listed, name
    for near in (
        "$OV _PRO",  # a blank inside the name
        " $OV_PRO",
        "$OV_PRO ",
        "$OV_PRO\t",
        "$OV_PRO\n",
        "$OV_PRO\x00",
        "$OV\u00a0PRO",
        "$OV_PRO[]",  # array brackets
        "$OV_PRO[1]",
        "$OV_PROX",  # trailing characters
        "$OV_PRO.A1",
        "$OV_PRO;",
        "$OV_PR",
        "OV_PRO",
        "$$OV_PRO",
        "OUTPUT_VARS[4]",
        "OUTPUT_VARS[03]",
        "OUTPUT_VARS",
        "OUTPUT_VARS[]",
        "OUTPUT_VARS [3]",
        "OUTPUT_VARS[3][3]",
        "MYAXIS",
        "MYAXIS.A2",
        "MYAXIS .A1",
        "MYAXIS. A1",
        "$TOOL_DATA[1]",
        "$TOOL_DATA[12]",
        "",
    ):
        assert r.writable_name(near) is None, repr(near)


@pytest.mark.parametrize(
    ("security", "message"),
    [
        ({"max_failed_logins": 0}, "max_failed_logins must be an integer in 1..1000000"),
        ({"max_failed_logins": 1_000_001}, "max_failed_logins"),
        ({"max_failed_logins": 2.0}, "max_failed_logins"),
        ({"max_failed_logins": True}, "max_failed_logins"),
        ({"lockout_seconds": 0.5}, "lockout_seconds must be within 1..86400"),
        ({"lockout_seconds": 86401}, "lockout_seconds"),
        ({"lockout_seconds": "60"}, "lockout_seconds"),
    ],
)
def test_login_limits_are_checked(security: dict[str, object], message: str) -> None:
    users = [{"name": "op", "password_hash": hash_password("pw", iterations=10_000)}]
    with pytest.raises(CellError, match=message):
        parse_cell(cell(security={"users": users, **security}))


def test_login_limits_default_and_bounds() -> None:
    users = [{"name": "op", "password_hash": hash_password("pw", iterations=10_000)}]
    sec = parse_cell(cell(security={"users": users})).security
    assert (sec.max_failed_logins, sec.lockout_seconds) == (5, 60.0)
    low = {"users": users, "max_failed_logins": 1, "lockout_seconds": 1}
    high = {"users": users, "max_failed_logins": 1_000_000, "lockout_seconds": 86400}
    assert parse_cell(cell(security=low)).security.max_failed_logins == 1
    assert parse_cell(cell(security=high)).security.lockout_seconds == 86400.0
