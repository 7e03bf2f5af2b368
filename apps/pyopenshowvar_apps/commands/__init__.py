"""The ``kvp`` subcommands: one module per group, found and registered automatically.

To add a command group, drop a module into this package that defines

.. code-block:: python

    ORDER = 60                      # place in ``kvp --help`` (lower first; default 50)

    def register(app: typer.Typer) -> None:
        app.command("mycmd")(mycmd)

and nothing else changes: :func:`register_all` imports every module here in ``ORDER`` (then
name) order and calls its ``register``. No central list means engineers adding commands in
parallel never edit the same lines.

Every module here is imported by every ``kvp`` invocation, so keep module level cheap: typer
and the library only; import numpy-heavy code, prompt_toolkit, Textual, matplotlib or a web
stack inside the command function.
"""

from __future__ import annotations

import importlib
import pkgutil
from types import ModuleType

import typer

__all__ = ["command_modules", "register_all"]


def command_modules() -> list[ModuleType]:
    """The command-group modules of this package, in ``kvp --help`` order."""
    modules = [
        importlib.import_module(f"{__name__}.{info.name}")
        for info in pkgutil.iter_modules(__path__)
        if not info.name.startswith("_")
    ]
    return sorted(modules, key=lambda m: (getattr(m, "ORDER", 50), m.__name__))


def register_all(app: typer.Typer) -> None:
    """Add every group's commands to ``app``."""
    for module in command_modules():
        module.register(app)
