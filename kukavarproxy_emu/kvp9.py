"""KUKAVARPROXY 9.0's request parsing, statement by statement: the ``--wire kvp9`` logic, no I/O.

The real server (ImtsSrl/KUKAVARPROXY, VB6; ``src/frmMain.frm`` as of commit 2745373,
``src/basMain.bas`` as of d01d909) does not frame a byte stream. Each socket event
``frmMain.sockServer_Read`` reads at most 2048 bytes and walks them on their own; nothing
survives to the next event. This module is a port of that walk and of ``basMain.readMsg`` /
``splitMsg`` on byte strings, keeping the VB6 semantics that decide what malformed input gets:

* ``Mid(s, start, n)`` past the end yields what is there (possibly ``""``); ``Asc("")`` and
  ``Right(s, n < 0)`` raise run-time error 5; ``Asc(..) * &H100`` is *Integer* arithmetic, so a
  length byte >= 0x80 raises error 6 (overflow); ``sString(9)`` holds ten blocks, an eleventh
  raises error 9; ``CLng`` of a non-number raises error 13.
* A run-time error inside ``sockServer_Read`` (or in ``readMsg``, which has no handler of its
  own) jumps to ``errRead``: the rest of that read is dropped, replies already written stay
  written, the connection stays open. ``splitMsg`` has its own handler: it returns False and
  that request gets no reply.
* ``sValueToWrite`` is a local of ``sockServer_Read`` that ``readMsg`` only overwrites for modes
  0..3, so an unknown mode answers the *previous* whole reply of the same read, wrapped in a new
  id and length.
* ``Mid(strBuffer, 6, L)`` takes L bytes after the mode byte, one more than the request holds:
  the first byte of the next request in the same read is part of ``strMsg``.

The VB strings are taken as bytes one to one (SocketWrench in binary mode, a single-byte ANSI
code page). The static ``bReadPending`` flag of ``sockServer_Read`` only matters if a read event
re-enters while CrossComm pumps messages; the emulator handles one read to completion before
the next, so the flag is always False here (docs/emulator.md, "wire-faithful mode").

The two CrossComm calls and the socket write are injected (:class:`Wire`), so the same code runs
synchronously on the fast path and with latency/faults in a worker (``kvp9_connection``).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Protocol

__all__ = [
    "KVP_READ_BYTES",
    "ReadOutcome",
    "VbError",
    "Wire",
    "long_to_word",
    "read_msg",
    "sock_server_read",
]

#: ``sockServer(Index).Read(strBuffer, 2048)``: the most one socket event of KUKAVARPROXY takes.
KVP_READ_BYTES = 2048
#: ``Dim sString(9) As String`` in readMsg: block indices 0..9.
_MAX_BLOCKS = 10
_VB_INTEGER_MAX = 0x7FFF
_LONG_MIN, _LONG_MAX = -(2**31), 2**31 - 1
_STATUS_OK = b"\x00\x01\x01"  # longToWord(Len(Chr(1))) & Chr(1)
_STATUS_FAIL = b"\x00\x01\x00"
#: The numbers a KRC prints, as VB's string-to-number coercion reads them with "." as the
#: decimal point: an optional sign, digits, an optional E/D exponent. Thousands separators,
#: currency signs and &H/&O literals never occur in ShowVar output and are not modelled.
_VB_NUMBER = re.compile(rb"[+-]?(?:\d+\.?\d*|\.\d+)(?:[EeDd][+-]?\d+)?")


class VbError(Exception):
    """A VB6 run-time error: control goes to the procedure's ``On Error GoTo`` label."""

    def __init__(self, number: int, what: str) -> None:
        super().__init__(f"run-time error {number}: {what}")
        self.number = number


