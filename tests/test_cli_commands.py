"""The command-group registry: every module of pyopenshowvar_apps.commands adds its commands."""

from __future__ import annotations

import typer
from pyopenshowvar_apps.cli import app
from pyopenshowvar_apps.commands import LazyCommands, build_group, command_modules, register_all
from typer.main import get_command, get_group


def test_every_group_module_declares_what_it_registers_in_order() -> None:
    modules = command_modules()
    orders = [getattr(m, "ORDER", 50) for m in modules]
    assert orders == sorted(orders)
    seen: list[str] = []
    for module in modules:
        built = build_group(module, rich_markup_mode=None)
        assert built, f"{module.__name__} registers nothing"
        # the lazy group finds a command by these names without running register()
        assert sorted(built) == sorted(module.COMMANDS), module.__name__
        seen += built
    assert len(seen) == len(set(seen)), "two groups register the same command name"
    assert {"read", "write", "watch", "repl", "monitor", "emu", "program", "files"} <= set(seen)


def test_the_lazy_group_lists_what_an_eager_one_would() -> None:
    fresh = typer.Typer(rich_markup_mode=None)
    register_all(fresh)
    eager = list(get_group(fresh).commands)  # commands in module order, then the groups
    group = get_command(app)
    assert group.list_commands(None) == eager  # type: ignore[attr-defined,arg-type]
    assert list(LazyCommands(rich_markup_mode=None)) == eager


def test_a_lookup_builds_only_its_own_group() -> None:
    lazy = LazyCommands(rich_markup_mode=None)
    assert "read" in lazy and "nosuchcommand" not in lazy
    assert lazy["read"].name == "read"
    assert set(lazy._loaded) == {"pyopenshowvar_apps.commands.variables"}
    assert lazy.get("nosuchcommand") is None
    assert len(lazy) == len(list(lazy))
