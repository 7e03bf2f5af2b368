"""The KUKAVARPROXY emulator in a process of its own, with its robot's state shared for measuring.

A real set-up has the KRC, the PLC and the control PC on separate hardware; the embedded
experiment keeps the emulator out of the control server's process the same way, so the two do
not share one interpreter lock (a moving robot costs the emulator several milliseconds per 12 ms
cycle). The child (``python -m pyopenshowvar_apps.heave.emuproc``) runs an
:class:`~kukavarproxy_emu.emulator_thread.EmulatorThread` and, on the emulator's own event loop, copies
the simulated robot's state every few milliseconds into a small memory-mapped file: time, axes,
flange pose in the base frame (the plant's ground truth when the emulator runs a dynamic plant).
:meth:`EmulatorProcess.robot_state` reads it without locks (a sequence counter detects a torn
read). This is the simulator's own state, never a variable the controller publishes. The child
exits when its standard input closes, so it never outlives the parent.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import mmap
import os
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any, Self

import numpy as np

from .geometry import FloatArray

__all__ = ["EmulatorProcess", "robot_state_of"]

#: seq, wall time, robot time, q1..q6, the 3×4 top of the flange pose
_SLOTS = 3 + 6 + 12


def robot_state_of(robot: Any, model: Any) -> tuple[FloatArray, FloatArray, float]:
    """Axes (deg), flange pose in the base frame (4×4) and the robot's own clock (s) of an
    emulator's robot: the physical robot's ground truth when the emulator runs a plant
    (``robot.plant.truth``), else the interpolator's axes (the ideal plant: the robot is exactly
    where it is commanded)."""
    from pyopenshowvar.kinematics import fk_matrix

    sync = getattr(robot, "sync", None)
    if sync is not None:
        sync()  # a robot coasting at rest runs its due ticks first (kukavarproxy_emu.motion.clock)
    truth = getattr(getattr(robot, "plant", None), "truth", None)
    if truth is not None:
        return np.asarray(truth.q, float), np.asarray(truth.flange, float), float(truth.time)
    q = np.asarray(robot.q, float)
    return q, np.asarray(fk_matrix(model, q), float), float(robot.time)


class EmulatorProcess:
    """``with EmulatorProcess(program=..., latency="kvp") as emu: emu.port, emu.robot_state()``."""

    def __init__(
        self,
        *,
        program: str,
        latency: str = "kvp",
        seed: int | None = None,
        plant: str = "dynamic",
        sample: float = 0.003,
        start_timeout: float = 30.0,
    ) -> None:
        self.program, self.latency, self.seed, self.plant = program, latency, seed, plant
        self.sample, self.start_timeout = sample, start_timeout
        self.port = 0
        self._proc: subprocess.Popen[str] | None = None
        self._file: Any = None
        self._map: mmap.mmap | None = None
        self._view: FloatArray | None = None
        self._last: FloatArray = np.zeros(_SLOTS - 1)

    def start(self) -> Self:
        self._file = tempfile.NamedTemporaryFile(prefix="heave-robot-", suffix=".state")
        self._file.write(b"\0" * (8 * _SLOTS))
        self._file.flush()
        self._map = mmap.mmap(self._file.fileno(), 8 * _SLOTS)
        self._view = np.ndarray((_SLOTS,), dtype=np.float64, buffer=self._map)
        args = [sys.executable, "-m", __name__, "--state", self._file.name, "--program", self.program,
                "--latency", self.latency, "--sample", str(self.sample), "--plant", self.plant]  # fmt: skip
        if self.seed is not None:
            args += ["--seed", str(self.seed)]
        # its own session: Ctrl-C in the terminal goes to the experiment, which stops the child
        # in order (closing its stdin), and the scheduler treats it as the separate machine it is
        self._proc = subprocess.Popen(
            args,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        line = self._first_line()
        if not line.startswith("port "):
            err = self._proc.stderr.read() if self._proc.stderr else ""
            self.stop()
            raise RuntimeError(f"the emulator process failed: {(line + err).strip()[-400:]}")
        self.port = int(line.split()[1])
        deadline = time.monotonic() + 5.0
        while self._view[0] < 2.0 and time.monotonic() < deadline:
            time.sleep(0.005)
        return self

    def _first_line(self) -> str:
        assert self._proc is not None and self._proc.stdout is not None
        stdout = self._proc.stdout
        out: list[str] = []
        reader = threading.Thread(target=lambda: out.append(stdout.readline()), daemon=True)
        reader.start()
        reader.join(self.start_timeout)
        if not out:
            self.stop()
            raise TimeoutError("the emulator process did not start in time")
        return out[0]

    def stop(self) -> None:
        proc, self._proc = self._proc, None
        if proc is not None:
            with contextlib.suppress(OSError):
                if proc.stdin is not None:
                    proc.stdin.close()  # the child's signal to stop
            try:
                proc.wait(timeout=10.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5.0)
            for stream in (proc.stdout, proc.stderr):
                if stream is not None:
                    stream.close()
        self._view = None
        if self._map is not None:
            self._map.close()
            self._map = None
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def robot_state(self) -> tuple[FloatArray, FloatArray, float]:
        """The robot's axes (deg), flange pose in its base frame (4×4) and its own clock (s,
        one step per interpolation cycle) as last sampled."""
        view = self._view
        if view is None:
            raise RuntimeError("the emulator process is not running")
        for attempt in range(50):
            seq = view[0]
            values = view[1:].copy()
            if seq == view[0] and int(seq) % 2 == 0:
                self._last = values
                break
            time.sleep(0 if attempt < 10 else 0.001)  # the writer was preempted mid-write
        else:  # a writer stuck mid-write (a stalled machine): the last consistent sample
            values = self._last
        flange = np.eye(4)
        flange[:3] = values[8:20].reshape(3, 4)
        return values[2:8], flange, float(values[1])


def _serve(args: argparse.Namespace) -> None:
    from kukavarproxy_emu import EmulatorConfig, EmulatorThread
    from pyopenshowvar.kinematics import KR6R900SIXX

    config = EmulatorConfig(
        host="127.0.0.1", port=0, program=args.program, latency=args.latency,
        seed=args.seed, discovery=False, plant=args.plant,
    )  # fmt: skip
    with open(args.state, "r+b") as fh, EmulatorThread(config) as emu:
        shared = np.ndarray((_SLOTS,), dtype=np.float64, buffer=mmap.mmap(fh.fileno(), 8 * _SLOTS))
        robot = emu.emulator.robot
        if robot is None:
            raise RuntimeError("the emulator runs without a robot")

        def write() -> None:
            q, flange, robot_time = robot_state_of(robot, KR6R900SIXX)
            shared[0] += 1.0  # odd: being written
            shared[1] = time.monotonic()  # CLOCK_MONOTONIC: the same clock in every process
            shared[2] = robot_time
            shared[3:9] = q
            shared[9:21] = flange[:3].ravel()
            shared[0] += 1.0  # even: consistent

        async def sampler() -> None:
            while True:
                write()
                await asyncio.sleep(args.sample)

        emu.call(lambda: asyncio.ensure_future(sampler()))
        print(f"port {emu.port}", flush=True)
        sys.stdin.read()  # until the parent closes our stdin (or dies)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description="emulator child of the heave experiment")
    ap.add_argument("--state", required=True)
    ap.add_argument("--program", required=True)
    ap.add_argument("--latency", default="kvp")
    ap.add_argument("--seed", type=int, default=None)
    ap.add_argument("--sample", type=float, default=0.003)
    ap.add_argument("--plant", default="dynamic")
    try:
        _serve(ap.parse_args(argv))
    except KeyboardInterrupt:  # pragma: no cover
        pass
    except BaseException as exc:
        print(f"error {type(exc).__name__}: {exc}", flush=True)
        os._exit(1)


if __name__ == "__main__":
    main()
