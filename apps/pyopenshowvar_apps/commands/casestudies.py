"""Registers the thesis' case studies: ``kvp demo``, ``linefollow``, ``teleop``, ``haptic``."""

from __future__ import annotations

import typer

from pyopenshowvar_apps import demo
from pyopenshowvar_apps.casestudies import linefollow_cli, teleop_cli

ORDER = 60


def register(app: typer.Typer) -> None:
    app.command("demo")(demo.demo)
    app.command("linefollow")(linefollow_cli.linefollow)
    app.command("teleop")(teleop_cli.teleop)
    app.command("haptic")(teleop_cli.haptic)
