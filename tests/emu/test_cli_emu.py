"""The emulator's command line: a real subprocess, the first stdout line, SIGTERM exit 0."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from kukavarproxy_emu.__main__ import build_parser, config_from_args, main
from kukavarproxy_emu.faults import Fault
from pyopenshowvar.protocol import ReplyDecoder, encode_read

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")


def start(*args: str) -> tuple[subprocess.Popen[str], str, int]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "kukavarproxy_emu", "--port", "0", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    assert proc.stdout is not None
    line = proc.stdout.readline()
    assert line.startswith("listening on "), (line, proc.stderr.read() if proc.stderr else "")
    host, _, port = line.removeprefix("listening on ").strip().rpartition(":")
    return proc, host, int(port)


def read(host: str, port: int, name: str) -> str:
    with socket.create_connection((host, port), timeout=5) as sock:
        sock.sendall(encode_read(1, name))
        decoder = ReplyDecoder()
        while not (replies := decoder.feed_replies(sock.recv(4096))):
            pass
    assert replies[0].ok
    return replies[0].text


def test_subprocess_serves_and_stops_on_sigterm(tmp_path: Path) -> None:
    dat = tmp_path / "extra.dat"
    dat.write_text("DEFDAT $CONFIG\nDECL INT CLI_TEST=42\nENDDAT\n")
    proc, host, port = start("--config", str(dat), "--latency", "kvp", "--seed", "1")
    try:
        assert host == "127.0.0.1" and port > 0
        assert read(host, port, "$AXIS_ACT").startswith("{E6AXIS: A1 ")
        assert read(host, port, "CLI_TEST") == "42"
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
    finally:
        proc.kill()
        proc.wait()


def test_sigint_is_a_clean_exit_too() -> None:
    proc, host, port = start()
    try:
        assert read(host, port, "PING") == "PONG"
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=10) == 0
    finally:
        proc.kill()
        proc.wait()


def test_parse_all_options() -> None:
    args = build_parser().parse_args(
        "--host 0.0.0.0 --port 7001 --latency thesis --max-clients 3 --idle-timeout 0"
        " --seed 5 --strict --quirks legacy-ids --quirks no-ping --udp-port 16999"
        " --udp-reply-port 0 --no-discovery --fault drop:3 --fault delay:0.5@2"
        " --log-level debug".split()
    )
    config = config_from_args(args)
    assert (config.host, config.port, config.max_clients, config.idle_timeout) == (
        "0.0.0.0",
        7001,
        3,
        0,
    )
    assert config.latency == "thesis" and config.seed == 5 and config.strict
    assert config.quirks == {"legacy-ids", "no-ping"}
    assert (config.udp_port, config.udp_reply_port, config.discovery) == (16999, 0, False)
    assert config.faults == (Fault("drop", nth=3), Fault("delay", nth=2, seconds=0.5))


def test_defaults() -> None:
    config = config_from_args(build_parser().parse_args([]))
    assert (config.host, config.port, config.client_limit, config.idle_limit) == (
        "127.0.0.1",
        7000,
        10,
        30.0,
    )
    assert config.discovery_enabled and config.latency_profile is None
    assert config.robot_program == "follow"
    c3 = config_from_args(build_parser().parse_args(["--proxy", "c3bridge"]))
    # C3 Bridge has no client or idle limits; the emulator keeps 64 clients, and no program
    # runs until a client selects one
    assert (c3.client_limit, c3.idle_limit, c3.robot_program, c3.strict) == (64, 0.0, "none", True)


@pytest.mark.parametrize(
    "argv", [["--latency", "warp"], ["--quirks", "bogus"], ["--fault", "explode"], ["--port", "x"]]
)
def test_bad_options_exit_2(argv: list[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2


def test_port_in_use_exits_1() -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        assert main(["--port", str(port), "--no-discovery"]) == 1
