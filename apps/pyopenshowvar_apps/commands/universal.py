"""Registers ``kvp universal`` and ``kvp universal-sim`` (:mod:`pyopenshowvar_apps.universal.cli`)."""

from __future__ import annotations

import typer

ORDER = 63
COMMANDS = ("universal", "universal-sim")


def register(app: typer.Typer) -> None:
    from pyopenshowvar_apps.universal.cli import universal, universal_sim

    app.command("universal")(universal)
    app.command("universal-sim")(universal_sim)
