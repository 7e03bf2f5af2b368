"""C3 Bridge Interface: the extended protocol of the C3 Bridge server (ulsu-tech/c3bridge-server).

C3 Bridge replaces KUKAVARPROXY on the controller; it speaks KVP's modes 0/1 and adds UTF-16
reads and writes, read/write of up to 255 variables in one message, KRL program control,
motions, smartPAD keys, proxy information and file transfer (spec: "C3 Bridge Interface
Protocol", version 1 revision 5). This package is the sans-IO codec of those messages, shared
by the client and the emulator, plus the client operations built on it:

* :mod:`~pyopenshowvar.c3.constants` — message types, error codes, sub-commands, flags;
* :mod:`~pyopenshowvar.c3.wire` — field encoding (big-endian integers, UTF-16LE strings);
* :mod:`~pyopenshowvar.c3.messages`, :mod:`~pyopenshowvar.c3.files` — requests (and the file
  replies), :mod:`~pyopenshowvar.c3.replies` — replies and the footer;
* :mod:`~pyopenshowvar.c3.server` — is the server KVP or C3 Bridge, which version and messages;
* :mod:`~pyopenshowvar.c3.ops`, :mod:`~pyopenshowvar.c3.ops_programs`, :mod:`~pyopenshowvar.c3.ops_files` —
  the client operations,
  :mod:`~pyopenshowvar.c3.api` — them as methods of the asyncio and the blocking client.

See docs/c3bridge.md.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .. import lazy

if TYPE_CHECKING:
    from .constants import (
        Command,
        CopyFlag,
        ErrorCode,
        Interpreter,
        ItemAttribute,
        ItemType,
        KcpKey,
        MotionType,
        ProgramCommand,
    )
    from .errors import (
        C3CommandError,
        MotionNotAllowedError,
        RequestTooLargeError,
        UnsupportedError,
    )
    from .files import NameList, Properties
    from .ops_programs import ProgramState
    from .replies import BenchmarkReply, ProxyInfoReply
    from .server import ServerInfo

#: Where each public name lives. They are imported on first use (module ``__getattr__``), so
#: importing the client, which imports :mod:`.api` and so this package, loads no C3 codec.
_SOURCES = {
    **dict.fromkeys(
        (
            "Command",
            "CopyFlag",
            "ErrorCode",
            "Interpreter",
            "ItemAttribute",
            "ItemType",
            "KcpKey",
            "MotionType",
            "ProgramCommand",
        ),
        "constants",
    ),
    **dict.fromkeys(
        ("C3CommandError", "MotionNotAllowedError", "RequestTooLargeError", "UnsupportedError"),
        "errors",
    ),
    "NameList": "files",
    "Properties": "files",
    "ProgramState": "ops_programs",
    "BenchmarkReply": "replies",
    "ProxyInfoReply": "replies",
    "ServerInfo": "server",
}


def __getattr__(name: str) -> Any:
    return lazy.load(__name__, _SOURCES, globals(), name)


def __dir__() -> list[str]:
    return lazy.names(_SOURCES, globals())


__all__ = [
    "BenchmarkReply",
    "C3CommandError",
    "Command",
    "CopyFlag",
    "ErrorCode",
    "Interpreter",
    "ItemAttribute",
    "ItemType",
    "KcpKey",
    "MotionNotAllowedError",
    "MotionType",
    "NameList",
    "ProgramCommand",
    "ProgramState",
    "Properties",
    "ProxyInfoReply",
    "RequestTooLargeError",
    "ServerInfo",
    "UnsupportedError",
]
