"""Registers ``kvp bench`` (implemented in :mod:`pyopenshowvar_apps.bench`)."""

from __future__ import annotations

import typer

ORDER = 30
COMMANDS = ("bench",)


def register(app: typer.Typer) -> None:
    from pyopenshowvar_apps import bench

    app.command("bench")(bench.bench)
