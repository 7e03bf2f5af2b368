"""``pyopenshowvar.session`` rule by rule, without sockets: ids, the in-flight window, the id
probe and every rule that matches a reply to its request or refuses it.

The session is sans-IO (both clients drive it), so each rule is checked here on the exact
frames and replies a proxy would produce; ``test_client_ids.py`` and ``test_client_faults.py``
run the same rules end to end against broken proxies and the emulator.
"""

from __future__ import annotations

import pytest

from pyopenshowvar.errors import ProtocolError
from pyopenshowvar.protocol import Mode, Reply, encode_read, encode_write, encode_write_array
from pyopenshowvar.session import (
    PROBE_VARIABLE,
    Pending,
    Session,
    check_id_policy,
    new_reply,
    value_shape,
)

H = bytes.fromhex


def read_reply(msg_id: int, value: bytes, status: int = 1) -> Reply:
    return Reply(msg_id, Mode.READ, value, status)


def session(id_policy: str = "strict", **kw: int) -> Session[str]:
    return Session("kvp://robot", id_policy=id_policy, **kw)  # type: ignore[arg-type]


def queue_reads(s: Session[str], *names: str, timeout: float = 1.0) -> list[Pending[str]]:
    return [s.register(n, encode_read(0, n), f"w:{n}", timeout) for n in names]


# ------------------------------------------------------------------ building blocks


def test_pending_takes_id_mode_and_size_from_its_frame() -> None:
    frame = encode_write(7, "X", "12")
    p = Pending(7, "X", frame, "waiter", 2.5)
    assert (p.msg_id, p.name, p.frame, p.waiter, p.timeout) == (7, "X", frame, "waiter", 2.5)
    assert p.mode == Mode.WRITE and p.size == len(frame) == 12
    assert (p.sent_at, p.deadline, p.abandoned) == (0.0, 0.0, False)
    assert Pending(0, "r", encode_read(0, "R"), None, 1.0).mode == Mode.READ
    assert Pending(0, "?", H("0000 0000 03"), None, 1.0).mode == 3  # the 5th byte is the mode
    assert Pending(0, "?", H("0000 0000"), None, 1.0).mode == -1  # no mode byte at all


@pytest.mark.parametrize("policy", ["auto", "strict", "legacy", "fifo"])
def test_the_four_id_policies_are_accepted(policy: str) -> None:
    check_id_policy(policy)


@pytest.mark.parametrize("policy", ["Auto", "", "echoed", "none"])
def test_an_unknown_id_policy_is_named(policy: str) -> None:
    with pytest.raises(ValueError) as err:
        check_id_policy(policy)
    assert str(err.value) == f"id_policy must be 'auto', 'strict' or 'legacy', not {policy!r}"
    with pytest.raises(ValueError, match="id_policy must be"):
        session(policy)


@pytest.mark.parametrize(
    ("value", "shape"),
    [
        (b"{E6AXIS: A1 1.0}", b"{E6AXIS:"),
        (b"{:", b"{:"),  # the colon right after the brace still ends the type name
        (b"{LOAD: M 1.5, CM {FRAME: X 0}}", b"{LOAD:"),  # the first colon, not a member's
        (b"{A1 1.0}", b"{"),  # a struct without a type name
        (b"{" + b"x" * 62 + b":", b"{" + b"x" * 62 + b":"),  # colon at 63: within the 64
        (b"{" + b"x" * 63 + b": A", b"{"),  # colon at 64: past the search, the brace alone
        (b'"text"', b'"'),
        (b"'a'", b"'"),
        (b"#AUT", b"#"),
        (b"12", b"number"),
        (b"-1.5", b"number"),
        (b"+3", b"number"),
        (b".5", b"number"),
        (b"TRUE", b"BOOL"),
        (b"FALSE", b"BOOL"),
        (b"TRUEX", b"other"),
        (b"X", b"other"),
    ],
)
def test_value_shape(value: bytes, shape: bytes) -> None:
    assert value_shape(value) == shape


