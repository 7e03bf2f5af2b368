"""A stock client reads and writes the emulator exactly as it would a KRC4 with KVP 9.0.

The client is PyPI ``py-openshowvar`` 1.1.7 (module ``py_openshowvar``), used unmodified: if
our emulator drifted from the KVP 9.0 wire format, this is the code users would see break.
What the client does, read from its source (one 150-line module):

* requests are ``id | len | mode | name-block [| value-block]``, name and value UTF-8 encoded;
* a reply is taken from ONE ``sock.recv(256)``: the value is everything between the 7-byte
  header and the last 3 bytes (the value length field is ignored), and it is returned only if
  the last byte is ``01`` and the echoed id equals ``msg_id``; otherwise ``None``;
* ``msg_id`` starts at ``random.randint(1, 100)``, advances by one only after a successful
  reply and wraps ``% 65536``; a failure leaves it where it was.

Each test gives the client a 2 s socket timeout (it has none of its own) so a regression fails
fast instead of hanging, and passes ``debug=False`` (the default prints every reply twice).
"""

from __future__ import annotations

import socket
from collections.abc import Iterator

import pytest
from py_openshowvar import openshowvar  # type: ignore[import-untyped]

from kukavarproxy_emu import EmulatorThread
from pyopenshowvar.protocol import HEADER_SIZE, decode_reply, encode_read

HOME_AXIS = (
    b"{E6AXIS: A1 0.0, A2 -90.0000, A3 90.0000, A4 0.0, A5 0.0, A6 0.0,"
    b" E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
)
#: py_openshowvar's single ``recv(256)`` holds the 7-byte header, the value and the 3-byte tail.
RECV_SIZE = 256
MAX_STOCK_VALUE = RECV_SIZE - 7 - 3


@pytest.fixture
def client(ideal_emulator_thread: EmulatorThread) -> Iterator[openshowvar]:
    c = openshowvar(ideal_emulator_thread.host, ideal_emulator_thread.port)
    # The constructor swallows connect errors; fail here rather than on the first read.
    assert c.sock.getpeername()[1] == ideal_emulator_thread.port
    c.sock.settimeout(2.0)
    yield c
    c.close()


def declare_text(emu: EmulatorThread, name: str, length: int, text: str) -> None:
    """Declare a CHAR[length] global holding ``text``, on the emulator's own loop."""
    emu.call(lambda: emu.store.declare(name, "CHAR", (length,), init=f'"{text}"'))


def raw_read(emu: EmulatorThread, name: str) -> bytes:
    """The exact reply frame the emulator sends for a read, read by its length field."""
    with socket.create_connection((emu.host, emu.port), timeout=2.0) as s:
        s.sendall(encode_read(7, name))
        frame = b""
        while len(frame) < HEADER_SIZE or len(frame) < HEADER_SIZE + int.from_bytes(
            frame[2:4], "big"
        ):
            chunk = s.recv(4096)
            assert chunk, "emulator closed the connection mid-frame"
            frame += chunk
    return frame


# --- reads ---------------------------------------------------------------------------------


def test_can_connect(client: openshowvar) -> None:
    assert client.can_connect is True


def test_reads_ov_pro(client: openshowvar) -> None:
    assert client.read("$OV_PRO", debug=False) == b"100"


def test_reads_axis_act_home_text_exactly(client: openshowvar) -> None:
    assert client.read("$AXIS_ACT", debug=False) == HOME_AXIS


def test_reads_robname_as_quoted_text(client: openshowvar) -> None:
    assert client.read("$ROBNAME[]", debug=False) == b'"KR6-EMULATOR"'


def test_ping_is_answered_pong(client: openshowvar) -> None:
    # KVP 9.0's keep-alive: answered without CrossComm; a normal success reply to the client.
    start = client.msg_id
    assert client.read("PING", debug=False) == b"PONG"
    assert client.msg_id == start + 1


def test_unknown_variable_is_empty_bytes_not_none(client: openshowvar) -> None:
    # KVP 9.0 answers an unknown name with an empty value and *success*: the stock client
    # cannot tell it from an empty text, and advances its id as for any success.
    start = client.msg_id
    assert client.read("NO_SUCH_VARIABLE", debug=False) == b""
    assert client.msg_id == start + 1


# --- writes --------------------------------------------------------------------------------


def test_write_ov_pro_and_read_back(
    client: openshowvar, ideal_emulator_thread: EmulatorThread
) -> None:
    assert client.write("$OV_PRO", "50", debug=False) == b"50"  # KVP echoes the written text
    assert client.read("$OV_PRO", debug=False) == b"50"
    assert ideal_emulator_thread.store.get("$OV_PRO") == 50


def test_write_struct_to_myaxis_and_read_back(client: openshowvar) -> None:
    text = (
        "{E6AXIS: A1 10.0, A2 -80.0, A3 95.5, A4 0.0, A5 30.0, A6 -12.25,"
        " E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
    )
    assert client.write("MYAXIS", text, debug=False) == text.encode()
    assert client.read("MYAXIS", debug=False) == (
        b"{E6AXIS: A1 10.0000, A2 -80.0000, A3 95.5000, A4 0.0, A5 30.0000, A6 -12.2500,"
        b" E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
    )
    # a partial aggregate changes only the members it names, as on a KRC
    assert client.write("MYAXIS", "{A1 -5.0}", debug=False) == b"{A1 -5.0}"
    assert client.read("MYAXIS.A1", debug=False) == b"-5.00000"
    assert client.read("MYAXIS.A5", debug=False) == b"30.0000"


