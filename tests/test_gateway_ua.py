"""The gateway's typed boundary to asyncua (gateway/ua.py): each helper builds what asyncua's own
constructor builds from the same plain value, and the Error frame decodes as asyncua reads it."""

from __future__ import annotations

import uuid

import pytest
from asyncua import ua as asyncua_ua
from asyncua.common.utils import Buffer
from asyncua.ua.ua_binary import header_from_binary, struct_from_binary
from pyopenshowvar_apps.gateway import ua


@pytest.mark.parametrize(
    ("identifier", "namespace", "kind"),
    [
        (ua.ObjectIds.HasComponent, 0, asyncua_ua.NodeIdType.TwoByte),
        (70_000, 2, asyncua_ua.NodeIdType.Numeric),
        ("Cell.MotionDevices.r1", 3, asyncua_ua.NodeIdType.String),
        (b"\x01\x02", 1, asyncua_ua.NodeIdType.ByteString),
        (uuid.UUID(int=7), 1, asyncua_ua.NodeIdType.Guid),
    ],
)
def test_node_id_guesses_the_encoding_as_asyncua_does(
    identifier: ua.Identifier, namespace: int, kind: asyncua_ua.NodeIdType
) -> None:
    nid = ua.node_id(identifier, namespace)
    assert nid == asyncua_ua.NodeId(identifier, namespace)  # type: ignore[arg-type]
    assert (nid.Identifier, nid.NamespaceIndex, nid.NodeIdType) == (identifier, namespace, kind)


def test_path_of_is_a_string_identifier_and_refuses_others() -> None:
    assert ua.path_of(ua.node_id("Cell.Controllers.r1", 2)) == "Cell.Controllers.r1"
    with pytest.raises(TypeError, match="not a string NodeId"):
        ua.path_of(ua.node_id(85))


def test_status_code_and_variant_of() -> None:
    code = ua.status_code(ua.StatusCodes.BadNoCommunication)
    assert code.value == ua.StatusCodes.BadNoCommunication and not code.is_good()
    dv = ua.DataValue(None)  # asyncua wraps even None in a Variant
    assert ua.variant_of(dv).Value is None


def test_the_error_frame_is_an_opc_ua_err_message() -> None:
    frame = ua.error_frame(ua.StatusCodes.BadSecurityChecksFailed, "too many failed logins")
    buf = Buffer(frame)
    header = header_from_binary(buf)
    assert header.MessageType == ua.MessageType.Error and header.packet_size == len(frame)
    error = struct_from_binary(ua.ErrorMessage, buf)
    assert error.Error.value == ua.StatusCodes.BadSecurityChecksFailed
    assert error.Reason == "too many failed logins"
