"""A client-only install works, and a command whose extra is missing names the extra.

Each case runs a fresh interpreter in which the optional modules cannot be imported (a
meta-path finder refuses them, as an environment without the extra would), so the test sees
exactly what a user with ``pip install pyopenshowvar`` (numpy only) sees.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from kukavarproxy_emu.emulator_thread import EmulatorThread
from pyopenshowvar.extras import EXTRA_OF, MissingExtraError, explain, require

#: Run before the snippet: refuse ``blocked`` modules as if they were not installed.
BLOCKER = """
import importlib.abc, sys
BLOCKED = set({blocked!r})
class _Refuse(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None
sys.meta_path.insert(0, _Refuse())
"""


def run_without(blocked: set[str], snippet: str, *args: str) -> subprocess.CompletedProcess[str]:
    code = BLOCKER.format(blocked=sorted(blocked)) + textwrap.dedent(snippet)
    return subprocess.run(
        [sys.executable, "-c", code, *args],
        capture_output=True,
        text=True,
        timeout=60,
    )


EVERY_EXTRA = set(EXTRA_OF)


def test_client_library_needs_only_numpy(ideal_emulator_thread: EmulatorThread) -> None:
    """Both clients and the kinematics run with every optional module missing."""
    emu = ideal_emulator_thread
    if True:
        done = run_without(
            EVERY_EXTRA,
            """
            import asyncio, sys
            from pyopenshowvar import Client
            from pyopenshowvar.sync import Client as SyncClient
            from pyopenshowvar.kinematics import KR6R900SIXX, forward
            port = int(sys.argv[1])
            with SyncClient("127.0.0.1", port, timeout=5.0) as kvp:
                print("sync", kvp.read("$OV_PRO"), kvp.read_joint_angles().shape)
            async def main():
                async with Client("127.0.0.1", port, timeout=5.0) as kvp:
                    print("async", await kvp.read("$OV_PRO"))
            asyncio.run(main())
            print("fk", round(float(forward(KR6R900SIXX, [0, -90, 90, 0, 0, 0])[0]), 3))
            """,
            str(emu.port),
        )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split("\n")[:3] == ["sync 100 (6,)", "async 100", "fk 525.0"]


def test_kvp_without_the_apps_extra_names_it() -> None:
    done = run_without(
        {"typer", "rich"},
        """
        import sys
        sys.argv = ["kvp", "read", "$OV_PRO"]
        from pyopenshowvar_apps.entry import main
        main()
        """,
    )
    assert done.returncode == 2
    assert done.stderr.strip() == (
        "kvp: the kvp command line needs typer, which is not installed: "
        "pip install 'pyopenshowvar[apps]'"
    )


def test_kvp_gateway_without_asyncua_names_the_gateway_extra(tmp_path: object) -> None:
    done = run_without(
        {"asyncua"},
        """
        import sys
        sys.argv = ["kvp", "gateway", "cell.toml"]
        from pyopenshowvar_apps.entry import main
        main()
        """,
    )
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip() == (
        "kvp: this command needs asyncua, which is not installed: "
        "pip install 'pyopenshowvar[gateway]'"
    )


def test_emulator_without_mujoco_names_the_extra_and_runs_ideal() -> None:
    dynamic = run_without(
        {"mujoco"},
        """
        from kukavarproxy_emu.__main__ import main
        raise SystemExit(main(["--port", "0"]))
        """,
    )
    assert dynamic.returncode == 1
    assert dynamic.stderr.strip().endswith(
        "kukavarproxy-emu: error: the dynamic plant (the default; --plant ideal needs nothing"
        " more) needs mujoco, which is not installed: pip install 'pyopenshowvar[emulator]'"
    )
    ideal = run_without(
        {"mujoco"},
        """
        import sys, threading
        from kukavarproxy_emu.__main__ import main
        sys.stdout.reconfigure(line_buffering=True)
        # the emulator runs until SIGINT: the first line shows it served, then we stop it
        import os, signal
        threading.Timer(1.0, lambda: os.kill(os.getpid(), signal.SIGINT)).start()
        raise SystemExit(main(["--port", "0", "--plant", "ideal"]))
        """,
    )
    assert ideal.returncode == 0, ideal.stderr
    assert ideal.stdout.startswith("listening on 127.0.0.1:")


def test_explain_maps_only_our_optional_modules() -> None:
    error = explain(ModuleNotFoundError("No module named 'skimage.graph'", name="skimage.graph"))
    assert isinstance(error, MissingExtraError)
    assert (error.name, error.extra) == ("skimage", "apps")
    assert explain(ModuleNotFoundError("x", name="not_ours")) is None
    assert explain(ModuleNotFoundError("x")) is None
    with pytest.raises(ModuleNotFoundError) as info:
        require("definitely_not_installed_xyz", "a test")
    assert not isinstance(info.value, MissingExtraError)
    assert require("json", "a test").__name__ == "json"
