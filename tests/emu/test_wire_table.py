"""The differential table: malformed and split input, answered by ``--wire kvp9`` and the robust mode.

Each row is a list of chunks; every chunk reaches the server as ONE socket read (the test waits
until the kvp9 connection has read it before sending the next). After the last chunk a probe,
``PING`` with id BEEF, goes out as a read of its own; a row's output is everything received
before the probe's answer. A row ends ``open`` (the probe was answered), ``closed`` (EOF) or
``silent`` (neither within 0.3 s: the server waits for bytes that never come).

The ``kvp9`` column is derived by hand from KUKAVARPROXY 9.0's source (ImtsSrl/KUKAVARPROXY,
``src/frmMain.frm`` ``sockServer_Read`` as of commit 2745373, ``src/basMain.bas`` ``readMsg``/
``splitMsg``/``ExtractVariableValue`` as of d01d909, ``cCrossComm.ShowVar`` returning
``name & "=" & value``); the comment above each class of rows quotes the statements it follows.
The real server never closes on malformed input, so every kvp9 row ends ``open``. The ``robust``
column is the default mode's documented behaviour (docs/emulator.md): ``SAME`` where it agrees.

Values used: ``$OV_PRO`` = 100 and the torque array of a static robot (``robot=False``), ``WA[1..4]``
an INT array; every row runs on a fresh emulator, so writes do not leak between rows.
"""

from __future__ import annotations

import asyncio
import re
from dataclasses import dataclass
from pathlib import Path

import pytest

from kukavarproxy_emu import Emulator
from kukavarproxy_emu.kvp9_connection import Kvp9ConnectionInfo
from kukavarproxy_emu.testing import EmulatorFactory

H = bytes.fromhex
OV = "244F565F50524F"  # "$OV_PRO"
PROBE = H("BEEF 0007 00 0004 50494E47")  # read PING
PROBE_REPLY = H("BEEF 000A 00 0004 504F4E47 000101")
WA_DAT = "DECL INT WA[4]\nWA[1]=0\nWA[2]=0\nWA[3]=0\nWA[4]=0\n"
TORQUES = b"0.0 -24.7800 -25.5000 -0.800000 -0.600000 0.0 0.0 0.0 0.0 0.0 0.0 0.0"


def read(msg_id: int) -> str:
    """A well-formed read of $OV_PRO."""
    return f"{msg_id:04X} 000A 00 0007 {OV}"


def a100(msg_id: int) -> str:
    """readMsg Case 0: Chr(0) & word(3) & "100" & word(1) & Chr(1), behind id and word(9)."""
    return f"{msg_id:04X} 0009 00 0003 313030 000101"


def empty(msg_id: int) -> str:
    """Case 0 for a name CrossComm does not know: basMain.ShowVar sets "" and returns True."""
    return f"{msg_id:04X} 0006 00 0000 000101"


@dataclass(frozen=True)
class Outcome:
    out: str
    end: str = "open"  # "open" | "closed" | "silent"


SAME = None


@dataclass(frozen=True)
class Row:
    key: str
    what: str
    chunks: tuple[str, ...]
    kvp9: str
    robust: Outcome | None


