"""Frames written as hex in the tests, as the protocol references print them.

``H("00 01 ...")`` is the bytes of a hex dump (blanks ignored), ``W(text)`` the hex of a
UTF-16LE string (C3 Bridge's WSTRING), :func:`payload_of` the value block of a request frame
(where C3 Bridge carries its payload). Shared by the KVP and C3 Bridge codec tests and the C3
emulator's tests.
"""

from __future__ import annotations

from pyopenshowvar.protocol import decode_request

__all__ = ["H", "W", "payload_of"]


def H(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


def W(text: str) -> str:
    """UTF-16LE bytes of ``text`` as hex (the spec's WSTRING)."""
    return text.encode("utf-16-le").hex()


def payload_of(frame: bytes) -> bytes:
    return decode_request(frame).value or b""