def test_new_reply_equals_the_dataclass() -> None:
    reply = new_reply(0xBEEF, Mode.WRITE, b"5", 0, H("0002"))
    assert reply == Reply(0xBEEF, Mode.WRITE, b"5", 0, H("0002"))
    assert new_reply(1, None, b"", 1, H("0001")) == Reply(1, None, b"", 1, H("0001"))


# ------------------------------------------------------------------ construction and window


def test_initial_state_per_policy() -> None:
    s: Session[str] = Session("ep")
    assert (s.endpoint, s.max_in_flight, s.pipeline_bytes, s.window) == ("ep", 64, 2048, 2048)
    assert s.ids == "unknown" and s.needs_probe and s.id_policy == "auto"
    assert (s.next_id, s.last_label, s.bytes_in_flight) == (0, None, 0)
    assert (s.mislabeled_replies, s.dropped_requests) == (0, 0)
    assert not s.queue and not s.by_id
    assert session("strict").ids == "echoed" and not session("strict").needs_probe
    assert session("legacy").ids == "legacy" and not session("legacy").needs_probe
    assert session("fifo").ids == "legacy"


def test_window_bounds_are_at_least_one() -> None:
    s = session(max_in_flight=0, pipeline_bytes=0)
    assert (s.max_in_flight, s.pipeline_bytes, s.window) == (1, 1, 1)
    s = session(max_in_flight=3, pipeline_bytes=100)
    assert (s.max_in_flight, s.pipeline_bytes, s.window) == (3, 100, 100)


def test_the_window_is_lowered_to_one_segment_never_raised() -> None:
    s = session(pipeline_bytes=2048)
    s.limit_to_segment(1460)
    assert s.window == 1460
    s.limit_to_segment(65495)
    assert s.window == 2048
    s.limit_to_segment(0)
    assert s.window == 1


def test_a_request_larger_than_one_kvp_read_is_refused_before_sending() -> None:
    s = session(pipeline_bytes=30)
    s.check_size("A", encode_read(0, "A" * 23))  # exactly 30 bytes: one read holds it
    big = encode_write(0, "B", "x" * 21)  # 31 bytes
    with pytest.raises(ProtocolError) as err:
        s.check_size("B", big)
    assert str(err.value) == (
        "request for 'B' is 31 bytes; KUKAVARPROXY reads at most 30 per socket event and "
        "would cut it (see pipeline_bytes)"
    )
    # C3 Bridge messages (type 4 and up) are collected whole by their server
    c3 = big[:4] + bytes([4]) + big[5:]
    s.check_size("C3", c3)
    mode3 = encode_write_array(0, "W", list(range(20)))
    with pytest.raises(ProtocolError):
        s.check_size("W", mode3)  # mode 3 is a KVP request like any other


def test_fits_counts_requests_and_bytes_once_ids_are_echoed() -> None:
    size = len(encode_read(0, "A"))  # 8
    s = session(max_in_flight=3, pipeline_bytes=3 * size)
    assert s.fits(10**6)  # a lone request always goes
    queue_reads(s, "A")
    assert s.bytes_in_flight == size
    assert s.fits(2 * size) and not s.fits(2 * size + 1)
    queue_reads(s, "A")
    assert s.fits(size) and not s.fits(size + 1)
    s.window = 10**6
    queue_reads(s, "A")
    assert not s.fits(1)  # three in flight: the count is full


@pytest.mark.parametrize("policy", ["auto", "legacy"])
def test_one_awaited_request_in_flight_until_ids_are_proven(policy: str) -> None:
    s = session(policy)
    (first,) = queue_reads(s, "A")
    assert not s.fits(1)
    first.abandoned = True  # its caller gave up: it no longer holds the line
    assert s.fits(1)
    queue_reads(s, "B")
    assert not s.fits(1)


