"""Registers ``kvp discover`` (implemented in :mod:`pyopenshowvar_apps.discover`)."""

from __future__ import annotations

import typer

ORDER = 40
COMMANDS = ("discover",)


def register(app: typer.Typer) -> None:
    from pyopenshowvar_apps import discover

    app.command("discover")(discover.discover)
