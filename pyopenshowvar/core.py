"""What the asyncio and the blocking client share, without doing any I/O.

* :class:`ClientCore` — the constructor arguments, the endpoint, the access statistics, and the
  interpretation of replies (unknown variable, failure status, write refused, typed parsing,
  the per-name results of ``read_many``), so both clients raise exactly the same exceptions
  with the same messages.
* Operations: robot helpers (:mod:`pyopenshowvar.robot`) are written once as generators that
  yield the calls they need (``("read", args, kwargs)``, ``("sleep", (seconds,), {})``) and
  receive the results; :func:`as_async_method` and :func:`as_sync_method` turn one into a
  method of either client, keeping its signature and docstring. :class:`LazyOps` and
  :class:`LazyMethod` do the same for a module of operations imported on first use only.
"""

from __future__ import annotations

import importlib
import threading
import time
from collections.abc import Callable, Coroutine, Generator, Iterable, Sequence
from dataclasses import dataclass
from types import MethodType
from typing import Any, Concatenate, ParamSpec, TypeVar

from .errors import (
    KrlValueError,
    KvpConnectionError,
    KvpError,
    KvpStalledError,
    ReadFailedError,
    UnknownVariableError,
    WriteRefusedError,
)
from .krl import KrlValue, format_value, parse_value
from .protocol import Reply, encode_read
from .session import IdPolicy, check_id_policy
from .stats import AccessStats

__all__ = [
    "ClientCore",
    "LazyMethod",
    "LazyOps",
    "Op",
    "ReadResult",
    "as_async_method",
    "as_sync_method",
    "lazy_async_method",
    "lazy_sync_method",
]

P = ParamSpec("P")
T = TypeVar("T")

_READ_FRAMES_MAX = 256
#: The two bytes before the status byte of a C3 Bridge failure: error code 0, ErrorGeneral.
#: KUKAVARPROXY's failure tail is the status block ``00 01``, so the two never meet.
C3_GENERAL_FAILURE = b"\x00\x00"

#: A call an operation asks its client to make: (method name, positional args, keyword args).
Call = tuple[str, tuple[Any, ...], dict[str, Any]]
#: An operation: yields calls, receives their results (or their exceptions), returns a value.
Op = Generator[Call, Any, T]


@dataclass(frozen=True, slots=True)
class ReadResult:
    """The outcome for one name of ``read_many``: a value or the error."""

    name: str
    text: str | None = None
    value: Any = None
    error: KvpError | None = None

    @property
    def ok(self) -> bool:
        return self.error is None

    def unwrap(self) -> Any:
        """The typed value if parsed, else the text; raises the stored error."""
        if self.error is not None:
            raise self.error
        return self.value if self.value is not None else self.text