def test_stalled_only_without_room_and_past_the_oldest_timeout() -> None:
    size = len(encode_read(0, "A"))
    s = session(max_in_flight=1)
    assert not s.stalled(size, 100.0)  # nothing pending
    (p,) = queue_reads(s, "A", timeout=2.0)
    p.sent_at = 10.0
    assert not s.stalled(size, 12.0)  # exactly its timeout: not yet
    assert s.stalled(size, 12.01)
    s.max_in_flight = 2
    assert not s.stalled(size, 99.0)  # room again: never a stall


def test_the_stall_message_names_the_oldest_request_and_its_wait() -> None:
    s = session()
    a, _ = queue_reads(s, "$AXIS_ACT", "B")
    a.sent_at = 10.0
    assert s.stall_message(13.26) == (
        "kvp://robot stopped answering: 2 requests unanswered, the oldest ('$AXIS_ACT') for"
        " 3.3 s; the connection is marked unhealthy and closed"
    )
    a.sent_at = 0.0  # never sent (still queued): no wait to tell
    assert "for 0.0 s;" in s.stall_message(13.26)


# ------------------------------------------------------------------ ids


def test_ids_count_up_wrap_at_0xffff_and_skip_pending_ones() -> None:
    s = session()
    assert [p.msg_id for p in queue_reads(s, "A", "B")] == [0, 1]
    s.next_id = 0xFFFE
    got = queue_reads(s, "C", "D", "E")
    assert [p.msg_id for p in got] == [0xFFFE, 0xFFFF, 2]  # 0 and 1 are still pending
    assert s.next_id == 3
    assert got[0].frame[:2] == H("FFFE") and got[0].frame[2:] == encode_read(0, "C")[2:]
    assert s.by_id[0xFFFF] is got[1]


def test_register_sent_keeps_the_frames_own_id() -> None:
    s = session()
    frame = encode_read(0x1234, "A")
    p = s.register_sent("A", frame, "w", 1.5)
    assert (p.msg_id, p.frame, p.waiter, p.timeout) == (0x1234, frame, "w", 1.5)
    assert s.by_id == {0x1234: p} and list(s.queue) == [p] and s.bytes_in_flight == len(frame)
    assert s.next_id == 0  # nothing allocated
    assert s.dispatch(read_reply(0x1234, b"1")) == (p, [])


def test_the_probe_is_two_reads_of_ov_pro_in_one_write() -> None:
    s = session("auto")
    data = s.register_probe("w", 5.0, 1.0)
    assert data == encode_read(0, PROBE_VARIABLE) + encode_read(1, PROBE_VARIABLE)
    first, second = s.queue
    assert first.abandoned and second.abandoned
    assert (first.sent_at, second.sent_at) == (5.0, 5.0)
    assert (first.timeout, second.timeout) == (1.0, 1.0) and first.waiter == "w"
    assert s.fits(1)  # nobody waits for the probe: a request may follow at once


# ------------------------------------------------------------------ matching replies


def test_probe_answered_with_own_ids_proves_echoing() -> None:
    s = session("auto")
    s.register_probe("w", 0.0, 1.0)
    assert s.dispatch(read_reply(0, b"100")) == (None, [])  # nobody waited for it
    assert s.needs_probe
    assert s.dispatch(read_reply(1, b"100")) == (None, [])
    assert s.ids == "echoed" and not s.needs_probe and not s.queue and not s.by_id
    assert s.bytes_in_flight == 0 and s.last_label == 1


def test_probe_answered_with_the_first_id_twice_proves_the_legacy_bug() -> None:
    s = session("auto")
    s.register_probe("w", 0.0, 1.0)
    s.dispatch(read_reply(0, b"100"))
    assert s.dispatch(read_reply(0, b"100")) == (None, [])  # the second, labelled 0 again
    assert s.ids == "legacy" and s.mislabeled_replies == 1 and not s.queue
    (p,) = queue_reads(s, "A")
    assert not s.fits(1)  # one at a time from now on
    assert s.dispatch(read_reply(p.msg_id, b"1")) == (p, [])


