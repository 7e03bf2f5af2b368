"""Registers heave compensation on the wave platform: ``kvp heave`` and ``kvp platform``."""

from __future__ import annotations

import typer

from pyopenshowvar_apps.heave import cli

ORDER = 65


def register(app: typer.Typer) -> None:
    cli.register(app)
