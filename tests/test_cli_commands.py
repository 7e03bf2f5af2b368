"""The command-group registry: every module of pyopenshowvar_apps.commands adds its commands."""

from __future__ import annotations

import typer
from pyopenshowvar_apps.cli import app
from pyopenshowvar_apps.commands import command_modules, register_all
from typer.main import get_command


def _names(a: typer.Typer) -> list[str]:
    return [c.name or "" for c in a.registered_commands]


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
    assert _names(fresh) == seen == _names(app)
    assert {"read", "write", "watch", "repl", "monitor", "emu"} <= set(seen)
    assert set(get_command(app).list_commands(None)) == set(seen)  # type: ignore[attr-defined,arg-type]
