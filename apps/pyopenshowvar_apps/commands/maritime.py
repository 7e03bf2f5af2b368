"""Registers the maritime case studies: ``kvp crane-head`` and ``kvp underwater-plan``."""

from __future__ import annotations

import typer

ORDER = 66
COMMANDS = ("crane-head", "underwater-plan")


def register(app: typer.Typer) -> None:
    from pyopenshowvar_apps.maritime import cranehead_cli, underwater_cli

    app.command("crane-head")(cranehead_cli.crane_head)
    app.command("underwater-plan")(underwater_cli.underwater_plan)
