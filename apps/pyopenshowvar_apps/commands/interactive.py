"""Registers ``kvp repl`` and ``kvp monitor`` (in :mod:`pyopenshowvar_apps.sessions`)."""

from __future__ import annotations

import typer

from pyopenshowvar_apps import sessions

ORDER = 50


def register(app: typer.Typer) -> None:
    app.command("repl")(sessions.repl)
    app.command("monitor")(sessions.monitor)
