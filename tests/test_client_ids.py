"""Never another variable's value as a success (issue 16, item 8).

Servers that answer with ids nobody waits for, swap or duplicate replies, or mislabel them
like a pre-9.0 proxy; the client must match by id when the proxy echoes ids, fall back to
order only for a proxy proven to have the legacy bug (and check mode, echo and value shape
even then), and fail the connection loudly on a reply it cannot attribute.
"""

from __future__ import annotations

import asyncio

import pytest

from kukavarproxy_emu.testing import EmulatorFactory
from pyopenshowvar import Client, KvpConnectionError, KvpTimeoutError
from pyopenshowvar.protocol import Mode, Reply, Request, encode_read, encode_reply, encode_write
from pyopenshowvar.testing import FakeProxy, answer

NAMES = [f"N{i}" for i in range(8)]


def _unsolicited(msg_id: int, value: bytes = b"evil") -> bytes:
    return encode_reply(Reply(msg_id, Mode.READ, value))


async def _batch_outcomes(kvp: Client, names: list[str]) -> dict[str, object]:
    """``name -> text or exception`` of a pipelined batch; asserts no wrong value came back."""
    try:
        results = await kvp.read_many(names)
    except KvpConnectionError as exc:
        return dict.fromkeys(names, exc)
    out: dict[str, object] = {}
    for name, res in results.items():
        out[name] = res.text if res.ok else res.error
        assert not res.ok or res.text == f"v:{name}", f"{name} got another value: {res.text}"
    return out


async def test_unsolicited_reply_fails_the_batch_loudly_never_as_values() -> None:
    async def on_read(reqs: list[Request], w: asyncio.StreamWriter) -> None:
        if any(r.name == "N0" for r in reqs):
            w.write(_unsolicited(40000))  # nobody sent id 40000
        w.write(b"".join(answer(r) for r in reqs))

    async with FakeProxy(on_read=on_read) as port, Client(port=port) as kvp:
        outcomes = await _batch_outcomes(kvp, NAMES)
        assert all(isinstance(o, KvpConnectionError) for o in outcomes.values()), outcomes
        assert "answers no request" in str(outcomes["N0"])
        assert not kvp.connected


async def test_unsolicited_reply_with_a_pending_id_is_caught_by_the_value_shape() -> None:
    # The attacker guesses the next id; N3 is a number, the forged reply reads like a struct.
    forged: list[bool] = []

    async def on_read(reqs: list[Request], w: asyncio.StreamWriter) -> None:
        for r in reqs:
            if r.name == "N3" and forged:
                w.write(_unsolicited(r.msg_id, b"{E6AXIS: A1 1.0}"))
            w.write(answer(r, b"1.5" if r.name == "N3" else None))
            if r.name == "N3":
                forged.append(True)

    async with FakeProxy(on_read=on_read) as port, Client(port=port) as kvp:
        assert await kvp.read("N3") == "1.5"  # the variable's shape is learned: a number
        with pytest.raises(KvpConnectionError, match="reads like"):
            await kvp.read("N3")


async def test_swapped_replies_give_no_wrong_value() -> None:
    async def on_read(reqs: list[Request], w: asyncio.StreamWriter) -> None:
        frames = [answer(r) for r in reqs]
        ours = [i for i, r in enumerate(reqs) if r.name.startswith("N")]  # not the id probe
        if len(ours) >= 2:
            i, j = ours[0], ours[1]
            frames[i], frames[j] = frames[j], frames[i]
        w.write(b"".join(frames))

    async with FakeProxy(on_read=on_read) as port, Client(port=port, timeout=1.0) as kvp:
        outcomes = await _batch_outcomes(kvp, NAMES)
        assert any(isinstance(o, KvpConnectionError | KvpTimeoutError) for o in outcomes.values())
        assert not kvp.connected  # the reply for the "dropped" request is a protocol error


