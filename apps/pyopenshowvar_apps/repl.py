"""``kvp repl``: an interactive KRL variable console (JOpenShowVar's console, done better).

* ``NAME`` reads; ``NAME VALUE`` or ``NAME = VALUE`` writes (the value is everything after the
  name, so ``MYAXIS {A1 10.5, A2 -80.0}`` works unquoted); every answer shows the round trip;
* typed pretty printing (``:raw`` toggles the proxy's text instead);
* line editing, persistent history (Enter in a Ctrl-R search runs the line, as in bash) and
  tab completion (prompt_toolkit) on a terminal; plain lines from a pipe, where the exit code
  is the first failed command's (the codes of ``kvp read``/``write``);
* writes are checked like ``kvp write``: the literal before sending, the reason of a refusal,
  a program stop right after (:mod:`pyopenshowvar_apps.writecheck`);
* ``:watch NAME... [HZ]`` live until Ctrl-C, ``:stats``, ``:ping``, ``:help``, ``:quit``/``q``;
  Ctrl-C while a command waits abandons it and returns to the prompt;
* the connection is kept alive (``PING`` every 10 s) and re-opened after a drop, with ONE
  message per drop, without leaving the session.
"""

from __future__ import annotations

import asyncio
import os
import signal
import sys
import time
from collections.abc import Coroutine, Iterable
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
from pyopenshowvar_apps.common import (
    EXIT_CONNECTION,
    EXIT_PROTOCOL,
    EXIT_STOPPED,
    EXIT_TIMEOUT,
    EXIT_USAGE,
    EXIT_VARIABLE,
)
from pyopenshowvar_apps.pretty import render_text
from pyopenshowvar_apps.writecheck import STOP_WINDOW, check_literal, checked_write

