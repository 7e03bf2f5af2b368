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

from ..core import as_async_method, as_sync_method
from . import ops, ops_programs

if TYPE_CHECKING:
    from .server import ServerInfo

__all__ = ["C3Methods", "SyncC3Methods"]


class _C3State:
    #: What :meth:`server_info` found (cached per client; ``refresh=True`` asks again).
    _c3_info: ServerInfo | None = None
    #: Largest file chunk sent in one #29 message (C3 Bridge reassembles large frames).
    _c3_chunk: int = 32 * 1024


class C3Methods(_C3State):
    """C3 Bridge methods of the asyncio :class:`~pyopenshowvar.Client` (see docs/c3bridge.md)."""

    server_info = as_async_method(ops.server_info)
    read_utf16 = as_async_method(ops.read_utf16)
    write_utf16 = as_async_method(ops.write_utf16)
    read_multiple = as_async_method(ops.read_multiple)
    write_multiple = as_async_method(ops.write_multiple)
    motion = as_async_method(ops.motion)
    kcp_key = as_async_method(ops.kcp_key)
    confirm_all = as_async_method(ops.confirm_all)
    proxy_info = as_async_method(ops.proxy_info)
    proxy_features = as_async_method(ops.proxy_features)
    benchmark = as_async_method(ops.benchmark)
    program_select = as_async_method(ops_programs.program_select)
    program_run = as_async_method(ops_programs.program_run)
    program_start = as_async_method(ops_programs.program_start)
    program_stop = as_async_method(ops_programs.program_stop)
    program_reset = as_async_method(ops_programs.program_reset)
    program_cancel = as_async_method(ops_programs.program_cancel)
    program_state = as_async_method(ops_programs.program_state)
    program_upload = as_async_method(ops_programs.program_upload)
    file_list = as_async_method(ops_programs.file_list)
    file_properties = as_async_method(ops_programs.file_properties)
    file_full_name = as_async_method(ops_programs.file_full_name)
    file_krc_name = as_async_method(ops_programs.file_krc_name)
    file_read = as_async_method(ops_programs.file_read)
    file_write = as_async_method(ops_programs.file_write)
    file_delete = as_async_method(ops_programs.file_delete)
    file_create = as_async_method(ops_programs.file_create)
    file_copy = as_async_method(ops_programs.file_copy)
    file_move = as_async_method(ops_programs.file_move)
    file_set_attribute = as_async_method(ops_programs.file_set_attribute)


class SyncC3Methods(_C3State):
    """The same methods, blocking, for :class:`pyopenshowvar.sync.Client`."""

    server_info = as_sync_method(ops.server_info)
    read_utf16 = as_sync_method(ops.read_utf16)
    write_utf16 = as_sync_method(ops.write_utf16)
    read_multiple = as_sync_method(ops.read_multiple)
    write_multiple = as_sync_method(ops.write_multiple)
    motion = as_sync_method(ops.motion)
    kcp_key = as_sync_method(ops.kcp_key)
    confirm_all = as_sync_method(ops.confirm_all)
    proxy_info = as_sync_method(ops.proxy_info)
    proxy_features = as_sync_method(ops.proxy_features)
    benchmark = as_sync_method(ops.benchmark)
    program_select = as_sync_method(ops_programs.program_select)
    program_run = as_sync_method(ops_programs.program_run)
    program_start = as_sync_method(ops_programs.program_start)
    program_stop = as_sync_method(ops_programs.program_stop)
    program_reset = as_sync_method(ops_programs.program_reset)
    program_cancel = as_sync_method(ops_programs.program_cancel)
    program_state = as_sync_method(ops_programs.program_state)
    program_upload = as_sync_method(ops_programs.program_upload)
    file_list = as_sync_method(ops_programs.file_list)
    file_properties = as_sync_method(ops_programs.file_properties)
    file_full_name = as_sync_method(ops_programs.file_full_name)
    file_krc_name = as_sync_method(ops_programs.file_krc_name)
    file_read = as_sync_method(ops_programs.file_read)
    file_write = as_sync_method(ops_programs.file_write)
    file_delete = as_sync_method(ops_programs.file_delete)
    file_create = as_sync_method(ops_programs.file_create)
    file_copy = as_sync_method(ops_programs.file_copy)
    file_move = as_sync_method(ops_programs.file_move)
    file_set_attribute = as_sync_method(ops_programs.file_set_attribute)
