"""Registers ``kvp arms`` (implemented in :mod:`pyopenshowvar_apps.armscli`)."""

from __future__ import annotations

import typer

ORDER = 62
COMMANDS = ("arms",)


def register(app: typer.Typer) -> None:
    from pyopenshowvar_apps.armscli import arms_app

    app.add_typer(arms_app)
