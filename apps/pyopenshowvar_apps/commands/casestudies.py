"""Registers the thesis' case studies: ``kvp demo``, ``linefollow``, ``teleop``, ``haptic``."""

from __future__ import annotations

import typer

ORDER = 60
COMMANDS = ("demo", "linefollow", "teleop", "haptic")


def register(app: typer.Typer) -> None:
    from pyopenshowvar_apps import demo
    from pyopenshowvar_apps.casestudies import linefollow_cli, teleop_cli

    app.command("demo")(demo.demo)
    app.command("linefollow")(linefollow_cli.linefollow)
    app.command("teleop")(teleop_cli.teleop)
    app.command("haptic")(teleop_cli.haptic)
