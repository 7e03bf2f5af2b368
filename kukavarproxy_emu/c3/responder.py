"""``--proxy c3bridge``: the emulator answers as C3 Bridge 1.4 does, message by message.

:class:`C3Server` is the state one emulator shares between connections (virtual file system,
robot control, internal variables); :meth:`C3Server.session` makes each connection its own
:class:`C3Session`, a :class:`~kukavarproxy_emu.handler.Responder` with the connection's upload
and download buffers. Behaviour follows ``source/client.cpp`` and ``source/handlers/*.cpp``:

* types 0/1 are KVP's reads and writes with C3's failure tail (empty value, ``00 00 00``); a
  KRL variable wins over the internal ``PING`` and ``@PROXY_*`` ones;
* a type with no handler (2, 3, 8, 9, 15, 16, 18, 19, 31..62, 64..255) or a length of 0 closes
  the connection without an answer (the server's ``performDisconnect(ErrorUnknownInput)``);
  :meth:`C3Session.answer` raises :class:`~pyopenshowvar.errors.ProtocolError`, which the
  connection turns into a close after the replies already owed;
* every handled message is answered, a payload that ends early with ErrorProtocol; an answer
  too long for one message is ErrorLongAnswer where the server says so (#6, #7, #21) and
  otherwise closes the connection (the server's ``performDisconnect(ErrorBuildMessage)``).

Each message is answered in one synchronous call, between two interpolation cycles, so a
read-multiple returns values of one cycle.
"""

from __future__ import annotations

import datetime as dt
import time
import weakref
from collections.abc import Callable
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
from pyopenshowvar.protocol import Mode, Reply, Request

from ..handler import Responder
from ..latency import Kind
from .control import RobotControl
from .filemsgs import FileHandlers, IoBuffers
from .vfs import Limits, VirtualFS

if TYPE_CHECKING:
    from ..motion import Robot
    from ..store import VariableStore

__all__ = ["HANDLED", "VERSION", "C3Server", "C3Session"]

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
        if mode in (Mode.READ, Mode.WRITE):
            return super().answer(request, msg_id)
        payload = request.value or b""
        handler = _HANDLERS.get(mode)
        try:
            if handler is not None:
                out, code = handler(self, payload)
            else:
                out, code = self.server.files.handle(mode, payload, self.io)
        except PayloadError as exc:  # handlers parse safely: this is an answer over 65531 bytes
            raise ProtocolError(
                f"the answer to message #{mode} does not fit one message ({exc}): "
                "C3 Bridge disconnects (ErrorBuildMessage)"
            ) from None
        ok = code == ErrorCode.SUCCESS
        return Reply(msg_id, mode, out, 1 if ok else 0, int(code).to_bytes(2, "big"))

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
            value = self._lookup(name)
            items.append((ErrorCode.SUCCESS, value) if value else (ErrorCode.GENERAL, ""))
        return self._multiple(items)

    def write_multiple(self, payload: bytes) -> tuple[bytes, int]:
        try:
            pairs = m.WriteMultiple.parse(Reader(payload)).items
        except PayloadError:
            return bytes(1), ErrorCode.PROTOCOL
        items: list[tuple[int, str]] = []
        for name, value in pairs:
            text = value.encode("latin-1", "replace").decode("latin-1")
            if self.set_var(name, text):
                items.append((ErrorCode.SUCCESS, self.show_var(name) or ""))  # read back
            else:
                items.append((ErrorCode.GENERAL, value))  # the server echoes what was sent
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
        return Echo(command).payload(), self.server.control.program(command, interpreter, name)

    def motion(self, payload: bytes) -> tuple[bytes, int]:
        r = Reader(payload)
        kind = 0
        try:
            kind = r.u8("motion type")
            position = r.wstr("position")
        except PayloadError:
            return Echo(kind).payload(), ErrorCode.PROTOCOL
        return Echo(kind).payload(), self.server.control.motion(kind, position)

    def kcp_action(self, payload: bytes) -> tuple[bytes, int]:
        try:
            msg = m.KcpAction.parse(Reader(payload))
        except PayloadError:
            return Echo(payload[0] if payload else 0).payload(), ErrorCode.PROTOCOL
        code = self.server.control.key(msg.key, msg.target, msg.released)
        return Echo(msg.key).payload(), code

    def proxy_info(self, payload: bytes) -> tuple[bytes, int]:
        major, minor, kind = VERSION
        now = dt.datetime.now(dt.UTC)
        return ProxyInfoReply(major, minor, kind, now, COMPUTER_NAME).payload(), ErrorCode.SUCCESS

    def proxy_features(self, payload: bytes) -> tuple[bytes, int]:
        return self.server.features.payload(), ErrorCode.SUCCESS

    def benchmark(self, payload: bytes) -> tuple[bytes, int]:
        try:
            msg = m.Benchmark.parse(Reader(payload))
        except PayloadError:
            return BenchmarkReply(False, 0, 0, 0, 0, 0).payload(), ErrorCode.PROTOCOL
        names = msg.names[:10]  # the server takes 10 at most
        # bounded work: the reply says how many iterations were really done
        iterations = min(msg.iterations, 0xFFFFFFFE, BENCHMARK_OPS // max(1, len(names)))
        start = self.server.tick_ms()
        t0 = time.perf_counter()
        for _ in range(iterations):
            for i, name in enumerate(names):
                if msg.values is not None:
                    self.set_var(name, msg.values[i])
                else:
                    self.show_var(name)
        elapsed = int((time.perf_counter() - t0) * 1000)
        stop = (start + elapsed) & 0xFFFFFFFF
        reply = BenchmarkReply(msg.values is not None, len(names), iterations, start, stop, elapsed)
        return reply.payload(), ErrorCode.SUCCESS

    def confirm_all(self, payload: bytes) -> tuple[bytes, int]:
        return b"", self.server.control.confirm_all()


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
