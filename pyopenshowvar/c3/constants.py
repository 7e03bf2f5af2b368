"""The numbers of the C3 Bridge Interface protocol: message types, error codes, sub-commands.

Everything here is the spec's own numbering (C3 Bridge Interface Protocol, version 1 revision 5,
§3.3, §3.4, §3.6–§3.10) cross-checked with the server's ``include/c3bi.h``; names follow the
spec with Python spelling. No I/O, no logic beyond descriptions.
"""

from __future__ import annotations

from enum import IntEnum, IntFlag

__all__ = [
    "C3_TYPE_NAME",
    "Command",
    "CopyFlag",
    "EditMode",
    "ErrorCode",
    "FileIo",
    "Interpreter",
    "ItemAttribute",
    "ItemType",
    "KcpKey",
    "ListFlag",
    "ModulePart",
    "MotionType",
    "ProgramCommand",
    "PropertyFlag",
    "VersionType",
]

#: What ``@PROXY_TYPE`` reads on a C3 Bridge server (spec §2.2).
C3_TYPE_NAME = "C3 BRIDGE INTERFACE"


class Command(IntEnum):
    """Message types of the primary protocol (spec §3.4; 0..3 are KUKAVARPROXY's modes)."""

    READ_VARIABLE_ASCII = 0
    WRITE_VARIABLE_ASCII = 1
    READ_ARRAY_ASCII = 2
    WRITE_ARRAY_ASCII = 3
    READ_VARIABLE = 4
    WRITE_VARIABLE = 5
    READ_MULTIPLE = 6
    WRITE_MULTIPLE = 7
    PROGRAM_CONTROL = 10
    MOTION = 11
    KCP_ACTION = 12
    PROXY_INFO = 13
    PROXY_FEATURES = 14
    PROXY_INFO_EX = 15
    PROXY_CROSS_INFO = 16
    PROXY_BENCHMARK = 17
    FILE_SET_ATTRIBUTE = 20
    FILE_NAME_LIST = 21
    FILE_CREATE = 22
    FILE_DELETE = 23
    FILE_COPY = 24
    FILE_MOVE = 25
    FILE_GET_PROPERTIES = 26
    FILE_GET_FULL_NAME = 27
    FILE_GET_KRC_NAME = 28
    FILE_WRITE_CONTENT = 29
    FILE_READ_CONTENT = 30
    CROSS_CONFIRM_ALL = 63
    EXTENDED = 255


class ErrorCode(IntEnum):
    """The footer's error code (spec §3.3). ``SUCCESS`` is 1, not 0."""

    GENERAL = 0
    SUCCESS = 1
    ACCESS = 2
    ARGUMENT = 3
    MEMORY = 4
    POINTER = 5
    UNEXPECTED = 6
    NOT_IMPLEMENTED = 7
    NO_INTERFACE = 8
    PROTOCOL = 9
    LONG_ANSWER = 10

    @property
    def describe(self) -> str:
        return _ERROR_TEXT[self]


_ERROR_TEXT = {
    ErrorCode.GENERAL: "unspecified failure (E_FAIL)",
    ErrorCode.SUCCESS: "success",
    ErrorCode.ACCESS: "access denied",
    ErrorCode.ARGUMENT: "invalid argument",
    ErrorCode.MEMORY: "out of memory",
    ErrorCode.POINTER: "null pointer",
    ErrorCode.UNEXPECTED: "unexpected failure",
    ErrorCode.NOT_IMPLEMENTED: "not implemented",
    ErrorCode.NO_INTERFACE: "no such interface (the Cross 3 service is not available)",
    ErrorCode.PROTOCOL: "malformed message content",
    ErrorCode.LONG_ANSWER: "the answer does not fit into one message",
}


class VersionType(IntEnum):
    """The build type of a C3 Bridge version (spec §1.1)."""

    OPEN_SOURCE = 0
    PROPRIETARY = 1
    FREEWARE = 2
    INTERNAL_BUILD = 3


