"""README.md's emulator and snapshot steps run top to bottom, as a user pastes them into a shell.

The two blocks are taken from README.md itself (so the test follows the text) and run, in one
``bash -e``, in an empty directory whose ``.venv`` is this interpreter's environment. Their
port 7000 becomes a free one (the machine may run other emulators); the rest runs as written:
the emulators start in the background and the next line talks to them at once.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
VENV = Path(sys.executable).parent.parent


def readme_block(marker: str) -> str:
    """The fenced block of README.md that contains ``marker``."""
    blocks = re.findall(r"^```[a-z]*\n(.*?)^```", (ROOT / "README.md").read_text(), re.M | re.S)
    found = [b for b in blocks if marker in b]
    assert len(found) == 1, f"{len(found)} README blocks contain {marker!r}"
    return str(found[0])


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def on_port(block: str, port: int) -> str:
    """The block with its emulators on ``port`` instead of 7000 (the default ``kvp`` port
    follows through ``KVP_PORT``)."""
    lines = []
    for line in block.replace("--port 7000", f"--port {port}").splitlines():
        if "kukavarproxy-emu" in line and "--port" not in line:
            line = line.replace("kukavarproxy-emu", f"kukavarproxy-emu --port {port}", 1)
        lines.append(line)
    return "\n".join(lines) + "\n"


def test_the_emulator_and_snapshot_steps_run_top_to_bottom(tmp_path: Path) -> None:
    emulator = readme_block("--latency kvp &")
    snapshot = readme_block("snapshot krl CELL")
    assert "kill $!" in emulator and "kill $!" in snapshot  # each stops what it started
    (tmp_path / ".venv").symlink_to(VENV)
    port = free_port()
    script = "set -e\n" + on_port(emulator, port) + on_port(snapshot, port)
    env = {
        **os.environ,
        "KVP_PORT": str(port),
        # a loaded test machine starts the emulator in seconds, not in one: more patience
        # than the default 2 s, the commands themselves unchanged
        "KVP_TIMEOUT": "60",
    }
    out_file, err_file = tmp_path / "stdout", tmp_path / "stderr"
    with out_file.open("w") as stdout, err_file.open("w") as stderr:
        proc = subprocess.Popen(
            ["bash", "-c", script],
            cwd=tmp_path,
            env=env,
            stdout=stdout,  # files, not pipes: an emulator left running must not hold them
            stderr=stderr,
            start_new_session=True,  # its emulators too: all stopped below whatever happens
        )
        try:
            proc.wait(timeout=240)
        finally:
            try:
                os.killpg(proc.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
    out, err = out_file.read_text(), err_file.read_text()
    assert proc.returncode == 0, out + err
    assert out.count("listening on 127.0.0.1:") == 2  # each emulator started on the port
    assert "{E6AXIS: A1" in out and '"type": "E6POS"' in out  # the plain reads
    assert (tmp_path / "out" / "CELL.dat").is_file() and (tmp_path / "out" / "CELL.sub").is_file()
    cycle = re.search(r"^CYCLE (\d+)$", out, re.M)
    assert cycle and int(cycle.group(1)) >= 1, out  # the SPS ran: the snapshot is filled
    assert re.search(r"^\$POS_ACT \{E6POS: X ", out, re.M)
    assert re.search(r"^\$TORQUE_AXIS_ACT\[\] -?[0-9.]", out, re.M)
