"""The gateway's typed boundary to asyncua: the OPC UA names the gateway uses, typed precisely.

asyncua ships a ``py.typed`` marker, but its annotations are narrower than what it accepts, and
its packages import names without re-exporting them, so strict mypy refuses code that uses
asyncua exactly as documented:

* ``NodeId``'s fields are annotated with asyncua's own wrapper classes (``Int32 | String |
  Guid | ByteString``, ``Int16``), while ``NodeId.__post_init__`` takes a plain int, str, bytes
  or UUID and guesses the encoding from it; and the identifier read back is that union (the
  gateway's own nodes have string paths: :func:`path_of`);
* ``StatusCode.value`` is annotated ``UInt32`` while the code table ``StatusCodes`` holds ints;
* ``DataValue``'s timestamps are annotated with asyncua's ``DateTime`` subclass, while its
  binary encoder takes any ``datetime``; its ``Value`` is annotated optional, while
  ``__post_init__`` always makes it a Variant;
* ``uatcp_to_binary`` and ``ErrorMessage`` (see :func:`error_frame`);
* ``asyncua.Server`` / ``Client`` and ``asyncua.ua.ObjectIds`` / ``AttributeIds`` /
  ``StatusCodes`` are imported by their packages without being re-exported.

This module bridges exactly these gaps (each ``cast`` below is one of them, and changes nothing
at run time) and re-exports the names of ``asyncua.ua`` the gateway uses, so gateway code says
``from . import ua`` and is checked strictly. The asyncua server internals that
:mod:`.sessions` and :mod:`.clone` hook into are imported there, where they are hooked.
"""

from __future__ import annotations

import uuid
from datetime import datetime
from typing import cast

from asyncua import ua as _ua
from asyncua.client.client import Client as Client
from asyncua.server.server import Server as Server
from asyncua.ua import AccessLevel as AccessLevel
from asyncua.ua import ActivateSessionParameters as ActivateSessionParameters
from asyncua.ua import AddNodesItem as AddNodesItem
from asyncua.ua import AddReferencesItem as AddReferencesItem
from asyncua.ua import AnonymousIdentityToken as AnonymousIdentityToken
from asyncua.ua import Argument as Argument
from asyncua.ua import BrowseDirection as BrowseDirection
from asyncua.ua import DataValue as DataValue
from asyncua.ua import ErrorMessage as ErrorMessage
from asyncua.ua import EUInformation as EUInformation
from asyncua.ua import LocalizedText as LocalizedText
from asyncua.ua import MessageSecurityMode as MessageSecurityMode
from asyncua.ua import MessageType as MessageType
from asyncua.ua import NodeAttributesMask as NodeAttributesMask
from asyncua.ua import NodeClass as NodeClass
from asyncua.ua import NodeId as NodeId
from asyncua.ua import ObjectAttributes as ObjectAttributes
from asyncua.ua import QualifiedName as QualifiedName
from asyncua.ua import Range as Range
from asyncua.ua import ReferenceDescription as ReferenceDescription
from asyncua.ua import SecurityPolicyType as SecurityPolicyType
from asyncua.ua import StatusCode as StatusCode
from asyncua.ua import UserNameIdentityToken as UserNameIdentityToken
from asyncua.ua import VariableAttributes as VariableAttributes
from asyncua.ua import Variant as Variant
from asyncua.ua import VariantType as VariantType
from asyncua.ua.attribute_ids import AttributeIds as AttributeIds
from asyncua.ua.object_ids import ObjectIds as ObjectIds
from asyncua.ua.status_codes import StatusCodes as StatusCodes
from asyncua.ua.ua_binary import uatcp_to_binary
from asyncua.ua.uaerrors import UaError as UaError
from asyncua.ua.uaerrors import UaStatusCodeError as UaStatusCodeError

#: what asyncua's NodeId guesses its encoding from (see the module doc)
Identifier = int | str | bytes | uuid.UUID


def node_id(identifier: Identifier = 0, namespace: int = 0) -> NodeId:
    """``ua.NodeId(identifier, namespace)``: numeric, string, opaque or GUID by the type."""
    return NodeId(
        cast("_ua.Int32 | _ua.String | _ua.Guid | _ua.ByteString", identifier),
        cast("_ua.Int16", namespace),
    )


def path_of(node: NodeId) -> str:
    """The identifier of a string NodeId: the gateway names its own nodes by their path."""
    identifier = node.Identifier
    if not isinstance(identifier, str):
        raise TypeError(f"{node.to_string()} is not a string NodeId")
    return identifier


def status_code(code: int) -> StatusCode:
    """``ua.StatusCode(code)`` for a code of :class:`StatusCodes`."""
    return StatusCode(cast("_ua.UInt32", code))


def timestamp(when: datetime | None) -> _ua.DateTime | None:
    """A DataValue timestamp: asyncua encodes any ``datetime`` (see the module doc)."""
    return cast("_ua.DateTime | None", when)


def variant_of(value: DataValue) -> Variant:
    """A DataValue's Variant: annotated optional, but ``DataValue.__post_init__`` wraps every
    value (None too) in a Variant."""
    variant = value.Value
    if variant is None:
        raise TypeError("a DataValue without a Variant")
    return variant


def error_frame(code: int, reason: str) -> bytes:
    """An OPC UA TCP Error message (``ERR``, a StatusCode and a reason), ready to send.

    ``uatcp_to_binary`` annotates its first parameter as the ``MessageType`` class while it takes
    the message type's bytes (``MessageType.Error``, ``b"ERR"``), and ``ErrorMessage.Reason`` as
    asyncua's ``String`` subclass while it encodes any str."""
    error = ErrorMessage(status_code(code), cast("_ua.String", reason))
    return uatcp_to_binary(cast(MessageType, MessageType.Error), error)