class Wire(Protocol):
    """What ``sockServer_Read`` needs from the outside world."""

    async def show_var(self, name: bytes) -> bytes:
        """basMain ``ShowVar``: the trimmed value, ``b""`` for an unknown variable."""
        ...

    async def set_var(self, name: bytes, value: bytes) -> bool:
        """basMain ``SetVar``: True when CrossComm accepted the write."""
        ...

    async def send(self, data: bytes) -> None:
        """``sockServer(Index).Write``: one reply, as built."""
        ...


@dataclass(frozen=True, slots=True)
class ReadOutcome:
    """What one socket event did."""

    #: Requests the loop went through (answered or not).
    messages: int
    #: False when the event ended in ``errRead`` (the idle timer is then not refreshed).
    completed: bool


# --------------------------------------------------------------------------- VB6 primitives


def _asc(s: bytes, pos: int) -> int:
    """``Asc(Mid(s, pos, 1))`` (1-based); ``Asc("")`` is error 5."""
    if pos > len(s):
        raise VbError(5, "invalid procedure call (Asc of an empty string)")
    return s[pos - 1]


def _mid(s: bytes, start: int, length: int) -> bytes:
    """``Mid(s, start, length)``: never raises for start >= 1 and length >= 0."""
    return s[start - 1 : start - 1 + length]


def _right(s: bytes, n: int) -> bytes:
    """``Right(s, n)``: the last n bytes (all of s when n is larger); a negative n is error 5."""
    if n < 0:
        raise VbError(5, "invalid procedure call (Right with a negative length)")
    return s[max(0, len(s) - n) :]  # n = 0 starts at len(s): b""


def _integer_word(s: bytes, pos: int) -> int:
    """``Asc(Mid(s, pos, 1)) * &H100 + Asc(Mid(s, pos + 1, 1))`` with VB *Integer* operands."""
    high = _asc(s, pos) * 0x100
    if high > _VB_INTEGER_MAX:
        raise VbError(6, "overflow")
    return high + _asc(s, pos + 1)


def long_to_word(value: int) -> bytes:
    """basMain ``longToWord``: the low 16 bits, high byte first (also for negative Longs)."""
    return (value & 0xFFFF).to_bytes(2, "big")


def _word_to_long(s: bytes) -> int:
    """basMain ``wordToLong``: 0 unless exactly two bytes."""
    return int.from_bytes(s, "big") if len(s) == 2 else 0


def _vb_round(x: float) -> int:
    """Assignment of a Double to an Integer/Long: round half to even (Python's round)."""
    return round(x)


def _clng(token: bytes) -> int:
    """``CLng(token)`` for a token of ``Split(value, " ")`` (which holds no space): error 13
    unless a number."""
    if not _VB_NUMBER.fullmatch(token):
        raise VbError(13, f"type mismatch (CLng of {token!r})")
    number = float(token.replace(b"D", b"E").replace(b"d", b"E"))
    if math.isinf(number):
        raise VbError(6, "overflow")
    value = _vb_round(number)
    if not _LONG_MIN <= value <= _LONG_MAX:
        raise VbError(6, "overflow")
    return value


# --------------------------------------------------------------------------- basMain


def split_msg(msg: bytes) -> list[bytes] | None:
    """basMain ``splitMsg``: up to ten length-prefixed blocks; None where VB returns False."""
    blocks = [b""] * _MAX_BLOCKS
    start = 1  # nStartPos As Integer
    index = 0
    while start < len(msg):  # Do While nStartPos < nLunghezzaMsg
        try:
            length = _integer_word(msg, start)
        except VbError:
            return None  # errsplitMsg
        if index >= _MAX_BLOCKS:
            return None  # sArrayString(10): subscript out of range
        blocks[index] = _mid(msg, start + 2, length)
        start += 2 + length
        if start > _VB_INTEGER_MAX:
            return None  # the sum no longer fits nStartPos As Integer: overflow
        index += 1
    return blocks


