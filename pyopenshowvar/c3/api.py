"""The C3 Bridge methods of the clients: :class:`C3Methods` (asyncio) and :class:`SyncC3Methods`.

Both are made from the same operations (:mod:`pyopenshowvar.c3.ops`,
:mod:`pyopenshowvar.c3.ops_programs`) by :func:`~pyopenshowvar.core.as_async_method` and
:func:`~pyopenshowvar.core.as_sync_method`, so :class:`pyopenshowvar.Client` and
:class:`pyopenshowvar.sync.Client` take the same arguments, refuse the same requests before
sending, and raise the same errors. The operations use the client's ``_request(label, frame,
timeout)`` (one whole frame out, its reply back) and ``read_many``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..core import LazyOps, as_async_method, as_sync_method, lazy_async_method, lazy_sync_method

if TYPE_CHECKING:
    from . import ops, ops_files, ops_programs
    from .server import ServerInfo

    _async, _sync = as_async_method, as_sync_method
else:
    # The C3 codec (messages, replies, files: some 60 dataclasses) is imported when a C3
    # method is first used, not with the client: ``kvp read`` never needs it. mypy checks the
    # methods as written below with the real operations (the branch above).
    ops, ops_programs = LazyOps(f"{__package__}.ops"), LazyOps(f"{__package__}.ops_programs")
    ops_files = LazyOps(f"{__package__}.ops_files")
    _async, _sync = lazy_async_method, lazy_sync_method

__all__ = ["C3Methods", "SyncC3Methods"]


class _C3State:
    #: What :meth:`server_info` found (cached per client; ``refresh=True`` asks again).
    _c3_info: ServerInfo | None = None
    #: Largest file chunk sent in one #29 message (C3 Bridge reassembles large frames).
    _c3_chunk: int = 32 * 1024


class C3Methods(_C3State):
    """C3 Bridge methods of the asyncio :class:`~pyopenshowvar.Client` (see docs/c3bridge.md)."""

    server_info = _async(ops.server_info)
    read_utf16 = _async(ops.read_utf16)
    write_utf16 = _async(ops.write_utf16)
    read_multiple = _async(ops.read_multiple)
    write_multiple = _async(ops.write_multiple)
    motion = _async(ops.motion)
    kcp_key = _async(ops.kcp_key)
    confirm_all = _async(ops.confirm_all)
    proxy_info = _async(ops.proxy_info)
    proxy_features = _async(ops.proxy_features)
    benchmark = _async(ops.benchmark)
    program_select = _async(ops_programs.program_select)
    program_run = _async(ops_programs.program_run)
    program_start = _async(ops_programs.program_start)
    program_stop = _async(ops_programs.program_stop)
    program_reset = _async(ops_programs.program_reset)
    program_cancel = _async(ops_programs.program_cancel)
    program_state = _async(ops_programs.program_state)
    program_upload = _async(ops_programs.program_upload)
    file_list = _async(ops_files.file_list)
    file_properties = _async(ops_files.file_properties)
    file_full_name = _async(ops_files.file_full_name)
    file_krc_name = _async(ops_files.file_krc_name)
    file_read = _async(ops_files.file_read)
    file_write = _async(ops_files.file_write)
    file_delete = _async(ops_files.file_delete)
    file_create = _async(ops_files.file_create)
    file_copy = _async(ops_files.file_copy)
    file_move = _async(ops_files.file_move)
    file_set_attribute = _async(ops_files.file_set_attribute)


class SyncC3Methods(_C3State):
    """The same methods, blocking, for :class:`pyopenshowvar.sync.Client`."""

    server_info = _sync(ops.server_info)
    read_utf16 = _sync(ops.read_utf16)
    write_utf16 = _sync(ops.write_utf16)
    read_multiple = _sync(ops.read_multiple)
    write_multiple = _sync(ops.write_multiple)
    motion = _sync(ops.motion)
    kcp_key = _sync(ops.kcp_key)
    confirm_all = _sync(ops.confirm_all)
    proxy_info = _sync(ops.proxy_info)
    proxy_features = _sync(ops.proxy_features)
    benchmark = _sync(ops.benchmark)
    program_select = _sync(ops_programs.program_select)
    program_run = _sync(ops_programs.program_run)
    program_start = _sync(ops_programs.program_start)
    program_stop = _sync(ops_programs.program_stop)
    program_reset = _sync(ops_programs.program_reset)
    program_cancel = _sync(ops_programs.program_cancel)
    program_state = _sync(ops_programs.program_state)
    program_upload = _sync(ops_programs.program_upload)
    file_list = _sync(ops_files.file_list)
    file_properties = _sync(ops_files.file_properties)
    file_full_name = _sync(ops_files.file_full_name)
    file_krc_name = _sync(ops_files.file_krc_name)
    file_read = _sync(ops_files.file_read)
    file_write = _sync(ops_files.file_write)
    file_delete = _sync(ops_files.file_delete)
    file_create = _sync(ops_files.file_create)
    file_copy = _sync(ops_files.file_copy)
    file_move = _sync(ops_files.file_move)
    file_set_attribute = _sync(ops_files.file_set_attribute)