# fmt: off
TABLE: tuple[Row, ...] = (
    # --- well-formed baselines: both modes agree. readMsg Case 0/1/2 and, for the whole array,
    # ExtractVariableValue's Trim(): no trailing space through KVP.
    Row("W1", "one read", (read(1),), a100(1), SAME),
    Row("W2", "two reads in one read: each reply has its own id (sMsgID re-read in the loop)",
        (read(1) + read(2),), a100(1) + a100(2), SAME),
    Row("W3", "write then read in one read", (f"0002 000E 01 0007 {OV} 0002 3131" + read(3),),
        "0002 0008 01 0002 3131 000101" + "0003 0008 00 0002 3131 000101", SAME),
    Row("W4", "whole array: Trim() removes the KRC's trailing space",
        ("0001 0015 00 0012" + b"$TORQUE_AXIS_ACT[]".hex(),),
        f"0001 {len(TORQUES) + 6:04X} 00 {len(TORQUES):04X} {TORQUES.hex()} 000101", SAME),
    Row("W5", "mode 2 of the torque array: CLng rounds half to even (-25.5 -> -26)",
        ("0001 0015 02 0012" + b"$TORQUE_AXIS_ACT[]".hex(),),
        "0001 001E 02 0018 0000 FFE7 FFE6 FFFF FFFF 0000 0000 0000 0000 0000 0000 0000 000101",
        SAME),
    # --- split across reads (frmMain sockServer_Read: one Read(strBuffer, 2048) per event and
    # no buffer kept; the header of a read is whatever its first 4 bytes are).
    # Read 2 of S1 is "000A 00 0007 $OV_PRO": id 000A, L = 0, nFunction = Asc(Mid(.., 5, 1)) = 7,
    # an unknown mode with sValueToWrite still "" -> "000A 0000"; the rest has L = 0x4F56.
    Row("S1", "read split after its id", ("0001", f"000A 00 0007 {OV}"), "000A 0000",
        Outcome(a100(1))),
    # Read 1: 4 < L = 10, loop not entered. Read 2: L = 0x0724 > 10 bytes.
    Row("S2", "read split after its header", ("0001 000A", f"00 0007 {OV}"), "",
        Outcome(a100(1))),
    # Read 1 has 10 bytes = L: strMsg = Mid(.., 6, 10) holds "$OV" only; Right(10 - 14) then
    # raises (errRead). Read 2 "_PRO": L = 0x524F.
    Row("S3", "read cut after 10 bytes: KVP reads $OV", ("0001 000A 00 0007 244F56", "5F50524F"),
        empty(1), Outcome(a100(1))),
    # 17 of 18 bytes >= L = 14: splitMsg's value block Mid(.., 12, 2) is "1"; SetVar runs.
    Row("S4", "write cut before its last byte: the truncated value is written",
        (f"0002 000E 01 0007 {OV} 0002 31", "31"), "0002 0007 01 0001 31 000101",
        Outcome("0002 0008 01 0002 3131 000101")),
    # 15 bytes >= 14: strMsg has the name block and one byte, no value block: SetVar(name, "").
    Row("S5", "write cut inside its value length: an empty value is written (refused)",
        (f"0002 000E 01 0007 {OV} 00", "02 3131"), "0002 0006 01 0000 000100",
        Outcome("0002 0008 01 0002 3131 000101")),
    # The 5 left-over bytes of read 1 are a header with L = 10 > 5; read 2 starts "0007 $O...",
    # L = 0x244F, so the whole read, the complete request 3 included, is ignored.
    Row("S6", "a request cut by the read boundary takes the next read's requests with it",
        (read(1) + "0002 000A 00", f"0007 {OV}" + read(3)), a100(1),
        Outcome(a100(1) + a100(2) + a100(3))),
    # 2048 = 146 * 14 + 4: the 147th header (L = 10) waits in vain; read 2 (752 bytes) starts
    # "00 0007 $", id 0000, L = 0x0724 = 1828 > 752.
    Row("S7", "200 reads sent at once (2800 bytes) get 146 answers",
        ("".join(read(i) for i in range(1, 147)) + "0093 000A",
         f"00 0007 {OV}" + "".join(read(i) for i in range(148, 201))),
        "".join(a100(i) for i in range(1, 147)),
        Outcome("".join(a100(i) for i in range(1, 201)))),
    # Lone 3 bytes: Asc(Mid(strBuffer, 4, 1)) = Asc("") raises before any reply.
    Row("S8", "a 3-byte fragment, then a read in a later read", ("000100", read(2)), a100(2),
        Outcome("", "closed")),
    # --- wrong L (While Len(strBuffer) >= L; strMsg = Mid(strBuffer, 6, L); the next request
    # starts at Right(strBuffer, Len - (L + 4)), which raises when negative).
    Row("L1", "read with L = 8 (true 10): KVP reads $OV_PR", (f"0001 0008 00 0007 {OV}",),
        empty(1), Outcome("", "closed")),
    # splitMsg: block 1 has length 0000, so sString(1) = "" and the read is answered.
    Row("L2", "read with L = 12 holding two extra zero bytes", (f"0001 000C 00 0007 {OV} 0000",),
        a100(1), Outcome("", "closed")),
    # 14 >= 12: answered from the 9 bytes there; Right(14 - 16) raises after the write.
    Row("L3", "read with L two bytes too large, the bytes never sent", (f"0001 000C 00 0007 {OV}",),
        a100(1), Outcome("", "closed")),
    # L = 0: strMsg = "", nFunction = Asc(Mid(.., 5, 1)) = the next request's first id byte (00):
    # a read of the empty name, unknown -> empty success; then Right(Len - 4) is the read.
    Row("L4", "L = 0, then a read, in one read", ("0029 0000" + read(1),), empty(0x29) + a100(1),
        Outcome("", "closed")),
    Row("L5", "L = 0 alone: Asc(Mid(.., 5, 1)) raises, no reply", ("0029 0000",), "",
        Outcome("", "closed")),
    # Same as L4, but the next id starts with 05: mode 5 is unknown, sValueToWrite is "".
    Row("L6", "L = 0, then a read whose id starts with 05", ("0029 0000" + read(0x0501),),
        "0029 0000" + a100(0x0501), Outcome("", "closed")),
    # L = 1: strMsg = Mid(.., 6, 1) = "" (5 bytes only), function 0, splitMsg("") -> name "".
    Row("L7", "L = 1, the mode byte only", ("0007 0001 00",), empty(7), Outcome("", "closed")),
    # 14 < L = 2048: the loop is not entered, no error; the probe is a read of its own.
    Row("L8", "L larger than the read (0x0800)", (f"0001 0800 00 0007 {OV}",), "",
        Outcome("", "silent")),
    # --- block structure (splitMsg walks length-prefixed blocks up to the end of strMsg, which
    # includes one byte of the next request; Asc(..) * &H100 is Integer arithmetic).
    Row("B1", "name length 9 with 7 name bytes", (f"0001 000A 00 0009 {OV}",), a100(1),
        Outcome("", "closed")),
    # strMsg = "0009 $OV_PRO 00": the name block takes the next request's first byte.
    Row("B2", "name length 9 with 7 name bytes, then a read", (f"0001 000A 00 0009 {OV}" + read(2),),
        empty(1) + a100(2), Outcome("", "closed")),
    # name "$OV_P"; "RO" is the next block's length 0x524F, past the end: sString(1) = "".
    Row("B3", "name length 5 with 7 name bytes", (f"0001 000A 00 0005 {OV}",), empty(1),
        Outcome("", "closed")),
    # &H80 * &H100 overflows an Integer: splitMsg returns False, readMsg False, no reply.
    Row("B4", "name length with its high byte >= 0x80", (f"0001 000A 00 8007 {OV}",), "",
        Outcome("", "closed")),
    Row("B5", "read with an extra value block (ignored by Case 0)", (f"0001 000D 00 0007 {OV} 0001 31",),
        a100(1), Outcome("", "closed")),
    # Case 1 with sString(1) = "": SetVar refuses the empty text, the echo is empty.
    Row("B6", "write without a value block", (f"0002 000A 01 0007 {OV}",),
        "0002 0006 01 0000 000100", Outcome("", "closed")),
    # 18 >= L = 16: the write is done and answered; Right(18 - 20) raises afterwards.
    Row("B7", "write with L two bytes too large", (f"0002 0010 01 0007 {OV} 0002 3131",),
        "0002 0008 01 0002 3131 000101", Outcome("", "closed")),
    # After the write, Right(32 - 20) drops the read's id: "000A 0000 07 $OV_PRO" has id 000A,
    # L = 0 and function 7, unknown: the reply nests the previous 12-byte reply.
    Row("B8", "write with L two bytes too large, then a read, in one read",
        (f"0002 0010 01 0007 {OV} 0002 3131" + read(2),),
        "0002 0008 01 0002 3131 000101" + "000A 000C 0002 0008 01 0002 3131 000101",
        Outcome("", "closed")),
    Row("B9", "write with a third block (ignored)", (f"0002 0012 01 0007 {OV} 0002 3131 0002 3939",),
        "0002 0008 01 0002 3131 000101", Outcome("", "closed")),
    # Nine empty blocks fill sString(1..9); a tenth would be sString(10): error 9, no reply.
    Row("B10", "read followed by nine empty blocks", (f"0001 001C 00 0007 {OV}" + "0000" * 9,),
        a100(1), Outcome("", "closed")),
    Row("B11", "read followed by ten empty blocks", (f"0001 001E 00 0007 {OV}" + "0000" * 10,), "",
        Outcome("", "closed")),
    # --- unknown modes (Select Case has no Case Else; readMsg returns True and sValueToWrite,
    # a local of sockServer_Read, still holds the previous whole reply of the same read).
    Row("U1", "unknown mode 7 alone", (f"0005 000A 07 0007 {OV}",), "0005 0000", SAME),
    Row("U2", "a read, then an unknown mode: the read's reply nested",
        (read(1) + f"0002 000A 07 0007 {OV}",), a100(1) + "0002 000D" + a100(1),
        Outcome(a100(1) + "0002 0000")),
    Row("U3", "a read, then two unknown modes: nested twice",
        (read(1) + f"0002 000A 07 0007 {OV}" + f"0003 000A 07 0007 {OV}",),
        a100(1) + "0002 000D" + a100(1) + "0003 0011 0002 000D" + a100(1),
        Outcome(a100(1) + "0002 0000" + "0003 0000")),
    Row("U4", "an unknown mode, then a read", (f"0001 000A 07 0007 {OV}" + read(2),),
        "0001 0000" + a100(2), SAME),
    # splitMsg fails (overflow) before the Select Case: readMsg False, not even "id 00 00".
    Row("U5", "unknown mode with a name length >= 0x8000", (f"0005 000A 07 8007 {OV}",), "",
        Outcome("0005 0000")),
    # --- left-overs and modes 2/3.
    # Right() leaves "00000000": id 0000, L = 0, Asc(Mid(.., 5, 1)) raises: nothing more.
    # The robust mode answers the read before the L = 0 header, then closes.
    Row("T1", "four zero bytes after a read", (read(1) + "00000000",), a100(1),
        Outcome(a100(1), "closed")),
    # Case 2: CLng("{E6AXIS:") is error 13; readMsg has no handler, so errRead ends the read.
    Row("T2", "mode 2 of a struct, then a read, in one read",
        ("0001 0009 02 0006 4D5941584953" + read(2),), "",
        Outcome("0001 0006 02 0000 000100" + a100(2))),
    # Case 3: nDimVettore As Integer = Len / 2, rounded half to even: 1.5 -> 2 elements, the
    # second from one byte (wordToLong gives 0); status of the last SetVar.
    Row("T3", "mode 3 with a 3-byte payload: two elements written",
        ("0001 000C 03 0004 57415B5D 0003 000102",), "0001 0006 03 0000 000101",
        Outcome("0001 0006 03 0000 000100")),
    # 0.5 -> 0 elements: bWriteAllOk stays False.
    Row("T4", "mode 3 with a 1-byte payload: nothing written", ("0001 000A 03 0004 57415B5D 0001 01",),
        "0001 0006 03 0000 000100", SAME),
    # 3.5 -> 4 elements: WA[4] = 0 from the lone last byte.
    Row("T5", "mode 3 with a 7-byte payload: four elements written",
        ("0001 0010 03 0004 57415B5D 0007 00010002000307",), "0001 0006 03 0000 000101",
        Outcome("0001 0006 03 0000 000100")),
)
# fmt: on


