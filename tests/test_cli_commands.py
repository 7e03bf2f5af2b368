"""The command-group registry: every module of pyopenshowvar_apps.commands adds its commands."""

from __future__ import annotations

import typer
from pyopenshowvar_apps.cli import app
from pyopenshowvar_apps.commands import command_modules, register_all
from typer.main import get_command


def _names(a: typer.Typer) -> list[str]:
    """Commands and command groups (``kvp program start``: the group ``program``)."""
    groups = [
        g.name or (g.typer_instance.info.name if g.typer_instance else "") or ""
        for g in a.registered_groups
    ]
    return [c.name or "" for c in a.registered_commands] + groups


def test_every_group_module_registers_commands_in_order() -> None:
    modules = command_modules()
    orders = [getattr(m, "ORDER", 50) for m in modules]
    assert orders == sorted(orders)
    seen: list[str] = []
    for module in modules:
        one = typer.Typer()
        module.register(one)
        assert _names(one), f"{module.__name__} registers nothing"
        seen += _names(one)
    assert len(seen) == len(set(seen)), "two groups register the same command name"
    fresh = typer.Typer()
    register_all(fresh)
    # commands keep the modules' order; groups (typer lists them after the commands) too
    assert set(_names(fresh)) == set(seen) == set(_names(app))
    commands = [c.name for c in fresh.registered_commands]
    assert commands == [n for n in seen if n in commands]
    assert {"read", "write", "watch", "repl", "monitor", "emu", "program", "files"} <= set(seen)
    assert set(get_command(app).list_commands(None)) == set(seen)  # type: ignore[attr-defined,arg-type]