HELP = """\
[bold]NAME[/]                read a variable, e.g. [cyan]$AXIS_ACT[/], [cyan]$TORQUE_AXIS_ACT[][/], [cyan]$POS_ACT.X[/]
[bold]NAME VALUE[/]          write a KRL literal, e.g. [cyan]MYAXIS {A1 10.5, A2 -80.0}[/]
[bold]NAME = VALUE[/]        the same
[bold]:watch NAME... [HZ][/] live values until Ctrl-C (default 2 Hz)
[bold]:raw[/]                toggle raw text / typed tables
[bold]:stats[/]              access-time statistics of this session
[bold]:ping[/]               one keep-alive round trip
[bold]:help[/]               this text
[bold]:quit[/], [bold]q[/], Ctrl-D    leave
Tab completes variable names; ↑/↓ and Ctrl-R search the history (Enter runs the line found).
Ctrl-C abandons a command that waits."""


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

    def __init__(
        self,
        client: Client,
        console: Console,
        *,
        raw: bool = False,
        stop_window: float = STOP_WINDOW,
    ) -> None:
        self.client = client
        self.console = console
        self.raw = raw
        self.stop_window = stop_window
        #: Exit code of the first command that failed (a piped script exits with it).
        self.failure: int | None = None
        self._was_connected = False
        self._lost_reported = False
        self._writing: str | None = None
        self._quiet_reconnect = False

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
            self.fail(
                EXIT_USAGE, f"missing value after {name!r} (write: NAME VALUE or NAME = VALUE)"
            )
            return True
        if value is not None and (problem := check_literal(value)) is not None:
            lines = problem.lines(value)
            self.fail(EXIT_USAGE, f"not a KRL literal: {lines[0]}", *lines[1:])
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
        self._writing = name
        try:
            outcome = await checked_write(self.client, name, value, window=self.stop_window)
        finally:
            self._writing = None
        # the write's round trip, not the --stop-window watch after it
        self.console.print(
            Text("written", style="green"),
            Text(f"{name} = {outcome.echo}"),
            Text(f" ({outcome.seconds * 1e3:.1f} ms)", style="dim"),
        )
        if outcome.stop is not None:
            self.fail(EXIT_STOPPED, f"the robot program stopped: {outcome.stop.describe()}")

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
                self.fail(EXIT_USAGE, "usage: :watch NAME [NAME...] [HZ]")
                return
            await self._guarded(self._watch(args, hz))
        else:
            self.fail(EXIT_USAGE, f"unknown command {cmd} (:help lists them)")

    async def _ping(self) -> None:
        self.console.print(f"PONG ({await self.client.ping() * 1e3:.1f} ms)")

    async def _watch(self, names: list[str], hz: float) -> None:
        from rich.live import Live
        from rich.table import Table

        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        loop.add_signal_handler(signal.SIGINT, stop.set)
        try:
            first = await self.client.read_many(names)  # fail early: unknown names, connection
            for r in first.values():
                if r.error is not None:
                    raise r.error
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
    def fail(self, code: int, message: str, *more: str) -> None:
        """Report a failed command (one red line, plus e.g. a caret line) and remember it."""
        if self.failure is None:
            self.failure = code
        self.console.print(Text(message, style="bold red"))
        for line in more:
            self.console.print(Text(line), highlight=False)

    async def _guarded(self, job: Coroutine[Any, Any, None]) -> None:
        """Run one command; report errors in one line and keep the session."""
        if not await self._ensure_connected():
            job.close()
            return
        try:
            await job
        except UnknownVariableError as exc:
            self.fail(EXIT_VARIABLE, f"unknown variable: {exc.name!r} on {self.client.endpoint}")
        except WriteRefusedError as exc:
            self.fail(EXIT_VARIABLE, str(exc))
        except KvpTimeoutError as exc:
            self.fail(EXIT_TIMEOUT, f"timeout: {exc}")
        except KvpConnectionError as exc:
            # One message for the drop; the next command reconnects without another.
            self._lost_reported = True
            self.fail(EXIT_CONNECTION, f"connection lost: {exc}; the next command reconnects")
        except KvpError as exc:
            self.fail(EXIT_PROTOCOL, str(exc))

    async def _ensure_connected(self) -> bool:
        """Connected (reconnecting if needed)? At most one line says what happened."""
        if self.client.connected:
            self._was_connected = True
            return True
        try:
            await self.client.connect()
        except KvpError as exc:
            self._quiet_reconnect = False
            if self._lost_reported:
                message = f"still not connected to {self.client.endpoint}: {exc}"
            else:
                message = f"connection to {self.client.endpoint} lost and not back: {exc}"
            self._lost_reported = True
            self.fail(EXIT_CONNECTION, f"{message} (the next command tries again)")
            return False
        if self._was_connected and not (self._quiet_reconnect or self._lost_reported):
            # the drop was not reported yet: this is its one message
            self.console.print(
                Text(
                    f"reconnected to {self.client.endpoint} after a lost connection", style="yellow"
                )
            )
        self._was_connected = True
        self._lost_reported = self._quiet_reconnect = False
        return True

    # -------------------------------------------------------------------- input loop
    async def run(self, names: Iterable[str], history: Path) -> None:
        self.console.print(
            f"kvp repl on {self.client.endpoint} — :help for commands, :quit or Ctrl-D to leave",
            highlight=False,
        )
        if sys.stdin.isatty():
            await self._run_prompt(names, history)
        else:
            await self._run_pipe()

    async def _run_prompt(self, names: Iterable[str], history: Path) -> None:
        from prompt_toolkit import PromptSession
        from prompt_toolkit.history import FileHistory
        from prompt_toolkit.key_binding import KeyBindings
        from prompt_toolkit.key_binding.bindings.search import accept_search_and_accept_input

        from pyopenshowvar_apps.completion import NameCompleter

        keys = KeyBindings()
        # Enter in a Ctrl-R search runs the line found, as bash does (prompt_toolkit's default
        # only ends the search and leaves the line for editing).
        keys.add("enter")(accept_search_and_accept_input)
        history.parent.mkdir(parents=True, exist_ok=True)
        session: PromptSession[str] = PromptSession(
            history=FileHistory(str(history)),
            completer=NameCompleter(names),
            complete_while_typing=False,
            key_bindings=keys,
        )
        while True:
            try:
                line = await session.prompt_async("kvp> ")
            except KeyboardInterrupt:
                continue
            except EOFError:
                break
            if not await self._interruptible(line):
                break

    async def _interruptible(self, line: str) -> bool:
        """Run one line; Ctrl-C (SIGINT while no prompt is shown) abandons it."""
        loop = asyncio.get_running_loop()
        task = loop.create_task(self.handle(line))
        loop.add_signal_handler(signal.SIGINT, task.cancel)
        try:
            return await task
        except asyncio.CancelledError:
            if not task.cancelled():
                raise
            if self._writing is not None:
                self.console.print(
                    Text(
                        f"interrupted: the write to {self._writing} may or may not have been "
                        "applied (read it to see)",
                        style="yellow",
                    )
                )
                self._writing = None
            else:
                self.console.print(Text("interrupted", style="yellow"))
            # KUKAVARPROXY answers in order: the abandoned reply would hold up the next
            # command on this connection, so start the next one on a fresh connection.
            await self.client.close()
            self._quiet_reconnect = True
            return True
        finally:
            loop.remove_signal_handler(signal.SIGINT)

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
    host: str,
    port: int,
    timeout: float,
    *,
    names: Iterable[str],
    history: Path,
    raw: bool,
    stop_window: float = STOP_WINDOW,
) -> int:
    """Connect (raises KvpError when the first connection fails) and run the console.

    Returns the exit code: 0 on a terminal; from a pipe, the first failed command's code.
    """
    client = Client(host, port, timeout=timeout, auto_reconnect=True, keepalive=10.0)
    # soft_wrap: a line is printed as one line (the terminal wraps it, a pipe keeps it whole);
    # tables still fit the console width.
    console = Console(highlight=False, soft_wrap=True)
    async with client:
        repl = Repl(client, console, raw=raw, stop_window=stop_window)
        await repl.run(names, history)
    if sys.stdin.isatty():
        return 0
    return repl.failure or 0
