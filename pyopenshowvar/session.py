"""Sans-IO bookkeeping of one client connection: message ids, the in-flight window, and the
rules that match a reply to its request. Shared by the asyncio connection and the blocking
client, so both give the same guarantees; no sockets and no asyncio here.

The guarantee is that a reply is never handed to a request it does not answer:

* **By id** whenever the proxy echoes ids (KVP 9.0, C3 Bridge, our emulator). A reply is given
  to the pending request with its id; requests sent *before* that one and still unanswered were
  dropped by the proxy (servers never reorder) and fail at once. A reply whose id nobody is
  waiting for — an unsolicited or duplicated reply, a reply for a request already failed as
  dropped, a reply on an idle connection — is a protocol error: the connection is dropped and
  every pending call fails loudly. It is never taken as a value.
* **One request in flight** until the proxy is proven to echo ids, and for the whole life of a
  connection to a proxy with the pre-9.0 id bug (every reply to one socket read carries the id
  of the first request of that read). Under ``id_policy="auto"`` the proof is a probe sent as
  soon as a connection opens, while it is quiet: two reads of ``$OV_PRO`` in one segment, whose
  replies nobody waits for. Both answered with their own ids: the proxy echoes ids, and
  pipelining with by-id matching holds for the connection's life. The second answered with the
  first's id: the bug is proven, and requests keep going out one at a time (a ``read_many`` is
  a round trip per name). With one request awaited at a time no reply can be misdelivered: a
  reply with its id answers it; a reply that repeats the previous reply's id (the label of a
  read that also held requests abandoned after a timeout) is matched in order, and in order
  the only request it can land on that anyone awaits is the newest one sent, which is its own
  — a lost reply shifts the later ones onto abandoned requests, whose replies are discarded,
  never onto a request someone waits for. (Pipelining on such a proxy cannot be made safe: a
  reply lost in the middle of a read shifts every later reply of that read onto the wrong
  request, and two variables of the same type cannot be told apart.) What can be checked is
  checked on top: the reply's mode against the request's, a write's echo against the value
  sent, and a read's value shape against what that variable read before.
* ``id_policy="strict"`` declares ids echoed without a probe; ``"legacy"`` declares the bug.

The in-flight window is bounded by a request count and by the bytes of unanswered requests:
at most ``pipeline_bytes`` (2048, the size of KVP's single ``Read``) and at most one TCP segment
of the path (:meth:`Session.limit_to_segment`, with the MSS read at connect time). KVP parses
every socket read on its own and a read ends wherever the segments received so far end; while
everything unanswered fits in one segment, no read can end inside a request. A request larger
than ``pipeline_bytes`` could never arrive in one read and is refused (:meth:`Session.check_size`)
before anything is sent.
"""

from __future__ import annotations

import logging
from collections import deque
from typing import Generic, Literal, TypeVar

from .errors import ProtocolError
from .protocol import FIRST_EXTENDED, MAX_ID, Mode, Reply, encode_read

__all__ = ["IdPolicy", "Pending", "Session"]

log = logging.getLogger(__name__)

#: "fifo" is accepted as the old name of "legacy" (matching in order, now with checks).
IdPolicy = Literal["auto", "strict", "legacy", "fifo"]
IdState = Literal["unknown", "echoed", "legacy"]

W = TypeVar("W")

#: The variable the id probe reads twice: present on every KRC, cheap to read.
PROBE_VARIABLE = "$OV_PRO"
#: Bounds of the per-variable value-shape memory (legacy checks): entries and name length.
_SHAPES_MAX = 1024
_SHAPE_NAME_MAX = 200


class Pending(Generic[W]):
    """One request sent (or about to be) and not yet answered; ``waiter`` is transport-specific."""

    __slots__ = (
        "abandoned",
        "deadline",
        "frame",
        "mode",
        "msg_id",
        "name",
        "sent_at",
        "size",
        "timeout",
        "waiter",
    )

    def __init__(self, msg_id: int, name: str, frame: bytes, waiter: W, timeout: float) -> None:
        self.msg_id = msg_id
        self.name = name
        self.frame = frame
        self.mode = frame[4] if len(frame) > 4 else -1
        self.size = len(frame)
        self.waiter = waiter
        self.sent_at = 0.0
        #: how long its caller waits (a reply later than this means the server is stalled)
        self.timeout = timeout
        #: when its caller stops waiting, on the transport's clock (asyncio: loop time)
        self.deadline = 0.0
        #: the caller gave up (timeout, cancellation); its reply is still expected and discarded
        self.abandoned = False


_NUMBER_START = frozenset(b"+-.0123456789")
#: first bytes of the shapes that are literally a prefix of the text (struct type, quote, #)
_PREFIX_SHAPES = frozenset(b"{\"'#")


