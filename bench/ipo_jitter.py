"""IPO tick jitter of the emulator's simulated robot, idle and under load from 10 clients.

The emulator (robot on, real time, 12 ms cycle, latency none) runs in this process's event
loop; the load comes from 10 raw-socket clients in a subprocess, each keeping 4 requests in
flight (reads of $AXIS_ACT/$POS_ACT, writes of MYAXIS so the robot moves). Jitter = actual −
scheduled wall time of each tick. Plain script:

    python bench/ipo_jitter.py [--seconds 5]
"""

from __future__ import annotations

import argparse
import asyncio
import subprocess
import sys
import textwrap

from kukavarproxy_emu import Emulator, EmulatorConfig

LOAD = textwrap.dedent(
    """
    import asyncio, sys
    from pyopenshowvar.protocol import encode_read, encode_write
    PORT, SECONDS = int(sys.argv[1]), float(sys.argv[2])
    async def client(k):
        r, w = await asyncio.open_connection("127.0.0.1", PORT)
        names = ["$AXIS_ACT", "$POS_ACT", "$TORQUE_AXIS_ACT[]", "$OV_PRO"]
        n, loop = 0, asyncio.get_running_loop()
        end = loop.time() + SECONDS
        async def one(i):
            if k == 0 and i % 50 == 0:
                a1 = 30.0 if (i // 50) % 2 else -30.0
                w.write(encode_write(i & 0xFFFF, "MYAXIS", "{A1 %r}" % a1))
            else:
                w.write(encode_read(i & 0xFFFF, names[i % 4]))
        for i in range(4):
            await one(i)
        i = 4
        while loop.time() < end:
            head = await r.readexactly(4)
            await r.readexactly(int.from_bytes(head[2:4], "big"))
            n += 1
            await one(i); i += 1
        w.close()
        return n
    async def main():
        counts = await asyncio.gather(*(client(k) for k in range(10)))
        print(sum(counts))
    asyncio.run(main())
    """
)


async def main(seconds: float) -> None:
    async with Emulator(EmulatorConfig(port=0, discovery=False)) as emu:
        robot = emu.robot
        assert robot is not None
        await asyncio.sleep(0.5)  # warm-up (first ticks pay for lazy imports)
        robot.clock.reset_stats()
        await asyncio.sleep(seconds)
        idle = robot.jitter()
        robot.clock.reset_stats()
        proc = await asyncio.create_subprocess_exec(
            sys.executable,
            "-c",
            LOAD,
            str(emu.port),
            str(seconds),
            stdout=subprocess.PIPE,
        )
        out, _ = await proc.communicate()
        loaded = robot.jitter()
        requests = int(out.decode().strip() or 0)
    print(f"ipo 12 ms, real time, {seconds:g} s each")
    print(f"idle:              {idle}")
    print(f"10 clients loaded: {loaded}  ({requests / seconds:.0f} requests/s)")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=5.0)
    asyncio.run(main(parser.parse_args().seconds))