def test_a_dropped_probe_leaves_the_ids_unknown() -> None:
    s = session("auto")
    s.register_probe("w", 0.0, 1.0)
    (a,) = queue_reads(s, "A")
    # the proxy dropped both probe reads: the reply to A proves nothing about the ids
    pending, dropped = s.dispatch(read_reply(a.msg_id, b"1"))
    assert pending is a and [p.msg_id for p in dropped] == [0, 1]
    assert s.ids == "unknown" and s.dropped_requests == 2
    # and the probe is over: a later repeated label is not taken as its proof
    (b,) = queue_reads(s, "B")
    with pytest.raises(ProtocolError):
        s.dispatch(read_reply(a.msg_id, b"2"))
    assert s.ids == "unknown" and b in s.queue


def test_the_legacy_proof_needs_the_probes_second_read_at_the_head() -> None:
    s = session("auto")
    s.register_probe("w", 0.0, 1.0)
    s.dispatch(read_reply(0, b"100"))
    s.dispatch(read_reply(1, b"100"))  # echoed
    a, _ = queue_reads(s, "A", "B")
    s.dispatch(read_reply(a.msg_id, b"1"))
    with pytest.raises(ProtocolError, match="use id_policy='legacy'"):
        s.dispatch(read_reply(a.msg_id, b"1"))  # a repeat on an echoing proxy: no guess
    assert s.ids == "echoed" and s.mislabeled_replies == 0


def test_requests_ahead_of_the_answered_one_were_dropped() -> None:
    s = session()
    a, b, c = queue_reads(s, "A", "B", "C")
    pending, dropped = s.dispatch(read_reply(c.msg_id, b"3"))
    assert pending is c and dropped == [a, b] and s.dropped_requests == 2
    assert not s.queue and not s.by_id and s.bytes_in_flight == 0


def test_a_late_reply_to_an_abandoned_request_is_discarded() -> None:
    s = session()
    a, b = queue_reads(s, "A", "B")
    a.abandoned = True
    assert s.dispatch(read_reply(a.msg_id, b"1")) == (None, [])
    assert list(s.queue) == [b] and a.msg_id not in s.by_id
    assert s.bytes_in_flight == b.size


@pytest.mark.parametrize("policy", ["strict", "legacy"])
def test_a_reply_nobody_waits_for_is_a_protocol_error(policy: str) -> None:
    s = session(policy)
    with pytest.raises(ProtocolError) as err:
        s.dispatch(read_reply(5, b"evil"))
    assert str(err.value) == "reply with id 5 answers no request: no request is pending"
    a, _ = queue_reads(s, "A", "B")
    with pytest.raises(ProtocolError) as err:
        s.dispatch(read_reply(9, b"evil"))
    assert str(err.value) == (
        f"reply with id 9 answers no request: 2 requests are pending, the oldest with id {a.msg_id}"
    )


def test_a_repeated_label_on_a_strict_connection_names_the_legacy_policy() -> None:
    s = session("strict")
    a, b = queue_reads(s, "A", "B")
    s.dispatch(read_reply(a.msg_id, b"1"))
    with pytest.raises(ProtocolError) as err:
        s.dispatch(read_reply(a.msg_id, b"2"))
    assert str(err.value) == (
        f"reply with id {a.msg_id} answers no request: 1 requests are pending, the oldest with"
        f" id {b.msg_id} (it repeats the previous reply's id, as a pre-9.0 proxy does; use"
        " id_policy='legacy' for such a proxy)"
    )
    assert s.mislabeled_replies == 0 and list(s.queue) == [b]


def test_a_legacy_repeat_lands_on_the_head_in_order() -> None:
    s = session("legacy")
    a, b = queue_reads(s, "A", "B")
    a.abandoned = True  # a timed out; b is the only request anyone waits for
    assert s.dispatch(read_reply(a.msg_id, b"1")) == (None, [])
    assert s.dispatch(read_reply(a.msg_id, b"2")) == (b, [])  # labelled with a's id
    assert s.mislabeled_replies == 1 and not s.queue and s.last_label == a.msg_id


