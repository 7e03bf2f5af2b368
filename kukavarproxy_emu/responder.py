"""Request → reply logic of the emulator with KUKAVARPROXY 9.0 semantics, no I/O.

:class:`Responder` answers one decoded request from the variable store exactly as KVP 9.0 does
(reference §2.4, §4.1): unknown reads give an empty value with success status, refused writes
echo the value with a failure status, ``PING`` answers ``PONG``, modes 2/3 pack 16-bit words.
``strict`` switches the failures to C3 Bridge's ``00 00 00`` tail. Kept apart from the sockets
so it can be tested and reused (the KRL interpreter's tests drive it directly).

Every value read goes through :func:`extract_variable_value`, KVP's ``ExtractVariableValue``
(basMain.bas): the store prints what the KRC's CrossComm ``ShowVar`` prints (a whole array
``NAME[]`` with a trailing space), and KVP trims the spaces off before they reach the wire.
:meth:`Responder.show_var` and :meth:`Responder.set_var` are the two CrossComm calls on their
own, for the wire-faithful ``kvp9`` connection (:mod:`kukavarproxy_emu.kvp9`).

Names and values come from the network: they reach the log only escaped and clipped
(:func:`~kukavarproxy_emu.logsafe.clip`), through a rate limiter, so no client can forge a log
line or flood the log.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Awaitable, Callable

import numpy as np

from pyopenshowvar.protocol import ENCODING, Mode, Reply, Request, decode_request

from .config import EmulatorConfig
from .latency import Kind
from .logsafe import RateLimitedLog, clip
from .store import UnknownVariable, VariableStore, WriteRefused

__all__ = ["Deferred", "Responder", "build_store", "extract_variable_value"]

log = logging.getLogger(__name__)
#: Every line here can be provoked by any client at will: escaped (clip) and rate-limited.
_limited = RateLimitedLog(log)

_U16 = struct.Struct(">H")
#: A reply's value must leave room for the 6 other content bytes under the 16-bit length.
_MAX_VALUE = 0xFFFF - 6
#: Stands for a value too long for any reply (the store did not even format it): a failure.
_TOO_LONG = "\x00" * (_MAX_VALUE + 1)
#: C3 Bridge's failure tail is error code 0 + flag 0; KVP's is the block length 1 + flag 0.
_STRICT_CODE = b"\x00\x00"


class Deferred(Exception):
    """Raised by a responder's ``answer`` when the answer needs work spread over several
    event-loop iterations (a C3 select parses its module in slices): the connection awaits
    ``reply()`` and sends its result, and answers nothing after it meanwhile (in order)."""

    def __init__(self, reply: Callable[[], Awaitable[Reply]]) -> None:
        super().__init__("answer deferred")
        self.reply = reply


def _to_word(token: str) -> int:
    """VB's ``CLng`` then the proxy's ``longToWord``: round half to even, keep 16 bits."""
    try:
        value = int(token)
    except ValueError:
        value = round(float(token))  # ValueError / OverflowError for non-numbers
    return value & 0xFFFF


def extract_variable_value(name: str, shown: str) -> str:
    """KVP's ``ExtractVariableValue(name & "=" & shown)``: the text after the first ``=``, trimmed.

    VB's ``Trim`` removes spaces only (not tabs or newlines). The first ``=`` may sit inside
    ``name`` when the name is an expression; the store answers those as unknown, but the rule is
    kept whole so that the two can never disagree.
    """
    if "=" not in name:  # the usual case: the first "=" is the one ShowVar put there
        return shown.strip(" ")
    full = f"{name}={shown}"
    return full[full.index("=") + 1 :].strip(" ")


def _pack_words(tokens: list[str]) -> bytes | None:
    """``_to_word`` of every token, packed big-endian; None where VB would raise.

    Converted in C (``int`` / numpy) so that a 32 764-token array costs about a millisecond;
    the element-by-element path remains for what the fast paths cannot decide exactly.
    """
    try:
        ints = list(map(int, tokens))  # INT arrays: exact, any size
    except ValueError:
        try:
            reals = np.array(tokens, dtype=np.float64)
        except ValueError:
            return None  # not a number (a struct's text, TRUE/FALSE): VB's type mismatch
        if not np.all(np.abs(reals) < 2.0**52):  # NaN, infinities, or beyond exact rounding
            try:
                ints = [_to_word(t) for t in tokens]
            except (ValueError, OverflowError):
                return None
        else:  # np.rint rounds half to even, as CLng does
            return (np.rint(reals).astype(np.int64) & 0xFFFF).astype(">u2").tobytes()
    return struct.pack(f">{len(ints)}H", *[v & 0xFFFF for v in ints])


def build_store(config: EmulatorConfig) -> VariableStore:
    """The default KRC4 variables (of ``config.arm``) plus the globals of
    ``config.config_files`` and ``dat_text``."""
    overrides = None
    if config.arm:
        from .robots import resolve_robot  # numpy: only for another arm than the KR 6

        overrides = resolve_robot(config.arm).sysvar_overrides()
    store = VariableStore(overrides=overrides)
    for path in config.config_files:
        store.load_dat(path.read_text(encoding="latin-1"))
    if config.dat_text:
        store.load_dat(config.dat_text)
    return store


class Responder:
    """Answers one request the way KUKAVARPROXY 9.0 does (``strict``: C3 Bridge failures)."""

    #: KVP trims what CrossComm shows (``ExtractVariableValue``); C3 Bridge passes it as is.
    trim = True
    #: How a connection turns a whole request frame into a :class:`Request` (KVP's blocks,
    #: checked; a frame whose blocks do not add up raises ProtocolError and closes it).
    decode = staticmethod(decode_request)

    def __init__(self, store: VariableStore, *, strict: bool = False, ping: bool = True) -> None:
        self.store = store
        self.strict = strict
        self.ping = ping

    def kind(self, request: Request) -> Kind | None:
        """What the request costs the controller: None for PING and unknown modes (no CrossComm)."""
        if request.mode in (Mode.READ, Mode.READ_ARRAY):
            return None if self.ping and request.name == "PING" else "read"
        if request.mode in (Mode.WRITE, Mode.WRITE_ARRAY):
            return "write"
        return None

    def weight(self, request: Request) -> int:
        """Service times one request costs (one CrossComm call per KVP request)."""
        return 1

    def answer(self, request: Request, msg_id: int) -> Reply:
        mode = request.mode
        if mode == Mode.READ:
            text = self._lookup(request.name)
            if text is None:
                # KVP 9.0 reports an unknown variable as an empty value with *success* status.
                return self._failure(msg_id, mode) if self.strict else Reply(msg_id, mode, b"")
            return self._reply(msg_id, mode, text.encode(ENCODING, errors="replace"))
        if mode == Mode.WRITE:
            value = request.value or b""
            if self._write(request.name, value.decode(ENCODING)):
                return self._reply(msg_id, mode, value)  # an echo, not a read-back
            return self._failure(msg_id, mode, value)
        if mode == Mode.READ_ARRAY:
            return self._read_array(request.name, msg_id)
        if mode == Mode.WRITE_ARRAY:
            return self._write_array(request, msg_id)
        return Reply(msg_id, None, b"", 0, b"")  # KVP: bare "id 00 00" for an unknown mode

    def _reply(self, msg_id: int, mode: int, value: bytes) -> Reply:
        if len(value) > _MAX_VALUE:
            _limited.warning(
                "value of %d bytes does not fit a reply; answering failure", len(value)
            )
            return self._failure(msg_id, mode)
        return Reply(msg_id, mode, value)

    def _failure(self, msg_id: int, mode: int, value: bytes = b"") -> Reply:
        if self.strict:
            return Reply(msg_id, mode, b"", 0, _STRICT_CODE)
        return Reply(msg_id, mode, value if len(value) <= _MAX_VALUE else b"", 0)

    def show_var(self, name: str) -> str | None:
        """basMain ``ShowVar``: the trimmed value (untrimmed without :attr:`trim`), or None
        where CrossComm raises (unknown)."""
        try:
            text = self.store.read(name)
            return extract_variable_value(name, text) if self.trim else text
        except UnknownVariable:
            return None
        except Exception:  # a store bug must cost one reply, not the connection
            _limited.warning("store.read(%s) failed", clip(name), exc_info=True)
            return None

    def set_var(self, name: str, text: str) -> bool:
        """basMain ``SetVar``: True when the write was applied."""
        return self._write(name, text)

    def _lookup(self, name: str) -> str | None:
        if self.ping and name == "PING":  # exact and case-sensitive, as in KVP 9.0
            return "PONG"
        if self.store.too_long_for_reply(name):
            return _TOO_LONG  # a failure, without formatting a text no reply can carry
        return self.show_var(name)

    def _write(self, name: str, text: str) -> bool:
        try:
            self.store.write(name, text)
        except (WriteRefused, UnknownVariable) as exc:
            if log.isEnabledFor(logging.DEBUG):
                _limited.debug("write %s=%s refused: %s", clip(name), clip(text), clip(str(exc)))
            return False
        except Exception:
            _limited.warning("store.write(%s, %s) failed", clip(name), clip(text), exc_info=True)
            return False
        return True

    def _read_array(self, name: str, msg_id: int) -> Reply:
        text = self._lookup(name)
        if text is None:
            if self.strict:
                return self._failure(msg_id, Mode.READ_ARRAY)
            text = ""
        if text is _TOO_LONG:
            return self._failure(msg_id, Mode.READ_ARRAY)
        tokens = text.split()
        if len(tokens) < 2:  # KVP's `If UBound(...) > 0` skips one-token values
            return Reply(msg_id, Mode.READ_ARRAY, b"")
        if len(tokens) > _MAX_VALUE // 2:
            return self._failure(msg_id, Mode.READ_ARRAY)  # the words would not fit a reply
        words = _pack_words(tokens)
        if words is None:
            # KVP raises a VB error here and sends nothing; a failure reply is kinder.
            return self._failure(msg_id, Mode.READ_ARRAY)
        return self._reply(msg_id, Mode.READ_ARRAY, words)

    def _write_array(self, request: Request, msg_id: int) -> Reply:
        payload = request.value or b""
        if not payload or len(payload) % 2:
            return self._failure(msg_id, Mode.WRITE_ARRAY)
        words = struct.unpack(f">{len(payload) // 2}H", payload)
        try:
            # KVP writes NAME[1..k] one by one; only the last element's status survives.
            ok = self.store.write_words(request.name.removesuffix("[]"), words)
        except Exception:  # a store bug must cost one reply, not the connection
            _limited.warning("store.write_words(%s) failed", clip(request.name), exc_info=True)
            ok = False
        if ok:
            return Reply(msg_id, Mode.WRITE_ARRAY, b"")
        return self._failure(msg_id, Mode.WRITE_ARRAY)
