"""Registers ``kvp web`` (in :mod:`pyopenshowvar_apps.web.command`; the web stack is imported
only when the command runs)."""

from __future__ import annotations

import typer

ORDER = 55
COMMANDS = ("web",)


def register(app: typer.Typer) -> None:
    from pyopenshowvar_apps.web import command

    app.command("web")(command.web)
