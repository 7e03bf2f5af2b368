"""Registers ``kvp watch`` and ``kvp record`` (implemented in :mod:`pyopenshowvar_apps.live`)."""

from __future__ import annotations

import typer

ORDER = 20
COMMANDS = ("watch", "record")


def register(app: typer.Typer) -> None:
    from pyopenshowvar_apps import live

    app.command("watch")(live.watch)
    app.command("record")(live.record)
