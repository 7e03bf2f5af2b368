"""`kvp web` as a user runs it: first line, token and QR code, refusal without the token, Ctrl-C."""

from __future__ import annotations

import asyncio
import json
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import websockets
from pyopenshowvar_apps.cli import app
from typer.testing import CliRunner
from websockets.asyncio.client import connect

from pyopenshowvar import Client

KVP = str(Path(sys.executable).with_name("kvp"))


def _read_banner(proc: subprocess.Popen[str]) -> list[str]:
    assert proc.stdout is not None
    lines = []
    while not lines or not lines[-1].startswith("Ctrl-C"):
        line = proc.stdout.readline()
        assert line, f"kvp web ended early: {lines}"
        lines.append(line.rstrip("\n"))
    return lines


@pytest.mark.timeout(90)
async def test_kvp_web_beyond_loopback_needs_the_token() -> None:
    proc = subprocess.Popen(  # noqa: ASYNC220 - started once, read in a thread below
        [KVP, "--emulate", "web", "--bind", "0.0.0.0", "--http-port", "0"],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        lines = await asyncio.to_thread(_read_banner, proc)
        first = re.fullmatch(r"serving on http://0\.0\.0\.0:(\d+)/", lines[0])
        assert first, lines[0]
        port = int(first.group(1))
        kvp_port = int(re.search(r"KVP 127\.0\.0\.1:(\d+)", lines[1]).group(1))  # type: ignore[union-attr]
        token = next(line for line in lines if line.startswith("token: ")).split()[1]
        assert any(f":{port}/#token={token}" in line for line in lines)
        assert sum("█" in line or "▀" in line or "▄" in line for line in lines) > 10  # QR
        with pytest.raises(websockets.exceptions.InvalidStatus):
            await connect(f"ws://127.0.0.1:{port}/ws")
        async with (
            connect(f"ws://127.0.0.1:{port}/ws?token={token}", max_queue=None) as ws,
            Client("127.0.0.1", kvp_port) as kvp,
        ):
            assert json.loads(await ws.recv())["t"] == "hello"
            # the pad jogs once KVP_JOG runs and is seen (patient: a loaded machine starts the
            # emulator's program and the pad's first state later)
            async with asyncio.timeout(45):
                while await kvp.read("JOG_MODE") != "1":
                    await ws.send(json.dumps({"t": "jog", "press": 1, "frame": "axis",
                                              "key": "A3", "dir": -1}))  # fmt: skip
                    await asyncio.sleep(0.025)
            await ws.send(json.dumps({"t": "release"}))
            async with asyncio.timeout(20):
                while await kvp.read("JOG_MODE") != "0":  # noqa: ASYNC110 - polling over KVP
                    await asyncio.sleep(0.02)
        proc.send_signal(signal.SIGINT)
        assert proc.wait(10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_krl_dir_writes_the_program_and_its_globals(tmp_path: Path) -> None:
    result = CliRunner().invoke(app, ["web", "--krl-dir", str(tmp_path)])
    assert result.exit_code == 0, result.output
    src = (tmp_path / "kvp_jog.src").read_text()
    dat = (tmp_path / "kvp_jog_config.dat").read_text()
    assert "DEF KVP_JOG()" in src and "DECL INT JOG_UNTIL=0" in dat


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--hz", "0"], "--hz"),
        (["--token", "short"], "--token"),
        (["--http-port", "70000"], "port"),
    ],
)
def test_bad_options_exit_2(args: list[str], message: str) -> None:
    result = CliRunner().invoke(app, ["web", *args])
    assert result.exit_code == 2
    assert message in result.output