def test_a_legacy_repeat_with_two_awaited_requests_is_never_guessed() -> None:
    s = session("legacy")
    a, b, c = queue_reads(s, "A", "B", "C")
    s.dispatch(read_reply(a.msg_id, b"1"))
    with pytest.raises(ProtocolError) as err:
        s.dispatch(read_reply(a.msg_id, b"2"))
    assert str(err.value) == (
        f"reply with id {a.msg_id} repeats its batch's id, and more than one request awaits a"
        " reply: it cannot be told whose it is"
    )
    assert s.mislabeled_replies == 0
    # with the head abandoned, one awaited request behind it: the head takes it (discarded)
    b.abandoned = True
    assert s.dispatch(read_reply(a.msg_id, b"2")) == (None, [])
    assert list(s.queue) == [c] and s.mislabeled_replies == 1
    # with the head awaited and everything behind it abandoned: the head takes it
    d = queue_reads(s, "D")[0]
    d.abandoned = True
    assert s.dispatch(read_reply(a.msg_id, b"3")) == (c, [])


def test_a_legacy_reply_with_an_unrelated_id_is_refused() -> None:
    s = session("legacy")
    a, _ = queue_reads(s, "A", "B")
    s.dispatch(read_reply(a.msg_id, b"1"))
    with pytest.raises(ProtocolError, match="answers no request") as err:
        s.dispatch(read_reply(0x4242, b"2"))
    assert "pre-9.0" not in str(err.value)  # the hint is for proxies not declared legacy


# ------------------------------------------------------------------ checks of a matched reply


def test_the_reply_mode_must_be_the_requests() -> None:
    s = session()
    (a,) = queue_reads(s, "A")
    with pytest.raises(ProtocolError) as err:
        s.dispatch(Reply(a.msg_id, Mode.WRITE, b"1"))
    assert str(err.value) == f"reply id {a.msg_id} has mode 1, but the request for 'A' had mode 0"
    w = s.register("W", encode_write(0, "W", "1"), "w", 1.0)
    with pytest.raises(ProtocolError) as err:
        s.dispatch(Reply(w.msg_id, Mode.READ, b"1"))
    assert str(err.value) == f"reply id {w.msg_id} has mode 0, but the request for 'W' had mode 1"


@pytest.mark.parametrize("mode", [Mode.READ, Mode.WRITE])
def test_a_four_byte_reply_to_a_read_or_write_is_refused(mode: int) -> None:
    s = session()
    frame = encode_read(0, "A") if mode == Mode.READ else encode_write(0, "A", "1")
    p = s.register("A", frame, "w", 1.0)
    with pytest.raises(ProtocolError) as err:
        s.dispatch(Reply(p.msg_id, None))
    assert str(err.value) == f"reply id {p.msg_id} has no mode, but 'A' was a mode-{mode} request"


def test_a_four_byte_reply_answers_an_unknown_mode() -> None:
    s = session()
    p = s.register("X", H("0000 0003 07 0000"), "w", 1.0)  # mode 7: KVP answers id + 0000
    assert s.dispatch(Reply(p.msg_id, None)) == (p, [])
    q = s.register("Y", encode_write_array(0, "W", [1]), "w", 1.0)
    assert s.dispatch(Reply(q.msg_id, None)) == (q, [])  # mode 3 may be answered so, too


def test_a_legacy_write_reply_must_echo_the_value_written() -> None:
    def outcome(value: bytes, status: int) -> str:
        s = session("legacy")
        p = s.register("W", encode_write(0, "W", "12"), "w", 1.0)
        try:
            assert s.dispatch(Reply(p.msg_id, Mode.WRITE, value, status)) == (p, [])
        except ProtocolError as exc:
            return str(exc)
        return "ok"

    assert outcome(b"13", 1) == "reply id 0 does not echo the value written to 'W'"
    assert outcome(b"12", 1) == "ok"  # the echo
    assert outcome(b"", 0) == "ok"  # a refusal without an echo
    assert outcome(b"12", 0) == "ok"  # a refusal with it
    assert outcome(b"", 1) != "ok"  # success without the echo
    assert outcome(b"99", 0) != "ok"  # a refusal echoing another value


