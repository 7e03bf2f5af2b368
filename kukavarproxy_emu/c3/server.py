"""``--proxy c3bridge``: the emulator answers as C3 Bridge 1.4 does, message by message.

:class:`C3Server` is the state one emulator shares between connections (virtual file system,
robot control, internal variables); :meth:`C3Server.session` makes each connection its own
:class:`C3Session`, a :class:`~kukavarproxy_emu.responder.Responder` with the connection's upload
and download buffers. Behaviour follows ``source/client.cpp`` and ``source/handlers/*.cpp``:

* every message is a tag, a size, a type and a payload its handler parses field by field
  (:meth:`C3Session.decode`); trailing bytes are ignored, as the server's ``MessageReader``
  ignores them;
* types 0/1 are KVP's reads and writes answered by ``handleRead/WriteVariableAscii``: a value
  as CrossComm shows it (untrimmed, unlike KVP), C3's failure tail (empty value, ``00 00 00``)
  for an unknown name, a refused write and a payload that ends early alike; a KRL variable
  wins over the internal ``PING`` and ``@PROXY_*`` ones;
* a type with no handler (2, 3, 8, 9, 15, 16, 18, 19, 31..62, 64..255) or a length of 0 closes
  the connection without an answer (the server's ``performDisconnect(ErrorUnknownInput)``);
  :meth:`C3Session.answer` raises :class:`~pyopenshowvar.errors.ProtocolError`, which the
  connection turns into a close after the replies already owed;
* every handled message is answered, a payload that ends early with ErrorProtocol and the
  fields the handler had already written (the echoed command, the buffer size of a file
  transfer, the count of a benchmark); an answer too long for one message is ErrorLongAnswer
  where the server says so (#6, #7, #21) and otherwise closes the connection (the server's
  ``performDisconnect(ErrorBuildMessage)``); an error of the emulator itself answers
  ErrorGeneral and is logged, so no message can close another's connection or stop the server.

Each message is answered in one synchronous call, between two interpolation cycles, so a
read-multiple returns values of one cycle. The one exception is a select (and what must wait
for one): its module is parsed in slices, and :meth:`C3Session.answer` raises
:class:`~kukavarproxy_emu.responder.Deferred` so that the connection sends the answer later.
"""

from __future__ import annotations

import datetime as dt
import logging
import time
import weakref
from collections.abc import Awaitable, Callable
from functools import partial
from typing import TYPE_CHECKING

from pyopenshowvar.c3 import messages as m
from pyopenshowvar.c3.constants import C3_TYPE_NAME, Command, ErrorCode, VersionType
from pyopenshowvar.c3.replies import (
    BenchmarkReply,
    Echo,
    FeatureMap,
    Multiple,
    ProxyInfoReply,
    Value,
)
from pyopenshowvar.c3.wire import PayloadError, Reader
from pyopenshowvar.errors import ProtocolError
from pyopenshowvar.protocol import ENCODING, HEADER_SIZE, Mode, Reply, Request

from ..latency import Kind
from ..logsafe import RateLimitedLog
from ..responder import Deferred, Responder
from ..slices import Checkpoint, run_sliced
from .control import RobotControl
from .filemsgs import FileHandlers, IoBuffers
from .vfs import Limits, VirtualFS

if TYPE_CHECKING:
    from ..robot_task import Robot
    from ..store import VariableStore

__all__ = ["HANDLED", "VERSION", "C3Server", "C3Session"]

log = logging.getLogger(__name__)
_limited = RateLimitedLog(log)