def check_id_policy(id_policy: str) -> None:
    if id_policy not in ("auto", "strict", "legacy", "fifo"):
        raise ValueError(f"id_policy must be 'auto', 'strict' or 'legacy', not {id_policy!r}")


def value_shape(value: bytes) -> bytes:
    """A coarse class of a (non-empty) read's text that a variable keeps for life: its type,
    not its value (``b"{E6AXIS:"``, ``b'"'``, ``b"#"``, ``b"BOOL"``, ``b"number"``, ...)."""
    first = value[0]
    if first == 0x7B:  # "{": the struct's type name is part of its shape
        colon = value.find(b":", 1, 64)
        return value[: colon + 1] if colon > 0 else b"{"
    if first in (0x22, 0x27, 0x23):  # '"', "'", "#"
        return value[:1]
    if first in _NUMBER_START:
        return b"number"
    if value == b"TRUE" or value == b"FALSE":
        return b"BOOL"
    return b"other"


def new_reply(msg_id: int, mode: int | None, value: bytes, status: int, code: bytes) -> Reply:
    """A :class:`Reply`, built through its slots: the frozen dataclass's ``__init__`` costs
    several times more, which a serial read's round trip feels (clients' fast paths)."""
    reply = _new(Reply)
    _set_id(reply, msg_id)
    _set_mode(reply, mode)
    _set_value(reply, value)
    _set_status(reply, status)
    _set_code(reply, code)
    return reply


_new = object.__new__
_set_id, _set_mode, _set_value, _set_status, _set_code = (
    Reply.__dict__[field].__set__ for field in ("msg_id", "mode", "value", "status", "code")
)


def _write_value(frame: bytes) -> bytes:
    """The value block of a mode-1 request frame."""
    n = int.from_bytes(frame[5:7], "big")
    return frame[9 + n :]


