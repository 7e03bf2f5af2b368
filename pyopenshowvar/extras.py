"""Which pip extra brings which optional part of the toolkit, and the error that says so.

``pip install pyopenshowvar`` is the client library alone (numpy is its only dependency). The
emulator's dynamic plant, the ``kvp`` applications and the OPC UA gateway need more; each lives
behind an extra:

==========  ==============================================================================
extra       brings
==========  ==============================================================================
emulator    MuJoCo, for the emulator's dynamic plant (``--plant ideal`` needs nothing more)
apps        the ``kvp`` command line and its applications (CLI, REPL, monitor, web pad,
            case studies, wave platform) and the ``emulator`` extra for ``--emulate``
gateway     ``apps`` plus asyncua, for ``kvp gateway``
urdf        yourdfpy, to load an arm from a URDF file (the shipped catalogue needs nothing)
all         all of the above
==========  ==============================================================================

A command that reaches a missing module raises (or prints) :class:`MissingExtraError`, which
names the extra to install instead of showing a bare ``ModuleNotFoundError``.
"""

from __future__ import annotations

import importlib
from types import ModuleType

__all__ = ["EXTRA_OF", "MissingExtraError", "explain", "require"]

#: Top-level module name → the extra that installs it.
EXTRA_OF: dict[str, str] = {
    "mujoco": "emulator",
    **dict.fromkeys(
        (
            "typer",
            "click",
            "rich",
            "textual",
            "prompt_toolkit",
            "matplotlib",
            "pymodbus",
            "serial",
            "starlette",
            "uvicorn",
            "websockets",
            "segno",
            "skimage",
            "scipy",
            "google",  # protobuf: kvp universal's link to external simulators
            "waveresponse",
        ),
        "apps",
    ),
    "asyncua": "gateway",
    "yourdfpy": "urdf",
    "pygame": "gamepad",
}


class MissingExtraError(ModuleNotFoundError):
    """An optional dependency is not installed; the message names the pip extra that brings it.

    A subclass of :class:`ModuleNotFoundError` (with ``name`` set), so code that already
    handles a missing module keeps working.
    """

    def __init__(self, module: str, extra: str, what: str) -> None:
        super().__init__(
            f"{what} needs {module}, which is not installed: pip install 'pyopenshowvar[{extra}]'",
            name=module,
        )
        self.extra = extra


def explain(exc: ModuleNotFoundError, what: str = "this command") -> MissingExtraError | None:
    """The :class:`MissingExtraError` for ``exc`` if an extra brings its module, else None.

    ``None`` means the missing module is not one of ours to install: a real bug or a broken
    environment, to be reported as such.
    """
    if isinstance(exc, MissingExtraError):
        return exc
    top = (exc.name or "").partition(".")[0]
    extra = EXTRA_OF.get(top)
    return None if extra is None else MissingExtraError(top, extra, what)


def require(module: str, what: str) -> ModuleType:
    """Import ``module``; if it is missing, raise :class:`MissingExtraError` naming its extra."""
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        error = explain(exc, what)
        if error is None:
            raise
        raise error from None