class ClientCore:
    """Configuration and reply interpretation common to both clients (no I/O here)."""

    _torque_whole_array: bool | None = None

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 7000,
        *,
        timeout: float = 2.0,
        connect_timeout: float | None = None,
        auto_reconnect: bool = False,
        keepalive: float | None = 10.0,
        max_in_flight: int = 64,
        pipeline_bytes: int = 2048,
        id_policy: IdPolicy = "auto",
    ) -> None:
        check_id_policy(id_policy)  # at construction, not at the first connect
        if not timeout > 0:
            raise ValueError(f"timeout must be positive, not {timeout!r}")
        self.host = host
        self.port = port
        self.timeout = timeout
        self.connect_timeout = connect_timeout if connect_timeout is not None else max(timeout, 1.0)
        self.auto_reconnect = auto_reconnect
        self._conn_kw: dict[str, Any] = {
            "timeout": timeout,
            "keepalive": keepalive,
            "max_in_flight": max_in_flight,
            "pipeline_bytes": pipeline_bytes,
            "id_policy": id_policy,
        }
        self._stats = AccessStats()
        self._sync_lock = threading.Lock()  # the blocking client's connect() (threads)
        #: read requests by name (id 0): a control loop reads the same few names again and again
        self._read_frames: dict[str, bytes] = {}
        #: how many times a lost or stalled connection was replaced
        self.reconnects = 0

    @property
    def endpoint(self) -> str:
        return f"{self.host}:{self.port}"

    @property
    def stats(self) -> AccessStats:
        """Access times of every request made through this client (across reconnects)."""
        return self._stats

    def _closed_error(self, reason: str | None) -> KvpConnectionError:
        why = f": {reason}" if reason else ""
        return KvpConnectionError(
            f"connection to {self.endpoint} is closed{why} (auto_reconnect is off)"
        )

    def _may_retry(self, exc: KvpStalledError) -> None:
        """Re-raise ``exc`` unless the call may be retried on a new connection."""
        if self.auto_reconnect and exc.sent_nothing:
            return
        if not self.auto_reconnect:
            raise KvpStalledError(
                f"{exc} (auto_reconnect is off: call connect() to open a new connection)"
            ) from None
        raise KvpStalledError(f"{exc}; the next call reconnects") from None

    def _read_frame(self, name: str) -> bytes:
        frame = encode_read(0, name)
        if len(self._read_frames) < _READ_FRAMES_MAX:
            self._read_frames[name] = frame
        return frame

    # ------------------------------------------------------------------ replies

    def _check_read(self, name: str, reply: Reply) -> str:
        if not reply.ok:
            if reply.mode is None:
                raise ReadFailedError(
                    "proxy does not support this request mode", name=name, endpoint=self.endpoint
                )
            if reply.code == C3_GENERAL_FAILURE:
                # C3 Bridge's answer for a name CrossComm cannot show (KVP's is an empty
                # success); the same outcome as read_multiple's per-name ErrorGeneral
                raise UnknownVariableError(
                    "unknown or unreadable variable", name=name, endpoint=self.endpoint
                )
            raise ReadFailedError("read failed", name=name, endpoint=self.endpoint)
        if not reply.value:
            raise UnknownVariableError(
                "unknown or unreadable variable", name=name, endpoint=self.endpoint
            )
        return reply.text

    def _parse(self, name: str, text: str, type_name: str | None) -> KrlValue:
        try:
            return parse_value(text, type_name)
        except KrlValueError as exc:
            raise KrlValueError(f"{name!r} on {self.endpoint}: {exc}") from exc

    @staticmethod
    def _text(value: KrlValue | str) -> str:
        return value if isinstance(value, str) else format_value(value)

    def _check_write(self, name: str, text: str, reply: Reply) -> str:
        if not reply.ok:
            raise WriteRefusedError(
                "write refused (read-only, unknown variable or wrong type)",
                name=name,
                endpoint=self.endpoint,
                value=text,
            )
        return reply.text

    def _read_results(
        self, names: Sequence[str], replies: Sequence[Reply | KvpError], typed: bool
    ) -> dict[str, ReadResult]:
        out: dict[str, ReadResult] = {}
        for name, reply in zip(names, replies, strict=True):
            if isinstance(reply, KvpError):
                out[name] = ReadResult(name, error=reply)
                continue
            try:
                text = self._check_read(name, reply)
                value = self._parse(name, text, None) if typed else None
            except KvpError as exc:
                out[name] = ReadResult(name, text=reply.text or None, error=exc)
                continue
            out[name] = ReadResult(name, text=text, value=value)
        return out

    def _check_writes(
        self, texts: Iterable[tuple[str, str]], replies: Sequence[Reply | KvpError]
    ) -> None:
        for (name, text), reply in zip(texts, replies, strict=True):
            if isinstance(reply, KvpError):
                raise reply
            self._check_write(name, text, reply)

    def _check_array_read(self, name: str, reply: Reply) -> list[int]:
        if not reply.ok:
            what = (
                "proxy does not support array mode 2" if reply.mode is None else "array read failed"
            )
            raise ReadFailedError(what, name=name, endpoint=self.endpoint)
        return reply.words()

    def _check_array_write(self, name: str, reply: Reply) -> None:
        if not reply.ok:
            raise WriteRefusedError("array write refused", name=name, endpoint=self.endpoint)

    def _proxy_type(self, text_or_error: str | KvpError) -> str | None:
        if isinstance(text_or_error, UnknownVariableError | ReadFailedError):
            return None
        if isinstance(text_or_error, KvpError):
            raise text_or_error
        return text_or_error


