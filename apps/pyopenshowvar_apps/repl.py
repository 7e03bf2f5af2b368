"""``kvp repl``: an interactive KRL variable console (JOpenShowVar's console, done better).

* ``NAME`` reads; ``NAME VALUE`` or ``NAME = VALUE`` writes (the value is everything after the
  name, so ``MYAXIS {A1 10.5, A2 -80.0}`` works unquoted); every answer shows the round trip;
* typed pretty printing (``:raw`` toggles the proxy's text instead);
* line editing, persistent history and tab completion (prompt_toolkit) on a terminal; plain
  lines from a pipe;
* ``:watch NAME... [HZ]`` live until Ctrl-C, ``:stats``, ``:ping``, ``:help``, ``:quit``/``q``;
* the connection is kept alive (``PING`` every 10 s) and re-opened after a drop, with a message,
  without leaving the session.
"""

from __future__ import annotations

import asyncio
import os
import signal
import sys
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.text import Text

from pyopenshowvar import (
    Client,
    KvpConnectionError,
    KvpError,
    KvpTimeoutError,
    UnknownVariableError,
    WriteRefusedError,
)
from pyopenshowvar_apps.pretty import render_text

HELP = """\
[bold]NAME[/]                read a variable, e.g. [cyan]$AXIS_ACT[/], [cyan]$TORQUE_AXIS_ACT[][/], [cyan]MYE6ARRAY[2].A1[/]
[bold]NAME VALUE[/]          write a KRL literal, e.g. [cyan]MYAXIS {A1 10.5, A2 -80.0}[/]
[bold]NAME = VALUE[/]        the same
[bold]:watch NAME... [HZ][/] live values until Ctrl-C (default 2 Hz)
[bold]:raw[/]                toggle raw text / typed tables
[bold]:stats[/]              access-time statistics of this session
[bold]:ping[/]               one keep-alive round trip
[bold]:help[/]               this text
[bold]:quit[/], [bold]q[/], Ctrl-D    leave
Tab completes variable names; ↑/↓ and Ctrl-R search the history."""


def default_history_path() -> Path:
    """``$KVP_HISTORY`` or ``~/.local/share/kvp/history`` (XDG_DATA_HOME honoured)."""
    env = os.environ.get("KVP_HISTORY")
    if env:
        return Path(env)
    data = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(data) / "kvp" / "history"


def split_command(line: str) -> tuple[str, str | None]:
    """``NAME [=] VALUE`` → (name, value or None). Brackets may hold commas and blanks."""
    line = line.strip()
    depth = 0
    for i, ch in enumerate(line):
        if ch == "[":
            depth += 1
        elif ch == "]":
            depth -= 1
        elif depth == 0 and (ch.isspace() or ch == "="):
            rest = line[i:].strip()
            if rest.startswith("="):
                rest = rest[1:].strip()
            return line[:i], rest
    return line, None


