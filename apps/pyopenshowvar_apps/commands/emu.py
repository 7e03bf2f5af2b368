"""``kvp emu``: the KUKAVARPROXY emulator in the foreground, as ``kukavarproxy-emu``."""

from __future__ import annotations

import typer

ORDER = 90


def emu(ctx: typer.Context) -> None:
    """Run the KUKAVARPROXY emulator in the foreground (options as kukavarproxy-emu)."""
    from kukavarproxy_emu.__main__ import main as emu_main

    raise typer.Exit(emu_main(list(ctx.args)))


def register(app: typer.Typer) -> None:
    app.command(
        "emu", context_settings={"allow_extra_args": True, "ignore_unknown_options": True}
    )(emu)