class ProgramCommand(IntEnum):
    """Message #10 command codes (spec §3.6; 1..4 subtype I, 5..6 subtype II)."""

    RESET = 1
    START = 2
    STOP = 3
    CANCEL = 4
    SELECT = 5
    RUN = 6


class Interpreter(IntEnum):
    """Interpreter type of message #10 subtype I (INT16) and #12 (INT32)."""

    SUBMIT = 0
    ROBOT = 1


class MotionType(IntEnum):
    """Message #11 motion types (spec §3.7.1)."""

    PTP = 1
    LIN = 2
    PTP_REL = 3
    LIN_REL = 4


class KcpKey(IntEnum):
    """Message #12 key types (spec §3.7.2)."""

    START = 1
    STOP = 2
    JOG = 3
    MOUSE_6D = 4


class FileIo(IntEnum):
    """Sub-operations of messages #29/#30 (spec §3.9.1.8)."""

    NONE = 0
    BEGIN = 1
    DATA = 2
    GET_SIZE = 3
    END = 4
    CHECKSUM = 5


class ItemAttribute(IntFlag):
    """File attributes (spec §3.9.1.1)."""

    NONE = 0
    READ_ONLY = 1
    HIDDEN = 2
    SYSTEM = 4
    DIRECTORY = 16
    ARCHIVE = 32
    ENCRYPTED = 16384
    SIGNED = 268435456


class ItemType(IntFlag):
    """Item types of listings and properties (spec §3.9.1.2)."""

    UNKNOWN = 0
    DIRECTORY = 1
    VIRTUAL_DIRECTORY = 2
    ARCHIVE = 4
    BINARY_FILE = 8
    TEXT_FILE = 16
    MODULE = 32
    RAW = 64
    MOTION_FILE = 128
    PROTECTED_CONTAINER = 256


class ListFlag(IntFlag):
    """Directory listing flags (spec §3.9.1.3)."""

    NONE = 0
    RECURSIVE = 1
    EXPAND = 2
    LONG = 4
    OLD_LONG = 8
    NO_PFC = 16
    PFC_AS_FILE = 32
    ZIP_AS_FILE = 64


class ModulePart(IntEnum):
    """Module parts for message #22 (spec §3.9.1.4)."""

    UNKNOWN = 0
    SUB = 1
    SRC = 2
    DAT = 4
    SUBDAT = 5
    SRCDAT = 6
    TEMPLATE = 8
    MOTION = 16


class CopyFlag(IntFlag):
    """Copy flags of messages #24, #25, #29 and #30 (spec §3.9.1.5)."""

    NONE = 0
    ARCHIVE = 1
    MODIFY = 3
    CONTINUE = 4
    RECURSIVE = 8
    REFRESH = 16
    UPDATE = 48
    OVERWRITE = 64
    NO_DIRECTORY_ENTRIES = 128
    JUNK_DIRECTORY = 256
    FORCE_BINARY = 512
    FORCE_TEXT = 1024
    NO_VERSION_CHECK = 2048
    OVERWRITE_READ_ONLY = 4096
    NO_KRL_ANALYSIS = 8192


class PropertyFlag(IntFlag):
    """Which properties message #26 asks for (spec §3.9.1.6; ALL = 255 since revision 5)."""

    NONE = 0
    TYPE = 1
    NAME = 2
    SIZE = 4
    ATTRIBUTES = 8
    CREATION_TIME = 16
    ACCESS_TIME = 32
    MODIFIED_TIME = 64
    EDIT_MODE = 128
    ALL = 255


class EditMode(IntEnum):
    """Edit modes of message #26 (spec §3.9.1.7)."""

    UNKNOWN = -1
    FULL_EDIT = 0
    DAT_KOR = 1
    PRO_KOR = 2
    READ_ONLY = 3
