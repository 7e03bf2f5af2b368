"""Registers ``kvp repl`` and ``kvp monitor`` (in :mod:`pyopenshowvar_apps.sessions`)."""

from __future__ import annotations

import typer

ORDER = 50
COMMANDS = ("repl", "monitor")


def register(app: typer.Typer) -> None:
    from pyopenshowvar_apps import sessions

    app.command("repl")(sessions.repl)
    app.command("monitor")(sessions.monitor)
