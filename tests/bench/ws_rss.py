#!/usr/bin/env python3
"""The resident memory of `pavlov serve` with 0, 50 and 100 websocket clients that read everything.

Usage: tests/bench/ws_rss.py PAVLOV_BINARY [--settle SECONDS] [--counts 0,50,100] [--shipped]

Starts `pavlov serve` (the simulated Create, config/stall.toml with room for 128 operators) on an
ephemeral loopback port, then for each count opens that many websocket connections, each a plain socket
that reads every byte the server sends (the frames are not parsed: reading the bytes is what makes the
server write them), waits `--settle` seconds, and prints the server's VmRSS and VmHWM from /proc, and the
server's CPU time (user + system) over those seconds beside their wall time. Clients are held open across
counts (50 then 50 more), so each figure is the server with that many readers; the last line gives the
cost of a client, (RSS at the largest count - RSS at the smallest) / the clients added. With `--shipped`
it is `pavlov serve --bind 127.0.0.1:PORT`, the built-in configuration (config/stall.toml) as shipped:
its seat limits then hold (32 operators), so use counts up to 32. The clients run in this process, not the server's, so the figures
are the server's alone. Standard library only, so it runs without the test venv.
"""

import argparse
import base64
import os
import selectors
import socket
import subprocess
import sys
import tempfile
import time

CONFIG_EXTRA = """
[dashboard]
bind = "127.0.0.1:{port}"
max_operators = 128
max_pending = 256
max_pending_per_address = 256
"""


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cpu_seconds(pid):
    """The process's user + system CPU time so far, seconds."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def status(pid):
    out = {}
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            key, _, value = line.partition(":")
            if key in ("VmRSS", "VmHWM"):
                out[key] = int(value.split()[0])
    return out


def connect(port):
    s = socket.create_connection(("127.0.0.1", port), timeout=10)
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall(
        (
            f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
            "Sec-WebSocket-Protocol: pavlov.v1\r\n\r\n"
        ).encode()
    )
    head = b""
    while b"\r\n\r\n" not in head:
        chunk = s.recv(4096)
        if not chunk:
            raise RuntimeError("connection closed during the handshake")
        head += chunk
    if not head.startswith(b"HTTP/1.1 101"):
        raise RuntimeError(head.split(b"\r\n")[0].decode())
    s.setblocking(False)
    return s


def read_for(sel, seconds):
    """Reads every socket until `seconds` have passed; returns the bytes read."""
    total = 0
    end = time.monotonic() + seconds
    while (left := end - time.monotonic()) > 0:
        for key, _ in sel.select(timeout=min(left, 0.2)):
            try:
                data = key.fileobj.recv(65536)
            except BlockingIOError:
                continue
            if not data:
                sel.unregister(key.fileobj)
            total += len(data)
    return total


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("binary")
    ap.add_argument("--settle", type=float, default=10.0)
    ap.add_argument("--counts", default="0,50,100")
    ap.add_argument(
        "--shipped",
        action="store_true",
        help="`pavlov serve --bind`: the built-in configuration as shipped, its own seat limits",
    )
    args = ap.parse_args()
    counts = [int(c) for c in args.counts.split(",")]
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    port = free_port()
    with open(os.path.join(repo, "config", "stall.toml")) as f:
        config = f.read()
    config += CONFIG_EXTRA.format(port=port)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "rss.toml")
        with open(path, "w") as f:
            f.write(config)
        if args.shipped:
            command = [args.binary, "serve", "--bind", f"127.0.0.1:{port}"]
        else:
            command = [args.binary, "serve", "--config", path]
        server = subprocess.Popen(
            command,
            cwd=tmp,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            deadline = time.monotonic() + 60
            while True:
                try:
                    socket.create_connection(("127.0.0.1", port), timeout=1).close()
                    break
                except OSError:
                    if time.monotonic() > deadline or server.poll() is not None:
                        sys.exit("the server did not start")
                    time.sleep(0.2)
            sel = selectors.DefaultSelector()
            clients = []
            load = open("/proc/loadavg").read().split()[:3]
            print(f"load average at the start: {' '.join(load)}")
            rss = {}
            for n in counts:
                while len(clients) < n:
                    s = connect(port)
                    clients.append(s)
                    sel.register(s, selectors.EVENT_READ)
                cpu0, wall0 = cpu_seconds(server.pid), time.monotonic()
                read = read_for(sel, args.settle)
                cpu, wall = cpu_seconds(server.pid) - cpu0, time.monotonic() - wall0
                st = status(server.pid)
                rss[n] = st["VmRSS"]
                alive = len(sel.get_map())
                print(
                    f"{n:4} clients ({alive} reading, {read / args.settle / 1024:8.1f} KiB/s read): "
                    f"VmRSS {st['VmRSS'] / 1024:6.1f} MiB, VmHWM {st['VmHWM'] / 1024:6.1f} MiB; "
                    f"server CPU {cpu:5.2f} s in {wall:5.2f} s wall ({100 * cpu / wall:4.1f} %)"
                )
            low, high = min(counts), max(counts)
            if high > low:
                per = (rss[high] - rss[low]) * 1024 / (high - low) / 1000
                print(f"a reading client costs {per:.0f} kB (VmRSS, {low} to {high} clients)")
            load = open("/proc/loadavg").read().split()[:3]
            print(f"load average at the end: {' '.join(load)}")
        finally:
            server.terminate()
            server.wait(timeout=30)


if __name__ == "__main__":
    main()