async def read_msg(
    function: int, msg: bytes, previous: bytes, wire: Wire, *, ping: bool
) -> bytes | None:
    """basMain ``readMsg``: the new ``sValueToWrite``, or None where it returns False.

    ``previous`` is ``sValueToWrite`` as the caller holds it; an unknown ``function`` leaves it
    as it is (and readMsg still returns True). A CLng error of mode 2 propagates (VbError).
    """
    blocks = split_msg(msg)
    if blocks is None:
        return None
    name = blocks[0]
    if function == 0:
        # PING is answered without CrossComm (v9.0, commit f3f7887); exact, case-sensitive.
        value = b"PONG" if ping and name == b"PING" else await wire.show_var(name)
        return b"\x00" + long_to_word(len(value)) + value + _STATUS_OK
    if function == 1:
        value = blocks[1]
        ok = await wire.set_var(name, value)
        return b"\x01" + long_to_word(len(value)) + value + (_STATUS_OK if ok else _STATUS_FAIL)
    if function == 2:
        value = await wire.show_var(name)
        # Split splits on every single space; Split("", " ") is an empty array (UBound -1),
        # which gives no words just as one token (UBound 0) does
        tokens = value.split(b" ")
        words = b""
        if len(tokens) - 1 > 0:  # If nDimVettore > 0 (one token gives nothing)
            words = b"".join(long_to_word(_clng(t)) for t in tokens)
        return b"\x02" + long_to_word(len(words)) + words + _STATUS_OK
    if function == 3:
        value = blocks[1]
        count = _vb_round(len(value) / 2)  # nDimVettore As Integer = Len / 2: 2.5 -> 2, 3.5 -> 4
        base = name[:-2] if name.endswith(b"[]") else name
        ok = False  # bWriteAllOk: the last element's result wins
        for a in range(count):
            element = base + b"[" + str(a + 1).encode() + b"]"
            text = str(_word_to_long(_mid(value, 2 * a + 1, 2))).encode()
            ok = await wire.set_var(element, text)
        # sMsg (the Case 2 local) is empty here: no value, only the status
        return b"\x03\x00\x00" + (_STATUS_OK if ok else _STATUS_FAIL)
    return previous


# --------------------------------------------------------------------------- frmMain


async def sock_server_read(
    buffer: bytes, wire: Wire, *, ping: bool = True, legacy_ids: bool = False
) -> ReadOutcome:
    """frmMain ``sockServer_Read`` after its ``Read(strBuffer, 2048)``: walk one socket read.

    ``legacy_ids`` keeps the first request's id for every reply of the read, the bug fixed in
    9.0 (commit 3e0225b) where ``sMsgID`` was not re-read inside the loop.
    """
    value_to_write = b""  # Dim sValueToWrite: "" at every event
    messages = 0
    try:
        # lMsgID = CLng(Asc(Mid(.., 1, 1))) * &H100 + ...: its Asc() of a missing byte raises
        # no sooner than the length's below, which needs all four header bytes
        msg_id = _mid(buffer, 1, 2)
        length = _integer_word(buffer, 3)
        # The loop test is Len >= L, not L + 4: a request up to 4 bytes short is still parsed
        # (with what is there), and the Right() below then raises.
        while len(buffer) >= length:
            messages += 1
            msg = _mid(buffer, 6, length)
            function = _asc(buffer, 5)
            answer = await read_msg(function, msg, value_to_write, wire, ping=ping)
            if answer is not None:  # readMsg returned True
                value_to_write = msg_id + long_to_word(len(answer)) + answer
                await wire.send(value_to_write)
            buffer = _right(buffer, len(buffer) - (length + 4))
            if len(buffer) > 3:
                if not legacy_ids:
                    msg_id = _mid(buffer, 1, 2)
                length = _integer_word(buffer, 3)
            # else: L keeps its old value; a 0..3-byte rest with L <= its length loops once more
            # and fails at Asc(Mid(strBuffer, 5, 1)).
    except VbError:
        return ReadOutcome(messages, completed=False)  # errRead
    return ReadOutcome(messages, completed=True)