def test_refused_write_returns_none_and_keeps_the_id(
    client: openshowvar, ideal_emulator_thread: EmulatorThread
) -> None:
    # KVP echoes the value with tail 00 01 00; the stock client's "failure" is None, and it
    # does not advance msg_id, so the next request reuses the id — which must still work.
    start = client.msg_id
    assert client.write("$AXIS_ACT", "{A1 1.0}", debug=False) is None
    assert client.msg_id == start
    assert client.read("$AXIS_ACT", debug=False) == HOME_AXIS
    assert client.msg_id == start + 1
    # a value the type refuses, and a read-only info text, fail the same way
    assert client.write("$OV_PRO", "101", debug=False) is None  # range 0..100
    assert client.write("$OV_PRO", "fast", debug=False) is None
    assert client.write("@PROXY_TYPE", '"x"', debug=False) is None
    assert ideal_emulator_thread.store.get("$OV_PRO") == 100


# --- message ids ---------------------------------------------------------------------------


def test_many_sequential_reads_cross_the_one_byte_id_boundary(client: openshowvar) -> None:
    # The echoed id is checked on every reply; 300 reads from id 1 cover ids 255 -> 256 -> 300.
    client.msg_id = 1
    for expected_id in range(1, 301):
        assert client.msg_id == expected_id
        assert client.read("$OV_PRO", debug=False) == b"100"
    assert client.msg_id == 301


def test_id_wraps_from_65535_to_0(client: openshowvar) -> None:
    client.msg_id = 65534
    seen = []
    for _ in range(4):
        seen.append(client.msg_id)
        assert client.read("$AXIS_ACT", debug=False) == HOME_AXIS
    assert seen == [65534, 65535, 0, 1]  # the emulator echoes id 0 like any other
    assert client.msg_id == 2


# --- the stock client's own limits ---------------------------------------------------------


@pytest.mark.parametrize(
    ("value_len", "expected"),
    [
        (MAX_STOCK_VALUE, "whole"),
        # one byte over: recv(256) ends on the "00 01" of the status block, whose 01 passes
        # for the status byte, so the value comes back as *success* with its last byte cut
        (MAX_STOCK_VALUE + 1, "truncated"),
        (MAX_STOCK_VALUE + 2, None),  # the "status" is the 00 of the status block
        (402, None),  # the "status" is a character of the text
    ],
)
def test_long_values_break_the_stock_clients_single_recv(
    client: openshowvar, ideal_emulator_thread: EmulatorThread, value_len: int, expected: str | None
) -> None:
    # py_openshowvar's bug, not the emulator's (reference/peers.md): one recv(256) per reply,
    # value = bytes 7..-3 of whatever arrived, success = last byte 01. The emulator sends a
    # whole, correct frame (checked with a raw socket). Deterministic on loopback: the reply
    # goes out in one write, so the first recv gets min(frame, 256) bytes.
    text = "".join(chr(ord("A") + i % 26) for i in range(value_len - 2))  # quoted: +2 bytes
    declare_text(ideal_emulator_thread, "LONGTEXT", 400, text)
    value = f'"{text}"'.encode()

    frame = raw_read(ideal_emulator_thread, "LONGTEXT[]")
    reply = decode_reply(frame)
    assert reply.ok and reply.value == value and len(frame) == len(value) + 10

    got = client.read("LONGTEXT[]", debug=False)
    if expected == "whole":
        assert got == value
    elif expected == "truncated":
        assert got == value[:-1]
    else:
        assert got is None


def test_long_write_succeeds_but_the_stock_client_reports_none(
    client: openshowvar, ideal_emulator_thread: EmulatorThread
) -> None:
    # KVP echoes the written value, so a successful write of a long text comes back longer
    # than 256 bytes and py_openshowvar reports it like a failure. The rest of that reply stays
    # in its socket and would be misread by the next call, so this client is not used again.
    declare_text(ideal_emulator_thread, "LONGTEXT", 400, "")
    text = "K" * 300
    assert client.write("LONGTEXT[]", f'"{text}"', debug=False) is None
    assert ideal_emulator_thread.call(ideal_emulator_thread.store.read, "LONGTEXT[]") == f'"{text}"'


def test_non_ascii_text_is_sent_as_utf8(
    client: openshowvar, ideal_emulator_thread: EmulatorThread
) -> None:
    # py_openshowvar encodes UTF-8 while KVP (like the emulator) reads single-byte text: a
    # non-ASCII character arrives as two characters, and reads back as those two bytes.
    assert client.write("MYSTRING[]", '"é"', debug=False) == '"é"'.encode()
    assert ideal_emulator_thread.call(ideal_emulator_thread.store.read, "MYSTRING[]") == '"Ã©"'
    assert client.read("MYSTRING[]", debug=False) == b'"\xc3\xa9"'