async def test_duplicate_and_idle_replies_drop_the_connection(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        w.write(answer(req))
        if req.name == "TWICE":
            w.write(answer(req))  # the same reply again, while the connection is idle

    async with FakeProxy(handler) as port, Client(port=port) as kvp:
        assert await kvp.read("TWICE") == "v:TWICE"
        for _ in range(50):
            if not kvp.connected:
                break
            await asyncio.sleep(0.01)
        assert not kvp.connected
        with pytest.raises(KvpConnectionError, match="no request is pending"):
            await kvp.read("NEXT")
    assert any("protocol error" in r.getMessage() for r in caplog.records)  # said loudly


async def test_probe_proves_echoed_ids_on_kvp_9(emulator_factory: EmulatorFactory) -> None:
    emu = await emulator_factory()
    async with Client("127.0.0.1", emu.port) as kvp:
        names = ["$OV_PRO", "$MODE_OP", "$AXIS_ACT", "NOPE"] * 10
        res = await kvp.read_many(names)
        assert res["$OV_PRO"].text == "100" and res["$MODE_OP"].text == "#AUT"
        assert kvp.connection is not None and kvp.connection.session.ids == "echoed"
        assert kvp.connection.mislabeled_replies == 0


async def test_probe_proves_the_legacy_bug_and_order_matching_is_checked(
    emulator_factory: EmulatorFactory,
) -> None:
    emu = await emulator_factory(quirks=frozenset({"legacy-ids"}))
    async with Client("127.0.0.1", emu.port) as kvp:
        await kvp.write_many([(f"MYE6ARRAY[{i}]", f"{{A1 {i}.5}}") for i in range(1, 41)])
        names = [f"MYE6ARRAY[{i}].A1" for i in range(1, 41)] + ["$OV_PRO", "$MODE_OP"]
        res = await kvp.read_many(names, typed=True)
        assert [res[n].value for n in names[:40]] == [i + 0.5 for i in range(1, 41)]
        assert res["$MODE_OP"].text == "#AUT"
        conn = kvp.connection
        assert conn is not None and conn.session.ids == "legacy"
        assert conn.mislabeled_replies > 0
    # the same proxy with ids declared echoed: the first repeated id fails loudly
    async with Client("127.0.0.1", emu.port, id_policy="strict") as kvp:
        with pytest.raises(KvpConnectionError, match=r"pre-9\.0"):
            await kvp.read_many(names)


def _legacy(reqs: list[Request], replies: list[bytes]) -> bytes:
    """Relabel ``replies`` with the first request's id, as a pre-9.0 proxy does."""
    first = reqs[0].msg_id.to_bytes(2, "big")
    return b"".join(first + r[2:] for r in replies)


VALUES = {"AX": b"{E6AXIS: A1 1.0}", "NUM": b"12", "DROP": b"{E6AXIS: A1 2.0}"}


@pytest.mark.parametrize("fault", ["shape", "echo", "mode"])
async def test_legacy_order_matching_checks_what_can_be_checked(fault: str) -> None:
    # A legacy proxy that loses one request in the middle of a read shifts every later reply
    # of that read by one; value shape, write echo and mode catch the shift.
    async def on_read(reqs: list[Request], w: asyncio.StreamWriter) -> None:
        live = [r for i, r in enumerate(reqs) if not (r.name == "DROP" and i > 0)]
        w.write(_legacy(reqs, [answer(r, None if r.mode else VALUES.get(r.name)) for r in live]))

    async with FakeProxy(on_read=on_read) as port, Client(port=port, timeout=1.0) as kvp:
        conn = kvp.connection
        assert conn is not None
        for name, value in VALUES.items():  # shapes learned, one request per read
            assert (await kvp.read(name)).encode() == value
        assert conn.session.ids == "legacy"
        items = {
            "shape": [("AX", encode_read(0, "AX")), ("DROP", encode_read(0, "DROP"))],
            "echo": [("W", encode_write(0, "W", "1")), ("DROP", encode_write(0, "DROP", "2"))],
            "mode": [("AX", encode_read(0, "AX")), ("DROP", encode_write(0, "DROP", "2"))],
        }[fault] + [
            ("NUM", encode_write(0, "NUM", "3") if fault == "echo" else encode_read(0, "NUM"))
        ]
        with pytest.raises(KvpConnectionError) as info:
            await conn._request_many(items, 1.0)
        expected = {"shape": "reads like", "echo": "does not echo", "mode": "has mode"}[fault]
        assert expected in str(info.value)


async def test_legacy_policy_never_guesses_on_an_unrelated_id() -> None:
    async def on_read(reqs: list[Request], w: asyncio.StreamWriter) -> None:
        w.write(b"".join(answer(r) for r in reqs))
        if reqs[0].name == "N0":
            w.write(_unsolicited(12345))

    async with FakeProxy(on_read=on_read) as port, Client(port=port, id_policy="legacy") as kvp:
        outcomes = await _batch_outcomes(kvp, ["N0", "N1"])
        assert outcomes == {"N0": "v:N0", "N1": "v:N1"}
        with pytest.raises(KvpConnectionError, match="answers no request"):
            await kvp.read("N2")
