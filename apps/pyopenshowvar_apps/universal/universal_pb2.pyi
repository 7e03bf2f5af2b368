from google.protobuf.internal import containers as _containers
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable
from typing import ClassVar as _ClassVar, Optional as _Optional

DESCRIPTOR: _descriptor.FileDescriptor

class ToOSC(_message.Message):
    __slots__ = ("model", "modelName", "valveSignals")
    MODEL_FIELD_NUMBER: _ClassVar[int]
    MODELNAME_FIELD_NUMBER: _ClassVar[int]
    VALVESIGNALS_FIELD_NUMBER: _ClassVar[int]
    model: int
    modelName: str
    valveSignals: _containers.RepeatedScalarFieldContainer[float]
    def __init__(self, model: _Optional[int] = ..., modelName: _Optional[str] = ..., valveSignals: _Optional[_Iterable[float]] = ...) -> None: ...

class ToAAUC(_message.Message):
    __slots__ = ("jointAngles", "jointVelocities")
    JOINTANGLES_FIELD_NUMBER: _ClassVar[int]
    JOINTVELOCITIES_FIELD_NUMBER: _ClassVar[int]
    jointAngles: _containers.RepeatedScalarFieldContainer[float]
    jointVelocities: _containers.RepeatedScalarFieldContainer[float]
    def __init__(self, jointAngles: _Optional[_Iterable[float]] = ..., jointVelocities: _Optional[_Iterable[float]] = ...) -> None: ...
