"""``kvp emu``: the KUKAVARPROXY emulator in the foreground, as ``kukavarproxy-emu``.

Its arguments are the emulator's (argparse, :mod:`kukavarproxy_emu.__main__`), so the global
``--port`` of ``kvp`` is not taken from after ``emu``: ``kvp emu --port 7001`` is the emulator's.
"""

from __future__ import annotations

import typer

ORDER = 90
COMMANDS = ("emu",)


def emu(ctx: typer.Context) -> None:
    """Run the KUKAVARPROXY emulator in the foreground (kvp emu --help lists its options)."""
    from kukavarproxy_emu.__main__ import main as emu_main

    try:
        code = emu_main(list(ctx.args), prog="kvp emu")
    except SystemExit as exc:  # argparse: --help (0) or a usage error (2)
        code = exc.code if isinstance(exc.code, int) else 2
    raise typer.Exit(code)


def register(app: typer.Typer) -> None:
    # Every argument, --help included, goes to the emulator's own parser: one definition of
    # its options, and ``kvp emu --help`` lists them all.
    settings = {
        "allow_extra_args": True,
        "ignore_unknown_options": True,
        "help_option_names": [],
    }
    app.command("emu", context_settings=settings, add_help_option=False)(emu)