def test_an_echoing_proxy_is_not_held_to_the_echo() -> None:
    s = session("strict")
    p = s.register("W", encode_write(0, "W", "12"), "w", 1.0)
    assert s.dispatch(Reply(p.msg_id, Mode.WRITE, b"13")) == (p, [])


def test_a_read_that_changes_shape_is_another_variables_reply() -> None:
    s = session()
    (a,) = queue_reads(s, "AX")
    s.dispatch(read_reply(a.msg_id, b"{E6AXIS: A1 1.0}"))
    (a,) = queue_reads(s, "AX")
    s.dispatch(read_reply(a.msg_id, b"{E6AXIS: A1 2.0}"))  # same shape, new value: fine
    (a,) = queue_reads(s, "AX")
    with pytest.raises(ProtocolError) as err:
        s.dispatch(read_reply(a.msg_id, b"12"))
    assert str(err.value) == (
        f"reply id {a.msg_id} for 'AX' reads like 'number', but that variable read like"
        " '{E6AXIS:' before: a reply for another variable"
    )


def test_empty_or_failed_reads_teach_no_shape() -> None:
    s = session()
    for reply_value, status in ((b"", 1), (b"12", 0)):
        (a,) = queue_reads(s, "V")
        s.dispatch(read_reply(a.msg_id, reply_value, status))
    (a,) = queue_reads(s, "V")
    s.dispatch(read_reply(a.msg_id, b"TRUE"))  # the first shape it learns
    assert s.text_prefix("V") is None
    (a,) = queue_reads(s, "V")
    with pytest.raises(ProtocolError, match="reads like 'number'"):
        s.dispatch(read_reply(a.msg_id, b"1"))


def test_shapes_are_remembered_for_at_most_1024_names_and_short_names_only() -> None:
    s = session()
    s.answered_read("N" * 200, 1, b"#A")  # 200 characters: remembered
    s.answered_read("M" * 201, 1, b"#A")  # 201: not
    assert s.text_prefix("N" * 200) == b"#" and s.text_prefix("M" * 201) is None
    s.answered_read("M" * 201, 2, b"1")  # no memory, no complaint
    for i in range(1023):
        s.answered_read(f"V{i}", 1, b'"x"')
    assert s.text_prefix("N" * 200) == b"#"  # 1024 entries: all kept
    s.answered_read("NEW", 1, b"#B")
    assert s.text_prefix("N" * 200) is None  # the oldest evicted
    assert s.text_prefix("V0") == b'"' and s.text_prefix("NEW") == b"#"
    with pytest.raises(ProtocolError):  # V0 kept its shape: a number now is another's reply
        s.answered_read("V0", 3, b"7")


# ------------------------------------------------------------------ the transports' idle path


def test_answered_idle_checks_and_labels() -> None:
    s = session("legacy")
    frame = encode_write(0x0102, "W", "5")
    s.answered_idle("W", frame, Reply(0x0102, Mode.WRITE, b"5"))
    assert s.last_label == 0x0102
    with pytest.raises(ProtocolError) as err:
        s.answered_idle("W", frame, Reply(0x0103, Mode.WRITE, b"6"))
    assert str(err.value) == "reply id 259 does not echo the value written to 'W'"
    assert s.last_label == 0x0102


