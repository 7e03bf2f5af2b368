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
from pyopenshowvar.protocol import Mode, Reply, Request, encode_reply
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


@pytest.mark.parametrize("sync_client", [False, True], ids=["asyncio", "sync"])
async def test_a_legacy_proxy_gets_one_request_at_a_time_and_a_lost_reply_is_no_value(
    sync_client: bool,
) -> None:
    # A pre-9.0 proxy that loses one request in the middle of a read shifts every later reply
    # of that read by one (two INTs read alike: no check could tell). With one request in
    # flight no read ever holds two requests, and the lost one only times out.
    reads: list[list[str]] = []

    async def on_read(reqs: list[Request], w: asyncio.StreamWriter) -> None:
        reads.append([r.name for r in reqs])
        live = [r for i, r in enumerate(reqs) if not (r.name == "DROP" and i > 0)]
        live = [r for r in live if r.name != "LOST"]  # its reply never comes
        w.write(_legacy(reqs, [answer(r, None if r.mode else VALUES.get(r.name)) for r in live]))

    names = ["NUM", "AX", "LOST", "DROP", "LAST"]
    async with FakeProxy(on_read=on_read) as port:
        if sync_client:
            from pyopenshowvar import sync

            def run() -> dict[str, object]:
                with sync.Client(port=port, timeout=0.5) as kvp:
                    kvp.read("NUM")  # the probe is answered meanwhile: legacy proven
                    assert kvp.connection is not None and kvp.connection.session.ids == "legacy"
                    res = kvp.read_many(names)
                    return {n: r.text if r.ok else r.error for n, r in res.items()}

            outcomes = await asyncio.to_thread(run)
        else:
            async with Client(port=port, timeout=0.5) as kvp:
                await kvp.read("NUM")
                assert kvp.connection is not None and kvp.connection.session.ids == "legacy"
                res = await kvp.read_many(names)
                outcomes = {n: r.text if r.ok else r.error for n, r in res.items()}
    assert outcomes["NUM"] == "12" and outcomes["AX"] == "{E6AXIS: A1 1.0}"
    assert isinstance(outcomes["LOST"], KvpTimeoutError)
    for name in ("DROP", "LAST"):  # not sent before LOST timed out: never a neighbour's value
        assert isinstance(outcomes[name], KvpTimeoutError), outcomes
    assert all(len(r) == 1 for r in reads[1:]), reads  # after the probe: one request per read


@pytest.mark.parametrize("fault", ["shape", "echo", "mode"])
async def test_legacy_replies_are_checked_all_the_same(fault: str) -> None:
    # A reply with the right id that cannot be the answer: another shape than the variable
    # had, an echo that is not the value written, another mode.
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        wrong = req.name == "BAD"
        if fault == "shape" and wrong:
            w.write(answer(req, b"12"))
        elif fault == "echo" and wrong:
            w.write(answer(req, b"2"))
        elif fault == "mode" and wrong:
            w.write(encode_reply(Reply(req.msg_id, Mode.WRITE, b"1")))
        else:
            w.write(answer(req, VALUES.get(req.name)))

    async with (
        FakeProxy(handler) as port,
        Client(port=port, timeout=1.0, id_policy="legacy") as kvp,
    ):
        assert (await kvp.read("AX")).encode() == VALUES["AX"]
        with pytest.raises(KvpConnectionError) as info:
            if fault == "shape":
                await _read_as(kvp, "BAD", "AX")
            elif fault == "echo":
                await kvp.write("BAD", "1")
            else:
                await kvp.read("BAD")
        expected = {"shape": "reads like", "echo": "does not echo", "mode": "has mode"}[fault]
        assert expected in str(info.value)


async def _read_as(kvp: Client, name: str, learned: str) -> str:
    """Read ``name`` after teaching the client that it reads like ``learned``."""
    conn = kvp.connection
    assert conn is not None
    conn.session._shapes[name] = conn.session._shapes[learned]
    return await kvp.read(name)


async def test_a_reply_labelled_with_an_abandoned_requests_id_reaches_only_the_newest() -> None:
    # SLOW times out; the proxy then reads SLOW and NEXT together and labels both replies
    # with SLOW's id (pre-9.0): the first is SLOW's (discarded), the second can only be NEXT's.
    held: list[Request] = []

    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "SLOW":
            held.append(req)
            return
        if held:
            slow = held.pop()
            w.write(answer(slow) + slow.msg_id.to_bytes(2, "big") + answer(req)[2:])
            return
        w.write(answer(req))

    async with (
        FakeProxy(handler) as port,
        Client(port=port, timeout=0.2, id_policy="legacy") as kvp,
    ):
        with pytest.raises(KvpTimeoutError):
            await kvp.read("SLOW")
        assert await kvp.read("NEXT", timeout=2.0) == "v:NEXT"
        assert await kvp.read("AFTER") == "v:AFTER"


async def test_legacy_policy_never_guesses_on_an_unrelated_id() -> None:
    async def on_read(reqs: list[Request], w: asyncio.StreamWriter) -> None:
        w.write(b"".join(answer(r) for r in reqs))
        if reqs[-1].name == "N1":
            w.write(_unsolicited(12345))

    async with FakeProxy(on_read=on_read) as port, Client(port=port, id_policy="legacy") as kvp:
        outcomes = await _batch_outcomes(kvp, ["N0", "N1"])
        assert outcomes == {"N0": "v:N0", "N1": "v:N1"}
        with pytest.raises(KvpConnectionError, match="answers no request"):
            await kvp.read("N2")


INTS = "DEFDAT $CONFIG\n" + "".join(f"DECL INT ID_{i}={i * 11}\n" for i in range(1, 5)) + "ENDDAT\n"


async def test_the_issues_case_a_legacy_emulator_dropping_the_fourth_reply(
    emulator_factory: EmulatorFactory,
) -> None:
    """``kukavarproxy-emu --quirks legacy-ids --fault drop@4,conn=1``: read_many of four INTs
    returned two values of other variables as success; now the lost one and those after it
    fail, and no value is another variable's. Both clients."""
    from kukavarproxy_emu import Fault
    from pyopenshowvar import sync

    names = [f"ID_{i}" for i in range(1, 5)]

    def wrong(results: dict[str, object]) -> list[str]:
        return [n for n, t in results.items() if isinstance(t, str) and t != n[3:] + n[3:]]

    for sync_client in (False, True):
        emu = await emulator_factory(
            quirks=frozenset({"legacy-ids"}),
            faults=(Fault("drop", nth=4, connection=1),),
            dat_text=INTS,
            robot=False,
        )
        if sync_client:

            def run(port: int) -> dict[str, object]:
                with sync.Client("127.0.0.1", port, timeout=0.3, keepalive=None) as kvp:
                    res = kvp.read_many(names)
                return {n: r.text if r.ok else r.error for n, r in res.items()}

            results = await asyncio.to_thread(run, emu.port)
        else:
            async with Client(emu.host, emu.port, timeout=0.3, keepalive=None) as kvp:
                res = await kvp.read_many(names)
            results = {n: r.text if r.ok else r.error for n, r in res.items()}
        assert results["ID_1"] == "11", results
        assert isinstance(results["ID_2"], KvpTimeoutError), results  # the dropped reply
        assert wrong(results) == [], results