class Repl:
    """One console session on one :class:`Client` (which may reconnect underneath)."""

    def __init__(self, client: Client, console: Console, *, raw: bool = False) -> None:
        self.client = client
        self.console = console
        self.raw = raw
        self._was_connected = False

    # -------------------------------------------------------------------- commands
    async def handle(self, line: str) -> bool:
        """Run one input line; False when the session should end."""
        line = line.strip()
        if not line or line.startswith(";"):
            return True
        if line in ("q", ":q", ":quit", ":exit", "quit", "exit"):
            return False
        if line.startswith(":"):
            await self._meta(line)
            return True
        name, value = split_command(line)
        if value == "":
            self.error(f"missing value after {name!r} (write: NAME VALUE or NAME = VALUE)")
            return True
        await self._guarded(self._write(name, value) if value is not None else self._read(name))
        return True

    async def _read(self, name: str) -> None:
        t0 = time.perf_counter()
        text = await self.client.read(name)
        ms = (time.perf_counter() - t0) * 1e3
        if self.raw:
            self.console.print(Text(text), Text(f" ({ms:.1f} ms)", style="dim"))
            return
        shown = render_text(name, text)
        if isinstance(shown, Text):
            self.console.print(shown, Text(f" ({ms:.1f} ms)", style="dim"))
        else:
            self.console.print(shown)
            self.console.print(Text(f"({ms:.1f} ms)", style="dim"))

    async def _write(self, name: str, value: str) -> None:
        t0 = time.perf_counter()
        echo = await self.client.write(name, value)
        ms = (time.perf_counter() - t0) * 1e3
        self.console.print(
            Text("written", style="green"),
            Text(f"{name} = {echo}"),
            Text(f" ({ms:.1f} ms)", style="dim"),
        )

    async def _meta(self, line: str) -> None:
        cmd, *args = line.split()
        if cmd in (":help", ":h", ":?"):
            self.console.print(HELP, highlight=False)
        elif cmd == ":raw":
            self.raw = not self.raw
            self.console.print(f"raw output {'on' if self.raw else 'off'}")
        elif cmd == ":stats":
            s = self.client.stats.snapshot().as_ms()
            self.console.print(
                f"{s['count']:.0f} requests: mean {s['mean']:.2f} ms, median {s['p50']:.2f} ms, "
                f"p99 {s['p99']:.2f} ms, max {s['max']:.2f} ms; reconnects {self.client.reconnects}"
            )
        elif cmd == ":ping":
            await self._guarded(self._ping())
        elif cmd == ":watch":
            hz = 2.0
            if args and _is_number(args[-1]):
                hz = max(0.1, min(100.0, float(args.pop())))
            if not args:
                self.error("usage: :watch NAME [NAME...] [HZ]")
                return
            await self._guarded(self._watch(args, hz))
        else:
            self.error(f"unknown command {cmd} (:help lists them)")

    async def _ping(self) -> None:
        self.console.print(f"PONG ({await self.client.ping() * 1e3:.1f} ms)")

    async def _watch(self, names: list[str], hz: float) -> None:
        from rich.live import Live
        from rich.table import Table

        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        loop.add_signal_handler(signal.SIGINT, stop.set)
        try:
            await self.client.read_many(names)  # fail early: unknown names, connection
            self.console.print(Text(f"watching at {hz:g} Hz — Ctrl-C stops", style="dim"))
            with Live(console=self.console, auto_refresh=False) as live:
                while not stop.is_set():
                    t0 = time.perf_counter()
                    results = await self.client.read_many(names)
                    ms = (time.perf_counter() - t0) * 1e3
                    table = Table(title=f"{ms:.1f} ms", title_justify="left")
                    table.add_column("variable", style="bold cyan")
                    table.add_column("value", overflow="fold")
                    for n, r in results.items():
                        table.add_row(n, r.text if r.ok else f"<{r.error}>")
                    live.update(table, refresh=True)
                    try:
                        await asyncio.wait_for(stop.wait(), 1.0 / hz)
                    except TimeoutError:
                        pass
        finally:
            loop.remove_signal_handler(signal.SIGINT)

    # -------------------------------------------------------------------- errors
    def error(self, message: str) -> None:
        self.console.print(Text(message, style="bold red"))

    async def _guarded(self, job: Any) -> None:
        """Run one command; report errors in one line and keep the session."""
        await self._ensure_connected()
        try:
            await job
        except UnknownVariableError as exc:
            self.error(f"unknown variable: {exc.name!r} on {self.client.endpoint}")
        except WriteRefusedError as exc:
            self.error(
                f"write refused: {exc.name!r} on {self.client.endpoint} (read-only, unknown or wrong type)"
            )
        except KvpTimeoutError as exc:
            self.error(f"timeout: {exc}")
        except KvpConnectionError as exc:
            self.error(f"connection lost: {exc}")
            await self._ensure_connected()
        except KvpError as exc:
            self.error(str(exc))

    async def _ensure_connected(self) -> None:
        if self.client.connected:
            self._was_connected = True
            return
        if self._was_connected:
            self.console.print(
                Text(f"connection to {self.client.endpoint} lost; reconnecting…", style="yellow")
            )
        try:
            await self.client.connect()
        except KvpError as exc:
            self.error(f"still disconnected ({exc}); the next command retries")
            return
        if self._was_connected:
            self.console.print(Text(f"reconnected to {self.client.endpoint}", style="green"))
        self._was_connected = True

    # -------------------------------------------------------------------- input loop
    async def run(self, names: Iterable[str], history: Path) -> None:
        self.console.print(
            f"kvp repl on {self.client.endpoint} — :help for commands, :quit or Ctrl-D to leave",
            highlight=False,
        )
        if sys.stdin.isatty():
            await self._run_prompt(list(names), history)
        else:
            await self._run_pipe()

    async def _run_prompt(self, names: list[str], history: Path) -> None:
        from prompt_toolkit import PromptSession
        from prompt_toolkit.history import FileHistory

        from pyopenshowvar_apps.completion import NameCompleter

        history.parent.mkdir(parents=True, exist_ok=True)
        session: PromptSession[str] = PromptSession(
            history=FileHistory(str(history)),
            completer=NameCompleter(names),
            complete_while_typing=False,
        )
        while True:
            try:
                line = await session.prompt_async("kvp> ")
            except KeyboardInterrupt:
                continue
            except EOFError:
                break
            if not await self.handle(line):
                break

    async def _run_pipe(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            line = await loop.run_in_executor(None, sys.stdin.readline)
            if not line or not await self.handle(line):
                break


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


async def run_repl(
    host: str, port: int, timeout: float, *, names: Iterable[str], history: Path, raw: bool
) -> None:
    """Connect (raises KvpError when the first connection fails) and run the console."""
    client = Client(host, port, timeout=timeout, auto_reconnect=True, keepalive=10.0)
    async with client:
        await Repl(client, Console(highlight=False), raw=raw).run(names, history)
