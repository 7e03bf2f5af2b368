"""The ``kvp`` subcommands: one module per group, found automatically, built when first used.

To add a command group, drop a module into this package that defines

.. code-block:: python

    ORDER = 60                      # place in ``kvp --help`` (lower first; default 50)
    COMMANDS = ("mycmd",)           # the names register() adds (a test checks they agree)

    def register(app: typer.Typer) -> None:
        from pyopenshowvar_apps.mything import mycmd   # the implementation, imported here

        app.command("mycmd")(mycmd)

and nothing else changes: :class:`LazyCommands` finds every module here and reads its
``COMMANDS``; a module's ``register`` runs only when one of its commands is looked up. No
central list means engineers adding commands in parallel never edit the same lines.

``kvp read`` imports every module here (to learn the names) but registers and imports only the
``read`` group, so keep module level cheap: typer, the standard library and the names; import
the implementation, numpy-heavy code, prompt_toolkit, Textual, matplotlib or a web stack in
``register`` or inside the command function. ``kvp --help`` builds them all (it lists every
command with its help line).
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Iterator, MutableMapping
from types import ModuleType
from typing import Any

import typer
import typer.main

__all__ = ["LazyCommands", "build_group", "command_modules", "register_all"]


def command_modules() -> list[ModuleType]:
    """The command-group modules of this package, in ``kvp --help`` order."""
    modules = [
        importlib.import_module(f"{__name__}.{info.name}")
        for info in pkgutil.iter_modules(__path__)
        if not info.name.startswith("_")
    ]
    return sorted(modules, key=lambda m: (getattr(m, "ORDER", 50), m.__name__))


def register_all(app: typer.Typer) -> None:
    """Add every group's commands to ``app`` (imports every implementation)."""
    for module in command_modules():
        module.register(app)


def build_group(module: ModuleType, **settings: Any) -> dict[str, Any]:
    """The click commands ``module.register`` adds, by name, built by typer with ``settings``.

    ``settings`` are the ``typer.Typer`` options the ``kvp`` app builds its commands with
    (``rich_markup_mode``...). Commands come before groups, as typer lists them.
    """
    one = typer.Typer(add_completion=False, **settings)
    module.register(one)
    group: Any = typer.main.get_group(one)
    return dict(group.commands)


class LazyCommands(MutableMapping[str, Any]):
    """The subcommands of the ``kvp`` group, each group module built when first looked up.

    It stands in for the ``commands`` dict of the click group: a lookup (``kvp read``) runs the
    ``register`` of the one module whose ``COMMANDS`` has the name; iterating (``kvp --help``,
    shell completion, "did you mean") builds them all and lists them as an eagerly built typer
    app would: every plain command in module order, then every group (``program``, ``files``).
    """

    def __init__(self, **settings: Any) -> None:
        self._settings = settings
        self._owner: dict[str, ModuleType] = {}
        for module in command_modules():
            for name in module.COMMANDS:
                if name in self._owner:
                    raise RuntimeError(
                        f"kvp command {name!r} is declared by both "
                        f"{self._owner[name].__name__} and {module.__name__}"
                    )
                self._owner[name] = module
        self._built: dict[str, Any] = {}
        #: module name -> its command names in typer's order, once built
        self._loaded: dict[str, list[str]] = {}

    def _load(self, module: ModuleType) -> None:
        if module.__name__ in self._loaded:
            return
        commands = build_group(module, **self._settings)
        if set(commands) != set(module.COMMANDS):
            raise RuntimeError(
                f"{module.__name__}.register adds {sorted(commands)}, "
                f"but its COMMANDS says {sorted(module.COMMANDS)}"
            )
        self._loaded[module.__name__] = list(commands)
        for name, command in commands.items():
            self._built.setdefault(name, command)

    def __getitem__(self, name: str) -> Any:
        if name not in self._built:
            if name not in self._owner:
                raise KeyError(name)
            self._load(self._owner[name])
        return self._built[name]

    def __setitem__(self, name: str, command: Any) -> None:
        self._built[name] = command

    def __delitem__(self, name: str) -> None:
        known = name in self._built or name in self._owner
        self._built.pop(name, None)
        self._owner.pop(name, None)
        if not known:
            raise KeyError(name)

    def __contains__(self, name: object) -> bool:
        return name in self._built or name in self._owner

    def __len__(self) -> int:
        return len(self._owner.keys() | self._built.keys())

    def __iter__(self) -> Iterator[str]:
        for module in dict.fromkeys(self._owner.values()):
            self._load(module)
        names = [n for n in self._built if n not in self._owner]  # added directly
        for module in dict.fromkeys(self._owner.values()):
            names += [n for n in self._loaded[module.__name__] if n in self._built]
        # typer lists plain commands first, then the groups (they have subcommands)
        plain = [n for n in names if not hasattr(self._built[n], "commands")]
        groups = [n for n in names if hasattr(self._built[n], "commands")]
        return iter(plain + groups)