def _chunks(row: Row) -> list[bytes]:
    return [H(c) for c in row.chunks]


async def _consumed(emu: Emulator, total: int) -> None:
    """Wait until the kvp9 connection has read ``total`` bytes (so the next chunk is a new read)."""
    async with asyncio.timeout(5):
        while True:
            infos = emu.connections()
            if infos and isinstance(infos[0], Kvp9ConnectionInfo) and infos[0].bytes_read >= total:
                return
            await asyncio.sleep(0.001)


async def exchange(emu: Emulator, chunks: list[bytes], quiet: float) -> Outcome:
    reader, writer = await asyncio.open_connection(emu.host, emu.port)
    try:
        sent = 0
        for chunk in chunks:
            writer.write(chunk)
            await writer.drain()
            sent += len(chunk)
            if emu.config.wire == "kvp9":
                await _consumed(emu, sent)
        writer.write(PROBE)
        data = b""
        try:
            async with asyncio.timeout(quiet):
                while not data.endswith(PROBE_REPLY):
                    try:
                        more = await reader.read(65536)
                    except ConnectionError:
                        more = b""
                    if not more:
                        return Outcome(data.hex(), "closed")
                    data += more
        except TimeoutError:
            return Outcome(data.hex(), "silent")
        return Outcome(data[: -len(PROBE_REPLY)].hex(), "open")
    finally:
        writer.close()


def _norm(o: Outcome) -> Outcome:
    return Outcome(H(o.out).hex(), o.end)


@pytest.mark.parametrize("wire", ["kvp9", "robust"])
@pytest.mark.parametrize("row", TABLE, ids=[r.key for r in TABLE])
async def test_table_row(emulator_factory: EmulatorFactory, row: Row, wire: str) -> None:
    want = Outcome(row.kvp9) if wire == "kvp9" or row.robust is SAME else row.robust
    emu = await emulator_factory(wire=wire, robot=False, dat_text=WA_DAT)
    got = await exchange(emu, _chunks(row), 0.3 if want.end == "silent" else 5.0)
    assert got == _norm(want), row.what


def test_table_size_and_docs_list_every_difference() -> None:
    malformed = [r for r in TABLE if not r.key.startswith("W")]
    assert len(malformed) >= 30
    differing = {r.key for r in TABLE if r.robust is not SAME}
    doc = (Path(__file__).parents[2] / "docs" / "emulator.md").read_text(encoding="utf-8")
    section = doc.split("### Every difference from the robust mode", 1)[1].split("\n## ", 1)[0]
    listed = set(re.findall(r"^\| ([A-Z]\d+) \|", section, re.MULTILINE))
    assert listed == differing
