"""Registers heave compensation on the wave platform: ``kvp heave`` and ``kvp platform``."""

from __future__ import annotations

import typer

ORDER = 65
COMMANDS = ("heave", "platform")


def register(app: typer.Typer) -> None:
    from pyopenshowvar_apps.heave import cli

    cli.register(app)
