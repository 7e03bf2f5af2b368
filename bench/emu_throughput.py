"""Requests per second the emulator serves at latency "none", with 1 and 10 clients.

Starts ``python -m kukavarproxy_emu --port 0`` in a subprocess (so client and server do not
share a GIL), then drives it from raw non-blocking sockets: each client keeps ``--depth``
requests in flight (send a batch, read the batch's replies, repeat) for ``--seconds``.

    .venv/bin/python bench/emu_throughput.py [--clients 1 10] [--depth 4] [--seconds 3]
"""

from __future__ import annotations

import argparse
import asyncio
import socket
import subprocess
import sys
import time

from pyopenshowvar.protocol import ReplyDecoder, encode_read


async def client(host: str, port: int, depth: int, stop_at: float) -> int:
    loop = asyncio.get_running_loop()
    sock = socket.create_connection((host, port))
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    sock.setblocking(False)
    batch = b"".join(encode_read(i, "$OV_PRO" if i % 2 else "$AXIS_ACT") for i in range(depth))
    decoder = ReplyDecoder()
    done = 0
    try:
        while time.perf_counter() < stop_at:
            await loop.sock_sendall(sock, batch)
            got = 0
            while got < depth:
                got += len(decoder.feed_replies(await loop.sock_recv(sock, 65536)))
            done += depth
    finally:
        sock.close()
    return done


async def run(host: str, port: int, clients: int, depth: int, seconds: float) -> float:
    start = time.perf_counter()
    counts = await asyncio.gather(
        *(client(host, port, depth, start + seconds) for _ in range(clients))
    )
    return sum(counts) / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clients", type=int, nargs="+", default=[1, 10])
    parser.add_argument("--depth", type=int, default=4, help="requests in flight per client")
    parser.add_argument("--seconds", type=float, default=3.0)
    args = parser.parse_args()
    proc = subprocess.Popen(
        [sys.executable, "-m", "kukavarproxy_emu", "--port", "0", "--idle-timeout", "0"],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        host, _, port = proc.stdout.readline().removeprefix("listening on ").strip().rpartition(":")
        for n in args.clients:
            rate = asyncio.run(run(host, int(port), n, args.depth, args.seconds))
            print(f"{n:3d} client(s), depth {args.depth}: {rate:10,.0f} requests/s", flush=True)
    finally:
        proc.terminate()
        proc.wait(timeout=10)


if __name__ == "__main__":
    main()