class Session(Generic[W]):
    """Ids, the queue of pending requests and the matching rules of one connection."""

    def __init__(
        self,
        endpoint: str,
        *,
        max_in_flight: int = 64,
        pipeline_bytes: int = 2048,
        id_policy: IdPolicy = "auto",
    ) -> None:
        check_id_policy(id_policy)
        self.endpoint = endpoint
        self.max_in_flight = max(1, max_in_flight)
        self.pipeline_bytes = max(1, pipeline_bytes)
        #: the unanswered-bytes bound in force: pipeline_bytes, lowered to the path's MSS
        self.window = self.pipeline_bytes
        self.id_policy: IdPolicy = id_policy
        self.ids: IdState = {"auto": "unknown", "strict": "echoed"}.get(id_policy, "legacy")  # type: ignore[assignment]
        self.queue: deque[Pending[W]] = deque()
        self.by_id: dict[int, Pending[W]] = {}
        self.bytes_in_flight = 0
        #: the next message id to try (ids still pending are skipped when allocating)
        self.next_id = 0
        #: the wire id of the last reply matched (a legacy batch repeats it); a transport's
        #: serial fast path sets it when it accepts a read through :meth:`text_prefix`
        self.last_label: int | None = None
        self._probe: tuple[Pending[W], Pending[W]] | None = None
        self._shapes: dict[str, bytes] = {}
        #: replies matched in order because they repeated their batch's label (legacy proxies)
        self.mislabeled_replies = 0
        #: requests the server never answered (detected when a later reply arrived)
        self.dropped_requests = 0

    # ------------------------------------------------------------------ sending side

    @property
    def needs_probe(self) -> bool:
        """True until ids are known to be echoed or proven legacy (``auto`` only)."""
        return self.ids == "unknown"

    def limit_to_segment(self, mss: int) -> None:
        """Keep unanswered bytes within one TCP segment of ``mss`` bytes (see the module doc)."""
        self.window = min(self.pipeline_bytes, max(1, mss))

    def check_size(self, name: str, frame: bytes) -> None:
        """Refuse a request KVP would cut (larger than one of its reads), before sending.

        C3 Bridge messages (types >= 4) are exempt: C3 Bridge collects each request whole
        (``Client::onCollect``), and they are only sent once the server is known to be one.
        """
        if len(frame) > self.pipeline_bytes and frame[4] < FIRST_EXTENDED:
            raise ProtocolError(
                f"request for {name!r} is {len(frame)} bytes; KUKAVARPROXY reads at most "
                f"{self.pipeline_bytes} per socket event and would cut it (see pipeline_bytes)"
            )

    def fits(self, size: int) -> bool:
        if not self.queue:
            return True  # a lone request always goes (check_size bounded it)
        if self.ids != "echoed" and self._awaited():
            return False  # one request in flight until ids are proven echoed (module doc)
        return self._room(size)

    def _room(self, size: int) -> bool:
        return len(self.queue) < self.max_in_flight and self.bytes_in_flight + size <= self.window

    def _awaited(self) -> bool:
        """A request someone still waits for is pending (not only abandoned ones)."""
        return any(not p.abandoned for p in self.queue)

    def stalled(self, size: int, now: float) -> bool:
        """No room, and the oldest request waits for longer than its timeout: the server has
        stopped answering (its requests timed out and fill the window). Waiting for the one
        request in flight of a legacy proxy is not a stall: its caller's timeout bounds it."""
        if not self.queue or self._room(size):
            return False
        head = self.queue[0]
        return now - head.sent_at > head.timeout

    def stall_message(self, now: float) -> str:
        head = self.queue[0]
        waited = now - head.sent_at if head.sent_at else 0.0
        return (
            f"{self.endpoint} stopped answering: {len(self.queue)} requests unanswered, the oldest "
            f"({head.name!r}) for {waited:.1f} s; the connection is marked unhealthy and closed"
        )

    def _alloc_id(self) -> int:
        # Skip ids still pending (abandoned requests keep theirs until answered).
        for _ in range(MAX_ID + 1):
            msg_id = self.next_id
            self.next_id = (msg_id + 1) & MAX_ID
            if msg_id not in self.by_id:
                return msg_id
        raise ProtocolError("no free message id")  # pragma: no cover - needs 65536 pending

    def answered_idle(self, name: str, frame: bytes, reply: Reply) -> None:
        """``reply`` (whose id is ``frame``'s) answers a request sent on an idle connection
        without being queued (the transports' serial fast path): check it."""
        self.check(name, frame, reply)
        self.last_label = reply.msg_id

    def answered_read(self, name: str, msg_id: int, value: bytes) -> None:
        """The idle-path read ``msg_id`` succeeded with non-empty ``value``: check its shape."""
        self.last_label = msg_id
        known = self._shapes.get(name)
        if known is not None and known[0] in _PREFIX_SHAPES and value.startswith(known):
            return  # a struct, string or enum shape is a prefix of the text: no need to classify
        shape = value_shape(value)
        if known != shape:
            self._new_shape(name, shape, known, msg_id)

    def text_prefix(self, name: str) -> bytes | None:
        """What every successful read of ``name`` starts with, once its shape is known and is
        literally a prefix (a struct's type, a string's quote, an enum's ``#``); else None.

        A non-empty value that starts with it passes :meth:`answered_read`'s check, so a
        transport may remember it and accept such a read by setting :attr:`last_label` alone
        (a variable keeps its type for life; an entry evicted here stays just as true there).
        """
        known = self._shapes.get(name)
        return known if known is not None and known[0] in _PREFIX_SHAPES else None

    def register_sent(self, name: str, frame: bytes, waiter: W, timeout: float) -> Pending[W]:
        """Queue a request sent on the serial fast path after all (its reply did not come
        whole and alone): from here on it is matched like any other."""
        pending = Pending(int.from_bytes(frame[:2], "big"), name, frame, waiter, timeout)
        self.queue.append(pending)
        self.by_id[pending.msg_id] = pending
        self.bytes_in_flight += pending.size
        return pending

    def register(self, name: str, frame0: bytes, waiter: W, timeout: float) -> Pending[W]:
        """Queue ``frame0`` (built with id 0) under a free id; ``pending.frame`` is what to send."""
        msg_id = self._alloc_id()
        # ids are the first two bytes of every frame, so re-stamping is exact and cheap
        frame = msg_id.to_bytes(2, "big") + frame0[2:]
        pending = Pending(msg_id, name, frame, waiter, timeout)
        self.queue.append(pending)
        self.by_id[msg_id] = pending
        self.bytes_in_flight += pending.size
        return pending

    def register_probe(self, waiter: W, now: float, timeout: float) -> bytes:
        """Queue the id probe (``auto`` only, on a new connection); returns the bytes to send
        in ONE write before anything else. Nobody waits for its replies (marked abandoned)."""
        frame0 = encode_read(0, PROBE_VARIABLE)
        first = self.register(PROBE_VARIABLE, frame0, waiter, timeout)
        second = self.register(PROBE_VARIABLE, frame0, waiter, timeout)
        first.abandoned = second.abandoned = True
        first.sent_at = second.sent_at = now
        self._probe = (first, second)
        return first.frame + second.frame

    # ------------------------------------------------------------------ receiving side

    def dispatch(self, reply: Reply) -> tuple[Pending[W] | None, list[Pending[W]]]:
        """Match ``reply``: ``(request it answers, requests found dropped)``.

        The request is None when its caller had given up (the late reply is discarded).
        Raises :class:`ProtocolError` when the reply cannot be attributed safely; the caller
        must then drop the connection.
        """
        pending = self.by_id.get(reply.msg_id)
        dropped: list[Pending[W]] = []
        if pending is None:
            pending = self._continuation(reply)
        elif pending is not self.queue[0]:
            # Servers never reorder: the requests ahead of it were dropped (KVP's busy flag).
            while self.queue[0] is not pending:
                dropped.append(self._finish(self.queue[0]))
            self.dropped_requests += len(dropped)
        self.check(pending.name, pending.frame, reply)
        if self._probe is not None and pending is self._probe[1]:
            if self.ids == "unknown":
                self.ids = "echoed"
                log.debug("%s echoes message ids: matching by id", self.endpoint)
        self.last_label = reply.msg_id
        self._finish(pending)
        return (None if pending.abandoned else pending), dropped

    def _continuation(self, reply: Reply) -> Pending[W]:
        """A reply whose id is not pending: the legacy batch label, or a protocol error."""
        head = self.queue[0] if self.queue else None
        repeats = head is not None and reply.msg_id == self.last_label
        if repeats and self.ids == "unknown" and self._probe is not None and head is self._probe[1]:
            self.ids = "legacy"
            log.warning(
                "%s repeats the first message id of a batch (pre-9.0 KUKAVARPROXY): sending"
                " one request at a time, since pipelined replies cannot be told apart",
                self.endpoint,
            )
        if repeats and self.ids == "legacy":
            assert head is not None
            if not head.abandoned and any(not p.abandoned for p in list(self.queue)[1:]):
                # cannot happen with one request awaited at a time; never guess if it does
                raise ProtocolError(
                    f"reply with id {reply.msg_id} repeats its batch's id, and more than one"
                    " request awaits a reply: it cannot be told whose it is"
                )
            self.mislabeled_replies += 1
            return head
        why = (
            "no request is pending"
            if head is None
            else f"{len(self.queue)} requests are pending, the oldest with id {head.msg_id}"
        )
        hint = ""
        if repeats and self.ids != "legacy":
            hint = (
                " (it repeats the previous reply's id, as a pre-9.0 proxy does;"
                " use id_policy='legacy' for such a proxy)"
            )
        raise ProtocolError(f"reply with id {reply.msg_id} answers no request: {why}{hint}")

    def check(self, name: str, frame: bytes, reply: Reply) -> None:
        """What can be checked of ``reply`` against the request ``frame`` for ``name``: mode,
        a write's echo (legacy proxies), a read's value shape. Raises :class:`ProtocolError`."""
        mode = frame[4]
        value = reply.value
        if mode == reply.mode == Mode.READ:
            if value and reply.status == 1:  # the common case first: a successful read
                shape = value_shape(value)
                known = self._shapes.get(name)
                if known != shape:
                    self._new_shape(name, shape, known, reply.msg_id)
            return
        if reply.mode is None:
            if mode in (Mode.READ, Mode.WRITE):
                raise ProtocolError(
                    f"reply id {reply.msg_id} has no mode, but {name!r} was a mode-{mode} request"
                )
        elif reply.mode != mode:
            raise ProtocolError(
                f"reply id {reply.msg_id} has mode {reply.mode}, but the request for"
                f" {name!r} had mode {mode}"
            )
        if self.ids == "legacy" and mode == Mode.WRITE:
            if value != _write_value(frame) and (reply.ok or value):
                raise ProtocolError(
                    f"reply id {reply.msg_id} does not echo the value written to {name!r}"
                )

    def _new_shape(self, name: str, shape: bytes, known: bytes | None, msg_id: int) -> None:
        if known is not None:
            raise ProtocolError(
                f"reply id {msg_id} for {name!r} reads like {shape.decode('latin-1')!r}, but that"
                f" variable read like {known.decode('latin-1')!r} before: a reply for another"
                " variable"
            )
        if len(name) <= _SHAPE_NAME_MAX:
            if len(self._shapes) >= _SHAPES_MAX:
                del self._shapes[next(iter(self._shapes))]  # the oldest entry
            self._shapes[name] = shape

    def _finish(self, pending: Pending[W]) -> Pending[W]:
        if self.queue and self.queue[0] is pending:
            self.queue.popleft()
        else:  # pragma: no cover - defensive, the queue head is always the match
            self.queue.remove(pending)
        if self.by_id.get(pending.msg_id) is pending:
            del self.by_id[pending.msg_id]
        self.bytes_in_flight -= pending.size
        if self._probe is not None and pending is self._probe[1]:
            self._probe = None  # answered (or dropped): the probe is over either way
        return pending

    def clear(self) -> list[Pending[W]]:
        """Forget every pending request (the connection is gone); returns them, oldest first."""
        pendings = list(self.queue)
        self.queue.clear()
        self.by_id.clear()
        self.bytes_in_flight = 0
        self._probe = None
        return pendings