#: The version the emulator reports (the open-source server's latest release).
VERSION = (1, 4, VersionType.OPEN_SOURCE)
#: Message types with a handler, as registered by the server (``Client::registerHandlers``).
HANDLED = frozenset({0, 1, 4, 5, 6, 7, 10, 11, 12, 13, 14, 17, *range(20, 31), 63})
COMPUTER_NAME = "KRC4-EMULATOR"
#: Upload buffers of all connections together (each is also at most one file's limit).
UPLOAD_BUDGET = 32 * 1024 * 1024
#: Store operations one #17 benchmark may do (the server itself caps 10 names, not the work).
BENCHMARK_OPS = 10_000
_WRITES = frozenset({1, 5, 7, 10, 11, 12, 20, 22, 23, 24, 25, 63})
_FREE = frozenset({13, 14})  # answered by the server itself, no CrossComm call


class C3Server:
    """What the C3 connections of one emulator share."""

    def __init__(
        self,
        store: VariableStore,
        robot: Robot | None,
        *,
        address: str = "0.0.0.0",
        port: int = 7000,
        limits: Limits | None = None,
    ) -> None:
        self.store = store
        self.vfs = VirtualFS(limits)
        self.control = RobotControl(robot, self.vfs)
        self.address = address
        self.port = port
        self.features = FeatureMap(HANDLED)
        self._started = time.monotonic()
        self._sessions: weakref.WeakSet[C3Session] = weakref.WeakSet()
        self.files = FileHandlers(self.vfs, self.control, self._upload_bytes, UPLOAD_BUDGET)

    def session(self) -> C3Session:
        session = C3Session(self)
        self._sessions.add(session)
        return session

    def _upload_bytes(self) -> int:
        return sum(len(s.io.upload) for s in self._sessions)

    def internal(self, name: str) -> str | None:
        """``PING`` and the ``@PROXY_*`` variables (spec §3.5.1), None for anything else."""
        if name == "PING":
            return "PONG"
        major, minor, kind = VERSION
        values: dict[str, Callable[[], str]] = {
            "@PROXY_TYPE": lambda: C3_TYPE_NAME,
            "@PROXY_VERSION": lambda: f"{major}.{minor} ({kind.name.replace('_', ' ')})",
            "@PROXY_FEATURES": self.features.to_string,
            "@PROXY_HOSTNAME": lambda: COMPUTER_NAME,
            "@PROXY_TIME": lambda: dt.datetime.now(dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
            "@PROXY_ADDRESS": lambda: self.address,
            "@PROXY_PORT": lambda: str(self.port),
            "@PROXY_ENABLED": lambda: "TRUE",
        }
        maker = values.get(name)
        return maker() if maker is not None else None

    def tick_ms(self) -> int:
        """Milliseconds since start, wrapping like ``GetTickCount``."""
        return int((time.monotonic() - self._started) * 1000) & 0xFFFFFFFF


class C3Session(Responder):
    """One connection's responder: C3 Bridge semantics over the shared store."""

    trim = False  # Cross3::getVariable hands ShowVar's text over as it is

    @staticmethod
    def decode(frame: bytes | bytearray | memoryview) -> Request:
        """Tag, type and raw payload of one whole message (``Client::onHeader``/``onCollect``:
        C3 Bridge frames by the size field only; each handler parses its own payload)."""
        msg_id = int.from_bytes(frame[:2], "big")
        if len(frame) <= HEADER_SIZE:
            raise ProtocolError("message with length 0 (no type byte): C3 Bridge disconnects")
        return Request(msg_id, frame[HEADER_SIZE], "", bytes(frame[HEADER_SIZE + 1 :]))

    def __init__(self, server: C3Server) -> None:
        # PING is one of the server's internal variables, asked after KRL (_lookup)
        super().__init__(server.store, strict=True, ping=False)
        self.server = server
        self.io = IoBuffers()

    # ------------------------------------------------------------------ server hooks

    def kind(self, request: Request) -> Kind | None:
        mode = request.mode
        if mode == Command.FILE_WRITE_CONTENT:  # only storing the file calls CrossComm
            return "write" if _io_op(request) == 4 else None
        if mode == Command.FILE_READ_CONTENT:  # only loading the file calls CrossComm
            return "read" if _io_op(request) == 1 else None
        if mode in _FREE:
            return None  # info and features: answered by the server itself
        return "write" if mode in _WRITES else "read"

    def weight(self, request: Request) -> int:
        """CrossComm calls a message costs: one per variable of #6/#7 (it reads them in turn)."""
        if request.mode in (Command.READ_MULTIPLE, Command.WRITE_MULTIPLE) and request.value:
            return max(1, request.value[0])
        return 1

    def answer(self, request: Request, msg_id: int) -> Reply:
        mode = request.mode
        if mode not in HANDLED:
            raise ProtocolError(f"message type {mode} has no handler: C3 Bridge disconnects")
        payload = request.value or b""
        try:
            if mode in (Mode.READ, Mode.WRITE):
                return self._ascii(mode, payload, msg_id)
            handler = _HANDLERS.get(mode)
            if handler is not None:
                out, code = handler(self, payload)
            else:
                out, code = self.server.files.handle(mode, payload, self.io)
        except _Pending as pending:  # a select or a benchmark: answered once its work is done
            raise Deferred(partial(self._later, pending, mode, msg_id)) from None
        except PayloadError as exc:  # handlers parse safely: this is an answer over 65531 bytes
            raise ProtocolError(
                f"the answer to message #{mode} does not fit one message ({exc}): "
                "C3 Bridge disconnects (ErrorBuildMessage)"
            ) from None
        except Exception:  # an emulator bug costs this answer, never the connection
            _limited.warning("C3 message #%d failed; answering ErrorGeneral", mode, exc_info=True)
            out, code = payload[:1] if mode in _ECHOES else b"", ErrorCode.GENERAL
        return _reply(msg_id, mode, out, code)

    async def _later(self, pending: _Pending, mode: int, msg_id: int) -> Reply:
        try:
            out, code = await pending.answer()
        except Exception:  # an emulator bug costs this answer, never the connection
            _limited.warning("C3 message #%d failed; answering ErrorGeneral", mode, exc_info=True)
            out, code = pending.out, ErrorCode.GENERAL
        return _reply(msg_id, mode, out, code)

    def _ascii(self, mode: int, payload: bytes, msg_id: int) -> Reply:
        """#0/#1 as ``handleRead/WriteVariableAscii``: the name (and the value) as u16-prefixed
        ANSI strings; a payload that ends early is answered like any failure, with an empty
        value and ErrorGeneral (the code those two handlers start from)."""
        r = Reader(payload)
        try:
            name = r.raw(r.u16("name length"), "name").decode(ENCODING)
            value = r.raw(r.u16("value length"), "value") if mode == Mode.WRITE else None
        except PayloadError:
            return self._failure(msg_id, mode)
        return super().answer(Request(msg_id, mode, name, value), msg_id)

    def _lookup(self, name: str) -> str | None:
        if name.startswith("@"):  # no KRL name starts with @: the server's own variables
            return self.server.internal(name)
        # A KRL variable of the same name wins (spec §3.5.1). The responder's lookup does not
        # format a whole array no reply can carry (issue 16's bound holds for C3 reads too).
        text = super()._lookup(name)
        return text if text is not None else self.server.internal(name)

    # ------------------------------------------------------------------ #4..#7

    def read_variable(self, payload: bytes) -> tuple[bytes, int]:
        try:
            name = m.ReadVariable.parse(Reader(payload)).name
        except PayloadError:
            return Value("").payload(), ErrorCode.PROTOCOL
        value = self._lookup(name)
        if value is None:
            return Value("").payload(), ErrorCode.GENERAL
        return Value(value).payload(), ErrorCode.SUCCESS

    def write_variable(self, payload: bytes) -> tuple[bytes, int]:
        try:
            msg = m.WriteVariable.parse(Reader(payload))
        except PayloadError:
            return Value("").payload(), ErrorCode.PROTOCOL
        text = msg.value.encode("latin-1", "replace").decode("latin-1")  # KRC text is ANSI
        if not self.set_var(msg.name, text):
            return Value("").payload(), ErrorCode.GENERAL
        return Value(msg.value).payload(), ErrorCode.SUCCESS

    def read_multiple(self, payload: bytes) -> tuple[bytes, int]:
        try:
            names = m.ReadMultiple.parse(Reader(payload)).names
        except PayloadError:
            return bytes(1), ErrorCode.PROTOCOL
        items: list[tuple[int, str]] = []
        for name in names:
            value = self._lookup(name)  # CrossComm's success counts, even for an empty text
            items.append((ErrorCode.GENERAL, "") if value is None else (ErrorCode.SUCCESS, value))
        return self._multiple(items)

    def write_multiple(self, payload: bytes) -> tuple[bytes, int]:
        """Writes item by item as the server parses them: an item cut short answers
        ErrorProtocol (count 0), and the whole items before it stay written."""
        r = Reader(payload)
        items: list[tuple[int, str]] = []
        try:
            for _ in range(r.u8("count")):
                name, value = r.wstr("variable name"), r.wstr("value")
                text = value.encode("latin-1", "replace").decode("latin-1")  # KRC text is ANSI
                if self.set_var(name, text):
                    items.append((ErrorCode.SUCCESS, self.show_var(name) or ""))  # read back
                else:
                    items.append((ErrorCode.GENERAL, value))  # the server echoes what was sent
        except PayloadError:
            return bytes(1), ErrorCode.PROTOCOL
        return self._multiple(items)

    @staticmethod
    def _multiple(items: list[tuple[int, str]]) -> tuple[bytes, int]:
        try:
            out = Multiple(tuple(items)).payload()
        except PayloadError:  # over one message: the server's ErrorLongAnswer, count 0
            return bytes(1), ErrorCode.LONG_ANSWER
        failed = any(code != ErrorCode.SUCCESS for code, _ in items)
        return out, ErrorCode.GENERAL if failed else ErrorCode.SUCCESS

    # ------------------------------------------------------------------ #10..#17, #63

    def program_control(self, payload: bytes) -> tuple[bytes, int]:
        r = Reader(payload)
        command = 0
        try:
            command = r.u8("command")
            interpreter = r.i16("interpreter")
            name = ""
            if command in (5, 6):
                name = r.wstr("name")
                r.wstr("parameters")
                r.boolean("force")
        except PayloadError:
            return Echo(command).payload(), ErrorCode.PROTOCOL
        control = self.server.control
        if command in (5, 6):
            return self._control(command, partial(control.select, name, run=command == 6))
        return self._control(command, partial(control.program, command, interpreter))

    def _control(
        self, echo: int, action: Callable[[], int | Callable[[], Awaitable[int]]]
    ) -> tuple[bytes, int]:
        """The answer of a program, motion or key ``action``: at once, or once a select is
        loaded (the select's own, or one in progress that this action must wait for)."""
        out = Echo(echo).payload()
        control = self.server.control
        if control.selecting:
            raise _Pending(partial(_answer, out, partial(control.after_select, action)), out)
        result = action()
        if isinstance(result, int):
            return out, result
        raise _Pending(partial(_answer, out, result), out)

    def motion(self, payload: bytes) -> tuple[bytes, int]:
        r = Reader(payload)
        kind = 0
        try:
            kind = r.u8("motion type")
            position = r.wstr("position")
        except PayloadError:
            return Echo(kind).payload(), ErrorCode.PROTOCOL
        return self._control(kind, partial(self.server.control.motion, kind, position))

    def kcp_action(self, payload: bytes) -> tuple[bytes, int]:
        try:
            msg = m.KcpAction.parse(Reader(payload))
        except PayloadError:
            return Echo(payload[0] if payload else 0).payload(), ErrorCode.PROTOCOL
        control = self.server.control
        return self._control(msg.key, partial(control.key, msg.key, msg.target, msg.released))

    def proxy_info(self, payload: bytes) -> tuple[bytes, int]:
        major, minor, kind = VERSION
        now = dt.datetime.now(dt.UTC)
        return ProxyInfoReply(major, minor, kind, now, COMPUTER_NAME).payload(), ErrorCode.SUCCESS

    def proxy_features(self, payload: bytes) -> tuple[bytes, int]:
        return self.server.features.payload(), ErrorCode.SUCCESS

    def benchmark(self, payload: bytes) -> tuple[bytes, int]:
        r = Reader(payload)
        write, count, iterations = False, 0, 0
        names: list[str] = []
        values: list[str] = []
        try:
            write = r.boolean("write")
            count = r.u8("count")
            iterations = r.u32("iterations")
            count = min(count, 10)  # the server takes 10 names at most, and parses no more
            for _ in range(count):
                names.append(r.wstr("variable name"))
                if write:
                    values.append(r.wstr("value"))
        except PayloadError:  # the answer keeps what was parsed (count capped at 10)
            cut = BenchmarkReply(write, min(count, 10), min(iterations, 0xFFFFFFFE), 0, 0, 0)
            return cut.payload(), ErrorCode.PROTOCOL
        # bounded work: the reply says how many iterations were really done
        iterations = min(iterations, 0xFFFFFFFE, BENCHMARK_OPS // max(1, count))

        def run(checkpoint: Checkpoint) -> tuple[bytes, int]:
            start = self.server.tick_ms()
            busy = 0.0  # time in store operations; the other clients' turns between slices
            for _ in range(iterations):  # are not the benchmark's
                checkpoint()
                t0 = time.perf_counter()
                for i, name in enumerate(names):
                    if write:
                        self.set_var(name, values[i])
                    else:
                        self.show_var(name)
                busy += time.perf_counter() - t0
            elapsed = int(busy * 1000)
            stop = (start + elapsed) & 0xFFFFFFFF
            reply = BenchmarkReply(write, count, iterations, start, stop, elapsed)
            return reply.payload(), ErrorCode.SUCCESS

        # 10 000 store operations take tens of ms: in slices, between other clients' requests
        raise _Pending(partial(run_sliced, run))

    def confirm_all(self, payload: bytes) -> tuple[bytes, int]:
        return b"", self.server.control.confirm_all()


class _Pending(Exception):
    """A handler's answer that comes later: ``await answer()`` gives (payload, code); should
    that fail, ``out`` is the payload of the ErrorGeneral answer (the echoed command)."""

    def __init__(
        self, answer: Callable[[], Awaitable[tuple[bytes, int]]], out: bytes = b""
    ) -> None:
        super().__init__("answer pending")
        self.answer = answer
        self.out = out


async def _answer(out: bytes, code: Callable[[], Awaitable[int]]) -> tuple[bytes, int]:
    return out, await code()


def _reply(msg_id: int, mode: int, out: bytes, code: int) -> Reply:
    ok = code == ErrorCode.SUCCESS
    return Reply(msg_id, mode, out, 1 if ok else 0, int(code).to_bytes(2, "big"))


#: Messages whose answer is the request's first byte (command, motion or key type, file
#: operation), also when they fail.
_ECHOES = frozenset({10, 11, 12, 29, 30})


def _io_op(request: Request) -> int:
    return request.value[0] if request.value else 0


_HANDLERS: dict[int, Callable[[C3Session, bytes], tuple[bytes, int]]] = {
    4: C3Session.read_variable,
    5: C3Session.write_variable,
    6: C3Session.read_multiple,
    7: C3Session.write_multiple,
    10: C3Session.program_control,
    11: C3Session.motion,
    12: C3Session.kcp_action,
    13: C3Session.proxy_info,
    14: C3Session.proxy_features,
    17: C3Session.benchmark,
    63: C3Session.confirm_all,
}