def test_answered_read_learns_and_checks_shapes() -> None:
    s = session()
    s.answered_read("AX", 4, b"{E6AXIS: A1 1}")
    assert s.last_label == 4 and s.text_prefix("AX") == b"{E6AXIS:"
    s.answered_read("AX", 5, b"{E6AXIS: A1 2}")  # its known prefix: accepted as it is
    assert s.last_label == 5
    with pytest.raises(ProtocolError, match=r"reads like '\{E6POS:'"):
        s.answered_read("AX", 6, b"{E6POS: X 1}")
    assert s.last_label == 6  # the label is the reply's, whatever its fate
    s.answered_read("N", 7, b"12")
    s.answered_read("N", 8, b"-3")  # a number stays a number
    assert s.text_prefix("N") is None  # a number is no prefix of its text
    with pytest.raises(ProtocolError) as err:
        s.answered_read("N", 9, b"TRUE")
    assert str(err.value) == (
        "reply id 9 for 'N' reads like 'BOOL', but that variable read like 'number' before:"
        " a reply for another variable"
    )
    with pytest.raises(ProtocolError):  # only a literal prefix shape is taken by its prefix
        s.answered_read("N", 10, b"number1")
    s.answered_read("S", 1, b'"ab"')
    with pytest.raises(ProtocolError):
        s.answered_read("S", 2, b"#X")
    s.answered_read("E", 1, b"#X")
    s.answered_read("E", 2, b"#Y")
    with pytest.raises(ProtocolError):
        s.answered_read("E", 3, b"'c'")


def test_clear_returns_every_pending_request_oldest_first() -> None:
    s = session("auto")
    s.register_probe("w", 0.0, 1.0)
    a, _ = queue_reads(s, "A", "B")
    got = s.clear()
    assert [p.name for p in got] == [PROBE_VARIABLE, PROBE_VARIABLE, "A", "B"] and got[2] is a
    assert not s.queue and not s.by_id and s.bytes_in_flight == 0
    # the probe is forgotten: a new connection's repeat proves nothing
    c, _ = queue_reads(s, "C", "D")
    s.dispatch(read_reply(c.msg_id, b"1"))
    with pytest.raises(ProtocolError):
        s.dispatch(read_reply(c.msg_id, b"1"))
    assert s.ids == "unknown"


def test_the_last_free_id_is_found_after_65535_taken() -> None:
    s = session()
    (p,) = queue_reads(s, "A")
    s.by_id = {i: p for i in range(0x10000) if i != 0x1233}
    s.next_id = 0x1234  # the free id is the last one tried
    assert s.register("B", encode_read(0, "B"), "w", 1.0).msg_id == 0x1233
    assert s.next_id == 0x1234


def test_no_free_id_when_all_65536_are_pending() -> None:
    s = session()
    (p,) = queue_reads(s, "A")
    s.by_id = dict.fromkeys(range(0x10000), p)  # every id taken (abandoned requests keep theirs)
    with pytest.raises(ProtocolError) as err:
        s.register("B", encode_read(0, "B"), "w", 1.0)
    assert str(err.value) == "no free message id"


def test_counters_and_bytes_add_up_over_many_replies() -> None:
    s = session()
    a = s.register_sent("A", encode_read(0x0100, "A"), "w", 1.0)
    b = s.register_sent("BB", encode_read(0x0101, "BB"), "w", 1.0)
    assert s.bytes_in_flight == a.size + b.size == 17
    assert s.dispatch(read_reply(0x0101, b"1")) == (b, [a])
    for _ in range(2):  # two rounds of two requests, the first of each dropped
        _, second = queue_reads(s, "X", "Y")
        s.dispatch(read_reply(second.msg_id, b"1"))
    assert s.dropped_requests == 3 and list(s.queue) == [] and s.bytes_in_flight == 0
    s = session("legacy")
    for i in range(3):  # a legacy proxy repeating one label three times
        p, _ = queue_reads(s, "X", "Y")
        p.abandoned = True
        if i == 0:
            s.dispatch(read_reply(p.msg_id, b"1"))
        else:
            s.dispatch(read_reply(s.last_label or 0, b"1"))  # p's reply, mislabelled
        s.dispatch(read_reply(s.last_label or 0, b"2"))  # q's reply, mislabelled
    assert s.mislabeled_replies == 5


def test_a_legacy_write_echo_is_taken_after_a_long_name() -> None:
    """The echo is compared with the value block after the name, whose length is two bytes."""
    s = session("legacy")
    name = "W" * 300  # the name length's low byte alone (0x2C) would point into the name
    p = s.register(name, encode_write(0, name, "12"), "w", 1.0)
    assert s.dispatch(Reply(p.msg_id, Mode.WRITE, b"12")) == (p, [])
