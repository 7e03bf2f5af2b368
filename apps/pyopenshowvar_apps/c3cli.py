"""What ``kvp program`` and ``kvp files`` share: running a C3 Bridge job with one-line errors.

The C3 errors get the usual exit codes (docs/cli.md): a refusal by the controller (a C3 error
code) is 5 like a refused write, a server without the message (KUKAVARPROXY, or an old C3
Bridge) is 6, a request the client will not send (a motion without ``--allow-motion``, a name
or file over a limit) is 2. ``--emulate`` starts an embedded emulator that speaks C3 Bridge
(a fresh one per command: for several steps run ``kukavarproxy-emu --proxy c3bridge``).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, TypeVar

from pyopenshowvar import KvpError
from pyopenshowvar_apps.common import (
    EXIT_PROTOCOL,
    EXIT_USAGE,
    EXIT_VARIABLE,
    Opts,
    fail,
    fail_for,
    open_client,
)

if TYPE_CHECKING:
    from pyopenshowvar import Client

__all__ = ["run_c3", "start_c3_emulator"]

T = TypeVar("T")


def start_c3_emulator() -> None:
    """With ``--emulate``: an embedded C3 Bridge emulator (ideal plant: exact values)."""
    if not Opts.emulate or Opts.emulator is not None:
        return
    from kukavarproxy_emu import EmulatorConfig, EmulatorThread

    config = EmulatorConfig(
        host="127.0.0.1", port=0, discovery=False, proxy="c3bridge", plant=Opts.plant
    )
    Opts.emulator = EmulatorThread(config).start()
    Opts.host, Opts.port = "127.0.0.1", Opts.emulator.port


def run_c3(job: Callable[[Client], Awaitable[T]]) -> T:
    """Run ``job`` with a connected client; C3 errors and library errors become one line."""
    import asyncio

    from pyopenshowvar.c3 import (
        C3CommandError,
        MotionNotAllowedError,
        RequestTooLargeError,
        UnsupportedError,
    )

    start_c3_emulator()

    async def main() -> T:
        async with open_client() as kvp:
            return await job(kvp)

    try:
        return asyncio.run(main())
    except MotionNotAllowedError as exc:
        fail(
            EXIT_USAGE,
            str(exc).replace("pass allow_motion=True (CLI: --allow-motion)", "add --allow-motion"),
        )
    except RequestTooLargeError as exc:
        fail(EXIT_USAGE, f"{Opts.where()}: {exc}")
    except UnsupportedError as exc:
        fail(EXIT_PROTOCOL, str(exc))
    except C3CommandError as exc:
        fail(EXIT_VARIABLE, str(exc))
    except KvpError as exc:
        fail_for(exc)
    except ValueError as exc:  # an argument the library checks (a module name, a motion type)
        fail(EXIT_USAGE, str(exc))
