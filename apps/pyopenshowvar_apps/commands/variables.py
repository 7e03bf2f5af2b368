"""``kvp read`` and ``kvp write``: one-shot access to KRL variables from a shell."""

from __future__ import annotations

import json
from typing import Annotated, Any

import typer

from pyopenshowvar import Client
from pyopenshowvar_apps.common import run, to_jsonable

ORDER = 10


def read(
    names: Annotated[list[str], typer.Argument(help="Variables, e.g. '$AXIS_ACT' '$OV_PRO'.")],
    as_json: Annotated[bool, typer.Option("--json", help="Print typed values as JSON.")] = False,
) -> None:
    """Read variables; print each raw value on its own line (or --json typed)."""

    async def job(kvp: Client) -> dict[str, Any]:
        results = await kvp.read_many(names, typed=as_json)
        for r in results.values():
            if r.error is not None:
                raise r.error
        return {n: (to_jsonable(r.value) if as_json else r.text) for n, r in results.items()}

    values = run(job)
    if as_json:
        typer.echo(json.dumps(values, indent=None if len(values) == 1 else 2))
    else:
        for text in values.values():
            typer.echo(text)


def write(
    name: Annotated[str, typer.Argument(help="Variable, e.g. '$OV_PRO' or 'MYAXIS'.")],
    value: Annotated[str, typer.Argument(help="KRL literal, e.g. 50 or '{A1 10.0, A2 -80.0}'.")],
) -> None:
    """Write a KRL literal to a variable; prints the proxy's echo."""
    typer.echo(run(lambda kvp: kvp.write(name, value)))


def register(app: typer.Typer) -> None:
    app.command("read")(read)
    app.command("write")(write)
