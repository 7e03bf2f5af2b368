"""Registers the crane benchmark suite (thesis §5.2): ``kvp crane-bench``."""

from __future__ import annotations

import typer

ORDER = 67
COMMANDS = ("crane-bench",)


def register(app: typer.Typer) -> None:
    from pyopenshowvar_apps.cranebench import cli

    app.command("crane-bench")(cli.crane_bench)
