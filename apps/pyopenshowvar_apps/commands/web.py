"""Registers ``kvp web`` (in :mod:`pyopenshowvar_apps.web.command`; the web stack is imported
only when the command runs)."""

from __future__ import annotations

import typer

from pyopenshowvar_apps.web import command

ORDER = 55


def register(app: typer.Typer) -> None:
    app.command("web")(command.web)
