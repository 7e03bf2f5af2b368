"""Registers ``kvp bench`` (implemented in :mod:`pyopenshowvar_apps.bench`)."""

from __future__ import annotations

import typer

from pyopenshowvar_apps import bench

ORDER = 30


def register(app: typer.Typer) -> None:
    app.command("bench")(bench.bench)
