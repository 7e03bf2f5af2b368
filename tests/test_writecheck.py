"""The write checks of `kvp write`, the REPL and the monitor (apps' writecheck module).

Pure functions first (a literal's problem and caret, the type comparison, the program state
and its stop, what an interruption means), then the refusal reasons and the stop watch over
real TCP against the emulator: its KRC4 system variables (read-only, ranges) and its running
program that a software limit switch stops.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

import pytest
from pyopenshowvar_apps.writecheck import (
    LiteralProblem,
    ProgramState,
    RefusedWrite,
    WriteProgress,
    _kind,
    _problem,
    _short,
    _type_mismatch,
    check_literal,
    checked_write,
    explain_refusal,
    read_program_state,
)

from kukavarproxy_emu import Emulator, Fault
from pyopenshowvar import Client, KrlEnum, Struct, WriteRefusedError, parse_value
from pyopenshowvar.protocol import Request
from pyopenshowvar.testing import FakeProxy, answer

#: an E6AXIS as the controller prints it, every member present
AXIS = parse_value(
    "{E6AXIS: A1 0.0, A2 -90.0, A3 90.0, A4 0.0, A5 0.0, A6 0.0,"
    " E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
)

# ---------------------------------------------------------------------- literals


def test_a_good_literal_has_no_problem() -> None:
    for text in ("5", "-1.5E-3", "TRUE", "#T1", '"text"', "{A1 10.0, A2 -80.0}"):
        assert check_literal(text) is None, text


def test_a_bad_literal_names_the_reason_and_the_character() -> None:
    problem = check_literal("{A1 10.0, A2 -80.0")
    assert problem == LiteralProblem("expected ',' or '}', got end of text", 18)
    assert check_literal("{A1 1O.0}") == LiteralProblem("unexpected '1O.0'", 4)
    assert check_literal('"abc') == LiteralProblem("unexpected '\"abc'", 0)


def test_a_message_without_a_position_is_kept_whole() -> None:
    assert _problem("no position here") == LiteralProblem("no position here", None)
    # the parser's prefix goes, the rest of the message stays (a colon in the reason too)
    assert _problem("invalid KRL value 'x': a: b") == LiteralProblem("a: b", None)
    assert _problem("invalid KRL value 'x': a: b at 7") == LiteralProblem("a: b", 7)
    # " at N" is only the position when it ends the message
    assert _problem("stuck at 3 here") == LiteralProblem("stuck at 3 here", None)
    # the prefix without a reason after it: nothing to cut
    assert _problem("invalid KRL value x") == LiteralProblem("invalid KRL value x", None)


def test_the_caret_stands_under_the_character_of_a_one_line_literal() -> None:
    problem = LiteralProblem("bad", 2)
    assert problem.lines("ab?d") == ["bad", "  ab?d", "    ^"]
    assert LiteralProblem("bad", 0).lines("?") == ["bad", "  ?", "  ^"]
    assert LiteralProblem("bad", None).lines("ab?d") == ["bad"]
    assert problem.lines("a\nb") == ["bad"]  # a caret under two lines would point nowhere
    assert len(problem.lines("x" * 200)) == 3  # up to 200 characters are shown
    assert problem.lines("x" * 201) == ["bad"]


# ---------------------------------------------------------------------- types


def test_each_value_kind_is_named_with_the_type_a_literal_is_checked_against() -> None:
    assert _kind(True) == ("BOOL", "BOOL")  # a bool is an int in Python: checked first
    assert _kind(False) == ("BOOL", "BOOL")
    assert _kind(3) == ("INT", "INT")
    assert _kind(3.0) == ("REAL", "REAL")
    assert _kind(KrlEnum("T1")) == ("an ENUM", None)
    assert _kind("text") == ("a CHAR array (text)", None)
    assert _kind(parse_value("{E6AXIS: A1 1.0}")) == ("E6AXIS", "E6AXIS")
    assert _kind(parse_value("{A1 1.0}")) == ("a struct", None)
    assert _kind([1, 2]) == ("an array", None)


def test_a_long_current_value_is_shortened_to_its_width() -> None:
    assert _short("x" * 60) == "x" * 60
    assert _short("x" * 61) == "x" * 59 + "…"
    assert _short("abcdef", width=4) == "abc…"


@pytest.mark.parametrize(
    ("current", "literal", "why"),
    [
        (0, "5.5", "expected an INT, got '5.5'"),
        (False, "1", "expected a BOOL (TRUE/FALSE), got '1'"),
        (1.5, "#X", "expected a REAL, got '#X'"),
        (AXIS, "{X 1, A1 2}", "E6AXIS has no member X, got 'X'"),
        (AXIS, "5", "expected a struct {...}, got '5'"),
        (parse_value("{A1 0.0}"), "5", "the value is not a struct"),
        (parse_value("{A1 0.0}"), "{B 1, A1 2, C 3}", "a struct has no member B, C"),
        (KrlEnum("T1"), "5", "the value is not an ENUM value #NAME"),
        ("text", "5", 'the value is not a text "..."'),
        ("text", "{A 1}", "the value is a struct"),
    ],
)
def test_a_literal_of_another_type_says_why(current: Any, literal: str, why: str) -> None:
    assert _type_mismatch(current, literal) == why


@pytest.mark.parametrize(
    ("current", "literal"),
    [
        (0, "5"),
        (False, "TRUE"),
        (1.5, "2"),  # an INT literal is a REAL value
        (AXIS, "{A1 2, A6 3}"),
        (parse_value("{A1 0.0}"), "{A1 2}"),
        (KrlEnum("T1"), "#T2"),
        ("text", '"other"'),
        ([1, 2], "5"),  # an array: nothing to compare
        (0, "{A1 1.0"),  # not a literal at all: checked before sending, nothing to add
    ],
)
def test_a_literal_that_fits_has_no_mismatch(current: Any, literal: str) -> None:
    assert _type_mismatch(current, literal) is None


def test_a_user_struct_the_library_does_not_know_is_compared_by_members() -> None:
    mine = Struct("MYTYPE", {"A": 1, "B": 2})
    assert _type_mismatch(mine, "{A 5}") is None
    assert _type_mismatch(mine, "{C 5}") == "MYTYPE has no member C"
    assert _type_mismatch(mine, "5") == "the value is not a struct"


# ---------------------------------------------------------------------- program state


RUNNING = ProgramState("#P_ACTIVE", False, None)


def test_a_program_stop_is_an_end_of_the_run_or_a_new_stop_message() -> None:
    assert RUNNING.running and not ProgramState("#P_STOP", False, None).running
    assert ProgramState("#P_STOP", False, None).stopped_since(RUNNING)
    assert ProgramState("#P_ACTIVE", True, None).stopped_since(RUNNING)  # message, still on
    assert not RUNNING.stopped_since(RUNNING)
    # a state that could not be read is no stop; nor is a program that was not running
    assert not ProgramState(None, False, None).stopped_since(RUNNING)
    stopped = ProgramState("#P_STOP", False, None)
    assert not stopped.stopped_since(stopped)
    assert not ProgramState("#P_FREE", False, None).stopped_since(stopped)
    # a stop message that was there before, or cannot be read before, is not new
    assert not ProgramState("#P_ACTIVE", True, None).stopped_since(
        ProgramState("#P_ACTIVE", True, None)
    )
    assert not ProgramState("#P_ACTIVE", True, None).stopped_since(
        ProgramState("#P_ACTIVE", None, None)
    )
    assert not ProgramState("#P_ACTIVE", None, None).stopped_since(RUNNING)


def test_a_program_state_describes_what_was_read() -> None:
    assert ProgramState("#P_STOP", True, "limit").describe() == (
        "$PRO_STATE1 #P_STOP, $STOPMESS TRUE: limit"
    )
    assert RUNNING.describe() == "$PRO_STATE1 #P_ACTIVE, $STOPMESS FALSE"
    assert ProgramState(None, None, None).describe() == ""
    assert ProgramState(None, True, None).describe() == "$STOPMESS TRUE"


# ---------------------------------------------------------------------- interruption


def test_an_interruption_says_what_became_of_the_write() -> None:
    progress = WriteProgress()
    assert (progress.sent, progress.answer, progress.echo) == (False, None, "")
    assert progress.describe("X") == "the write was not sent: 'X' was not written"
    progress.sent = True
    assert progress.describe("X") == (
        "the write was sent but not answered: 'X' may or may not have been written"
        " (read it to know)"
    )
    progress.answer = "refused"
    assert progress.describe("X") == "the write was sent and refused: 'X' was not written"
    progress.answer, progress.echo = "acknowledged", "5"
    assert progress.describe("X") == (
        "the write was sent and acknowledged: 'X' = 5 was written"
        " (the robot program was no longer watched for a stop)"
    )


def test_a_refused_write_carries_its_reason() -> None:
    exc = RefusedWrite("$OV_PRO", "127.0.0.1:7000", "150", "out of range 0..100")
    assert isinstance(exc, WriteRefusedError)
    assert str(exc) == "write refused: '$OV_PRO' on 127.0.0.1:7000: out of range 0..100"
    assert (exc.name, exc.endpoint, exc.value, exc.reason) == (
        "$OV_PRO",
        "127.0.0.1:7000",
        "150",
        "out of range 0..100",
    )
    assert str(RefusedWrite("A", "", "1", "why")) == "write refused: 'A': why"


# ---------------------------------------------------------------------- over TCP


async def test_refusal_reasons_from_the_controller(emulator: Emulator) -> None:
    async with Client("127.0.0.1", emulator.port, timeout=2.0) as client:
        assert await explain_refusal(client, "NOPE", "5") == (
            "the variable reads as unknown: not declared, an index or member that does not"
            " exist, or never initialised (and the value does not fit its type)"
        )
        assert await explain_refusal(client, "$MODE_OP", "#T1") == (
            "read-only: a KRC lets no client write this system variable"
        )
        assert await explain_refusal(client, "$MODE_OP", "5") == (
            "wrong type: the variable is an ENUM (now #AUT); the value is not an ENUM value #NAME"
        )
        # a text that is no KRL value (the proxy's own variables): no type to compare
        assert await explain_refusal(client, "@PROXY_TYPE", "5") == (
            "the controller gives no reason; the value fits its type (now KUKAVARPROXY"
            " EMULATOR), so it is probably read-only or out of range"
        )
        assert await explain_refusal(client, "$OV_PRO", "101") == "out of range 0..100"
        assert await explain_refusal(client, "$OV_PRO", "-1") == "out of range 0..100"
        assert await explain_refusal(client, "$ADVANCE", "6") == "out of range 0..5"
        assert await explain_refusal(client, "$VEL_AXIS[2]", "300") == "out of range 0..100"
        # within the range (its bounds too): the controller's refusal has no known reason
        for value in ("0", "100", "50"):
            reason = await explain_refusal(client, "$OV_PRO", value)
            assert reason.startswith("the controller gives no reason; the value fits its type")
            assert "(now 100)" in reason, reason
        assert (await explain_refusal(client, "MYINT", "5.5")).startswith(
            "wrong type: the variable is INT (now 0); expected an INT"
        )
        assert (await explain_refusal(client, "MYREAL", "#X")).startswith(
            "wrong type: the variable is REAL"
        )


async def test_an_unanswered_read_after_a_refusal_gives_no_reason(emulator: Emulator) -> None:
    async with Client("127.0.0.1", emulator.port, timeout=0.2) as client:
        await client.read("MYINT")
        emulator.faults.add(Fault("drop", count=None))
        assert await explain_refusal(client, "MYINT", "5") == "the controller gives no reason"


async def test_the_program_state_of_a_running_and_a_stopped_program(emulator: Emulator) -> None:
    async with Client("127.0.0.1", emulator.port, timeout=2.0) as client:
        assert await read_program_state(client) == ProgramState("#P_ACTIVE", False, None)
        outcome = await checked_write(client, "MYAXIS", "{A1 9999}", window=5.0)
        assert outcome.echo == "{A1 9999}" and outcome.stop is not None
        stop = outcome.stop
        assert stop.state == "#P_STOP" and stop.stopmess is True
        assert stop.message is not None and "Software limit switch +A1" in stop.message
        assert not stop.message.startswith(('"', " ")) and not stop.message.endswith(('"', " "))
        assert await read_program_state(client) == stop
        assert 0 < outcome.seconds < 5.0


async def test_a_harmless_write_is_watched_for_the_window_only(emulator: Emulator) -> None:
    async with Client("127.0.0.1", emulator.port, timeout=2.0) as client:
        progress = WriteProgress()
        t0 = time.monotonic()
        outcome = await checked_write(client, "MYINT", "7", window=0.15, progress=progress)
        assert time.monotonic() - t0 >= 0.15
        assert outcome.echo == "7" and outcome.stop is None
        assert outcome.seconds < 0.15  # the write's own round trip, not the window
        assert (progress.sent, progress.answer, progress.echo) == (True, "acknowledged", "7")
        assert emulator.store.read("MYINT") == "7"


async def test_without_a_window_nothing_but_the_write_is_sent(emulator: Emulator) -> None:
    async with Client("127.0.0.1", emulator.port, timeout=2.0) as client:
        await client.write("MYINT", "7")  # connected (the client's first requests are done)
        before = emulator.stats.requests
        outcome = await checked_write(client, "MYINT", "8", window=0)
        assert outcome.echo == "8" and outcome.stop is None
        assert emulator.stats.requests == before + 1
        assert 0 < outcome.seconds < 2.0


async def test_a_refused_write_is_raised_with_its_reason(emulator: Emulator) -> None:
    async with Client("127.0.0.1", emulator.port, timeout=2.0) as client:
        progress = WriteProgress()
        with pytest.raises(RefusedWrite) as info:
            await checked_write(client, "$OV_PRO", "150", window=0, progress=progress)
        assert info.value.reason == "out of range 0..100" and info.value.value == "150"
        assert info.value.endpoint == f"127.0.0.1:{emulator.port}"
        assert info.value.__cause__ is None and info.value.__suppress_context__
        assert (progress.sent, progress.answer) == (True, "refused")
        assert emulator.store.read("$OV_PRO") == "100"


async def test_a_refused_write_to_a_user_struct_names_the_member(emulator: Emulator) -> None:
    """A STRUC of the controller's own data lists is no type the library knows: its refusal
    is explained by its members, not as an unknown type."""
    emulator.store.load_dat(
        "DEFDAT $CONFIG\nSTRUC MYTYPE INT A, B\nDECL MYTYPE MYVAR={A 1, B 2}\nENDDAT\n"
    )
    async with Client("127.0.0.1", emulator.port, timeout=2.0) as client:
        with pytest.raises(RefusedWrite) as info:
            await checked_write(client, "MYVAR", "{C 5}", window=0)
        assert info.value.reason == (
            "wrong type: the variable is MYTYPE (now {MYTYPE: A 1, B 2}); MYTYPE has no member C"
        )
        with pytest.raises(RefusedWrite) as info:
            await checked_write(client, "MYVAR", "5", window=0)
        assert info.value.reason.endswith("; the value is not a struct")


async def test_a_controller_without_the_emulators_variables() -> None:
    """A real KRC has no $EMU_MESSAGE[]; here $STOPMESS is unknown too (an old proxy): those
    fields are None, never an empty text or FALSE."""
    texts = {"$PRO_STATE1": b"#P_ACTIVE"}

    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        w.write(answer(req, texts.get(req.name, b"")))  # empty with success: unknown

    async with FakeProxy(handler) as port, Client("127.0.0.1", port, timeout=2.0) as client:
        assert await read_program_state(client) == ProgramState("#P_ACTIVE", None, None)
        texts.update({"$STOPMESS": b" true ", "$EMU_MESSAGE[]": b'"X limit X "'})
        assert await read_program_state(client) == ProgramState("#P_ACTIVE", True, "X limit X")


async def test_an_interrupted_write_on_an_open_connection_was_sent(emulator: Emulator) -> None:
    async with Client("127.0.0.1", emulator.port, timeout=5.0) as client:
        await client.read("MYINT")  # connected
        emulator.faults.add(Fault("drop", count=None))  # the write is never answered
        progress = WriteProgress()
        task = asyncio.create_task(checked_write(client, "MYINT", "9", window=0, progress=progress))
        async with asyncio.timeout(2):
            while not progress.sent:  # noqa: ASYNC110 - set before the write first awaits
                await asyncio.sleep(0.01)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
        assert progress.answer is None
        assert progress.describe("MYINT").startswith("the write was sent but not answered")
