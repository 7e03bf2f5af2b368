"""Registers ``kvp discover`` (implemented in :mod:`pyopenshowvar_apps.discover`)."""

from __future__ import annotations

import typer

from pyopenshowvar_apps import discover

ORDER = 40


def register(app: typer.Typer) -> None:
    app.command("discover")(discover.discover)