# --------------------------------------------------------------------------- operations


def _advance(gen: Op[T], result: Any, error: BaseException | None) -> tuple[bool, Any]:
    """Resume ``gen`` with a result or an exception: (done, next call or return value)."""
    try:
        return False, (gen.send(result) if error is None else gen.throw(error))
    except StopIteration as stop:
        return True, stop.value


def as_async_method(
    op: Callable[Concatenate[Any, P], Op[T]],
) -> Callable[Concatenate[Any, P], Coroutine[Any, Any, T]]:
    """A coroutine method of the asyncio client that runs ``op``."""

    async def method(self: Any, /, *args: P.args, **kwargs: P.kwargs) -> T:
        import asyncio  # here, not at module level: the blocking client never loads asyncio

        gen = op(self, *args, **kwargs)
        done, item = _advance(gen, None, None)
        while not done:
            name, a, kw = item
            result, error = None, None
            try:
                call = asyncio.sleep(*a) if name == "sleep" else getattr(self, name)(*a, **kw)
                result = await call
            except Exception as exc:
                error = exc
            done, item = _advance(gen, result, error)
        return item  # type: ignore[no-any-return]

    _copy_identity(method, op)
    return method


def as_sync_method(
    op: Callable[Concatenate[Any, P], Op[T]],
) -> Callable[Concatenate[Any, P], T]:
    """A blocking method of the synchronous client that runs ``op``."""

    def method(self: Any, /, *args: P.args, **kwargs: P.kwargs) -> T:
        gen = op(self, *args, **kwargs)
        done, item = _advance(gen, None, None)
        while not done:
            name, a, kw = item
            result, error = None, None
            try:
                if name == "sleep":
                    time.sleep(*a)
                else:
                    result = getattr(self, name)(*a, **kw)
            except Exception as exc:
                error = exc
            done, item = _advance(gen, result, error)
        return item  # type: ignore[no-any-return]

    _copy_identity(method, op)
    return method


def _copy_identity(method: Callable[..., Any], op: Callable[..., Any]) -> None:
    method.__name__ = op.__name__
    method.__qualname__ = op.__qualname__
    method.__doc__ = op.__doc__
    method.__module__ = op.__module__


class LazyOps:
    """Stands for a module of operations that is imported when one of them is first used.

    ``LazyOps("pyopenshowvar.c3.ops").read_multiple`` names the operation without importing
    anything; :class:`LazyMethod` imports it when the method is first looked up. The clients
    have dozens of C3 Bridge methods whose codec most programs (``kvp read``) never touch.
    """

    def __init__(self, module: str) -> None:
        self._module = module

    def __getattr__(self, name: str) -> tuple[str, str]:
        if name.startswith("__"):  # copy, pickle and friends probe dunders
            raise AttributeError(name)
        return self._module, name


class LazyMethod:
    """A client method made by ``wrap`` (:func:`as_async_method`...) from a lazy operation.

    The first lookup, on the class or an instance, imports the operation's module and puts the
    real method on the class in place of this placeholder, so later calls cost nothing extra
    and ``help()``, ``inspect.signature`` and docstrings see the method itself.
    """

    def __init__(
        self, op: tuple[str, str], wrap: Callable[[Callable[..., Op[Any]]], Callable[..., Any]]
    ) -> None:
        self._module, self._op = op
        self._wrap = wrap
        self._owner: type | None = None
        self._name = self._op

    def __set_name__(self, owner: type, name: str) -> None:
        self._owner, self._name = owner, name

    def __get__(self, obj: object, objtype: type | None = None) -> Any:
        method = self._wrap(getattr(importlib.import_module(self._module), self._op))
        if self._owner is not None:
            setattr(self._owner, self._name, method)
        return method if obj is None else MethodType(method, obj)


def lazy_async_method(op: tuple[str, str]) -> LazyMethod:
    """:func:`as_async_method` of a :class:`LazyOps` operation, made on first use."""
    return LazyMethod(op, as_async_method)


def lazy_sync_method(op: tuple[str, str]) -> LazyMethod:
    """:func:`as_sync_method` of a :class:`LazyOps` operation, made on first use."""
    return LazyMethod(op, as_sync_method)
