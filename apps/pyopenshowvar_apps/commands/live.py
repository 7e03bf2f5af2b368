"""Registers ``kvp watch`` and ``kvp record`` (implemented in :mod:`pyopenshowvar_apps.live`)."""

from __future__ import annotations

import typer

from pyopenshowvar_apps import live

ORDER = 20


def register(app: typer.Typer) -> None:
    app.command("watch")(live.watch)
    app.command("record")(live.record)
