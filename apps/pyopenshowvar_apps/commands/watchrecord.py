"""Registers ``kvp watch`` and ``kvp record`` (in :mod:`pyopenshowvar_apps.watchrecord`)."""

from __future__ import annotations

import typer

ORDER = 20
COMMANDS = ("watch", "record")


def register(app: typer.Typer) -> None:
    from pyopenshowvar_apps import watchrecord

    app.command("watch")(watchrecord.watch)
    app.command("record")(watchrecord.record)
