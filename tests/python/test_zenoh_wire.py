"""The Zenoh wire as a lab's Python script sees it, with the `eclipse-zenoh` package (pinned in
tests/python/requirements-zenoh.txt; tests/run.sh installs it into the venv target/py-zenoh and runs this file).

Two simulated robots (`pavlov serve --zenoh`, robots alpha and beta) and one `pavlov fleet`, all Zenoh peers on
127.0.0.1 with explicit listen/connect endpoints and no scouting, so the topology is fixed. This script is a
fourth peer that connects to all three. It checks what docs/src/zenoh-wire.md promises:

- both robots' ticks arrive on `pavlov/v1/<robot>/tick`, declared `application/json`, with an HLC timestamp
  and the stream's publication number as an 8-byte attachment;
- a wildcard query `pavlov/v1/*/config` with Zenoh's default consolidation gets one reply per robot, each
  under the robot's own key;
- a command with alpha's token is applied; a wrong token gets an error reply, JSON, naming alpha;
- a 10 MB command is never delivered: no reply, nothing counted by the bridge, and Zenoh's drop counted in
  alpha's `pavlov_zenoh_oversized_dropped_total`;
- 300 made-up robot names published into the fleet's key space leave alpha and beta visible (alive), and a
  robot started after the flood (gamma) appears; beta stopped shows as departed.

Every wait is a deadline that ends as soon as its condition holds, generous for a loaded CI machine.
Needs PAVLOV_BIN: a `pavlov` built with the zenoh feature.
"""

import json
import os
import queue
import shutil
import signal
import socket
import subprocess
import tempfile
import threading
import time
import unittest
import urllib.request

import zenoh

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
# Absolute: the robots run in a temporary folder of their own, where a relative path would not resolve.
PAVLOV = os.path.abspath(os.environ.get("PAVLOV_BIN", os.path.join(REPO, "target", "debug", "pavlov")))
WAIT = 90.0  # seconds: a bound on waiting, not a performance target
ALPHA_TOKEN = "alpha-Tok3n-q8Zr2Lm9Vx4W"
BETA_TOKEN = "beta-Tok3n-H7pK1sD6nB3Y"


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def endpoint(port):
    return f"tcp/127.0.0.1:{port}"


def zenoh_file(path, listen, connect):
    config = {
        "mode": "peer",
        "listen": {"endpoints": listen},
        "connect": {"endpoints": connect},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
    }
    with open(path, "w") as f:
        json.dump(config, f)
    return config


def until(what, check, timeout=WAIT, every=0.2):
    """Polls `check` until it returns a true value, which is returned; fails naming `what` after `timeout`."""
    deadline = time.monotonic() + timeout
    last = None
    while time.monotonic() < deadline:
        last = check()
        if last:
            return last
        time.sleep(every)
    raise AssertionError(f"{what}: not within {timeout} s (last: {last!r})")


class Proc:
    """A pavlov process whose stdout lines are read by a thread; stopped with SIGTERM."""

    def __init__(self, args, cwd):
        self.p = subprocess.Popen(
            [PAVLOV, *args], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True
        )
        self.lines = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.p.stdout:
            self.lines.put(line.rstrip("\n"))

    def wait_line(self, prefix):
        deadline = time.monotonic() + WAIT
        while True:
            left = deadline - time.monotonic()
            if left <= 0 or self.p.poll() is not None and self.lines.empty():
                raise AssertionError(f"no line starting {prefix!r} (exit code {self.p.poll()})")
            try:
                line = self.lines.get(timeout=min(left, 1.0))
            except queue.Empty:
                continue
            if line.startswith(prefix):
                return line[len(prefix):].strip()

    def stop(self):
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGTERM)
            try:
                self.p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.p.kill()
                self.p.wait()


def http_get(addr, path):
    with urllib.request.urlopen(f"http://{addr}{path}", timeout=10) as r:
        return r.read().decode()


def metric(dashboard, line_prefix):
    for line in http_get(dashboard, "/metrics").splitlines():
        if line.startswith(line_prefix + " "):
            return float(line.split()[-1])
    raise AssertionError(f"no {line_prefix} in /metrics")


class ZenohWire(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        if not os.access(PAVLOV, os.X_OK):
            # A failure, not a skip: a missing binary must not pass for a tested wire.
            raise RuntimeError(f"no pavlov binary at {PAVLOV} (build it with the zenoh feature, or set PAVLOV_BIN)")
        cls.dir = tempfile.mkdtemp(prefix="pavlov-zenoh-py-")
        cls.procs = []
        ports = {name: free_port() for name in ("alpha", "beta", "gamma", "fleet")}
        cls.ports = ports
        zenoh_file(os.path.join(cls.dir, "alpha.json5"), [endpoint(ports["alpha"])], [])
        zenoh_file(os.path.join(cls.dir, "beta.json5"), [endpoint(ports["beta"])], [])
        # gamma starts later and connects to the fleet itself.
        zenoh_file(os.path.join(cls.dir, "gamma.json5"), [endpoint(ports["gamma"])], [endpoint(ports["fleet"])])
        zenoh_file(
            os.path.join(cls.dir, "fleet.json5"),
            [endpoint(ports["fleet"])],
            [endpoint(ports["alpha"]), endpoint(ports["beta"])],
        )
        cls.alpha, cls.alpha_dash = cls.serve("alpha", ALPHA_TOKEN, True)
        cls.beta, cls.beta_dash = cls.serve("beta", BETA_TOKEN, False)
        fleet = Proc(
            ["fleet", "--listen", "127.0.0.1:0", "--zenoh", os.path.join(cls.dir, "fleet.json5")], cls.dir
        )
        cls.procs.append(fleet)
        cls.fleet = fleet.wait_line("fleet: ").removeprefix("http://").rstrip("/")
        # This script: a peer connected to both robots and to the fleet.
        config = zenoh.Config.from_json5(
            json.dumps(
                {
                    "mode": "peer",
                    "connect": {"endpoints": [endpoint(ports[n]) for n in ("alpha", "beta", "fleet")]},
                    "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
                }
            )
        )
        cls.session = zenoh.open(config)

    @classmethod
    def serve(cls, robot, token, commands):
        with open(os.path.join(REPO, "config", "stall.toml")) as f:
            base = f.read()
        cfg = os.path.join(cls.dir, f"{robot}.toml")
        with open(cfg, "w") as f:
            f.write(f'{base}\n[zenoh]\nrobot = "{robot}"\ncommands = {str(commands).lower()}\nstatus_every_ms = 200\n')
        work = os.path.join(cls.dir, robot)
        os.makedirs(work, exist_ok=True)
        args = ["serve", "--bind", "127.0.0.1:0", "--token", token, "--config", cfg]
        p = Proc([*args, "--zenoh", os.path.join(cls.dir, f"{robot}.json5")], work)
        cls.procs.append(p)
        dash = p.wait_line("dashboard: ").removeprefix("http://").rstrip("/")
        p.wait_line("zenoh: publishing")
        return p, dash

    @classmethod
    def tearDownClass(cls):
        try:
            cls.session.close()
        except Exception:
            pass
        for p in reversed(cls.procs):
            p.stop()
        shutil.rmtree(cls.dir, ignore_errors=True)

    def robots(self):
        return json.loads(http_get(self.fleet, "/api/robots"))

    def row(self, table, name):
        return next((r for r in table["robots"] if r["robot"] == name), None)

    def test_1_ticks_from_both_robots_declare_json_with_a_timestamp_and_a_publication_number(self):
        seen = {}
        lock = threading.Lock()

        def on_tick(sample):
            with lock:
                seen.setdefault(str(sample.key_expr), []).append(sample)

        sub = self.session.declare_subscriber("pavlov/v1/*/tick", on_tick)
        try:
            keys = ("pavlov/v1/alpha/tick", "pavlov/v1/beta/tick")

            def enough():
                with lock:
                    return all(len(seen.get(k, [])) >= 5 for k in keys)

            until("five ticks from each robot", enough)
        finally:
            sub.undeclare()
        for k in keys:
            with lock:
                samples = list(seen[k])
            for s in samples:
                self.assertEqual(str(s.encoding), "application/json", k)
                self.assertIsNotNone(s.timestamp, k)
                self.assertIsNotNone(s.attachment, k)
                self.assertEqual(len(s.attachment.to_bytes()), 8, k)
            record = json.loads(samples[-1].payload.to_bytes())
            self.assertIn("seq", record)
            numbers = [int.from_bytes(s.attachment.to_bytes(), "little") for s in samples]
            self.assertEqual(numbers, sorted(numbers), f"{k}: publication numbers go up")
            print(f"{k}: {len(samples)} ticks, publication numbers {numbers[0]}..{numbers[-1]}, "
                  f"timestamp {samples[-1].timestamp}")

    def test_2_a_wildcard_query_gets_one_reply_per_robot(self):
        # Zenoh's default consolidation: replies under one key would be merged into one.
        replies = list(self.session.get("pavlov/v1/*/config", timeout=20.0))
        keys = sorted(str(r.ok.key_expr) for r in replies if r.ok is not None)
        self.assertEqual(keys, ["pavlov/v1/alpha/config", "pavlov/v1/beta/config"], replies)
        for r in replies:
            self.assertEqual(str(r.ok.encoding), "application/json")
            self.assertIsNotNone(r.ok.timestamp)
            body = json.loads(r.ok.payload.to_bytes())
            self.assertEqual(str(r.ok.key_expr), f"pavlov/v1/{body['config']['zenoh']['robot']}/config")
        print(f"pavlov/v1/*/config: {len(replies)} replies: {keys}")

    def ask(self, robot, body, timeout=20.0):
        payload = body if isinstance(body, bytes) else json.dumps(body).encode()
        return list(self.session.get(f"pavlov/v1/{robot}/command", payload=payload, timeout=timeout))

    def test_3_a_command_with_the_token_is_applied_and_a_refusal_names_the_robot(self):
        command = {"cmd": "set_mode", "mode": "manual"}
        [reply] = self.ask("alpha", {"token": ALPHA_TOKEN, "command": command})
        self.assertIsNotNone(reply.ok, reply.err and reply.err.payload.to_bytes())
        self.assertEqual(str(reply.ok.key_expr), "pavlov/v1/alpha/command")
        self.assertEqual(str(reply.ok.encoding), "application/json")
        answer = json.loads(reply.ok.payload.to_bytes())
        self.assertEqual(answer["ok"], True)
        self.assertEqual(answer["result"]["mode"], "manual")
        [reply] = self.ask("alpha", {"token": BETA_TOKEN, "command": command})
        self.assertIsNone(reply.ok)
        self.assertEqual(str(reply.err.encoding), "application/json")
        refusal = json.loads(reply.err.payload.to_bytes())
        self.assertEqual(refusal["robot"], "alpha")
        self.assertEqual(refusal["key"], "pavlov/v1/alpha/command")
        self.assertEqual(refusal["error"], "token")
        # The same command to every robot at once: each answers for itself.
        replies = self.ask("*", {"token": ALPHA_TOKEN, "command": {"cmd": "set_mode", "mode": "pavlovian"}})
        who = {}
        for r in replies:
            if r.ok is not None:
                who[str(r.ok.key_expr)] = "applied"
            else:
                body = json.loads(r.err.payload.to_bytes())
                who[body["key"]] = body["error"]
        self.assertEqual(who, {"pavlov/v1/alpha/command": "applied", "pavlov/v1/beta/command": "off"})
        print(f"commands: {who}")

    def test_4_an_oversized_command_is_dropped_by_zenoh_before_delivery(self):
        refused = 'pavlov_zenoh_commands_total{outcome="refused_invalid"}'
        dropped = "pavlov_zenoh_oversized_dropped_total"
        before = metric(self.alpha_dash, refused)
        pad = "x" * (10 * 1024 * 1024)
        body = json.dumps({"token": ALPHA_TOKEN, "command": {"cmd": "estop"}, "pad": pad}).encode()
        replies = self.ask("alpha", body, timeout=5.0)
        # Zenoh's own "Timeout" error ends the query (it names the face the query was routed to); nothing
        # came from the bridge, whose every reply is JSON.
        self.assertEqual([r for r in replies if r.ok is not None], [], "a reply came")
        for r in replies:
            self.assertNotEqual(str(r.err.encoding), "application/json", r.err.payload.to_bytes())
            self.assertEqual(r.err.payload.to_bytes(), b"Timeout")
        n = until("the drop counted in alpha's /metrics", lambda: metric(self.alpha_dash, dropped) or None)
        self.assertGreaterEqual(n, 1)
        self.assertEqual(metric(self.alpha_dash, refused), before, "the bridge never saw it")
        # The link still works.
        [reply] = self.ask("alpha", {"token": ALPHA_TOKEN, "command": {"cmd": "set_mode", "mode": "pavlovian"}})
        self.assertIsNotNone(reply.ok)
        print(f"10 MB command: no reply; {dropped} = {n:.0f}")

    def test_5_made_up_names_leave_live_robots_visible(self):
        until("alpha and beta alive in the fleet", lambda: all(
            (self.row(t, n) or {}).get("presence") == "alive" for t in [self.robots()] for n in ("alpha", "beta")))
        status = json.dumps({"robot": "fake", "ok": True, "health": "ok", "dashboard_url": "http://fake/"})
        for i in range(300):
            self.session.put(f"pavlov/v1/fake{i:03}/status", status, encoding="application/json",
                             congestion_control=zenoh.CongestionControl.BLOCK)
        # The flood has arrived when the fleet has refused most of it.
        table = until("the flood refused", lambda: (lambda t: t if t["unknown_names_refused"] >= 250 else None)(
            self.robots()))
        unknown = [r for r in table["robots"] if r["presence"] == "unknown"]
        limits = table["limits"]
        self.assertLessEqual(len(unknown), limits["max_unknown"])
        for name in ("alpha", "beta"):
            self.assertEqual(self.row(table, name)["presence"], "alive", name)
        # A robot started after the flood appears.
        gamma, _ = self.serve("gamma", "gamma-Tok3n-u5Rt8Jc2Ne6Q", False)
        table = until("gamma alive, ticking, in the fleet", lambda: (lambda t: t if (
            (self.row(t, "gamma") or {}).get("presence") == "alive"
            and (self.row(t, "gamma") or {}).get("ticks_received", 0) > 0) else None)(self.robots()))
        self.assertIsNotNone(self.row(table, "gamma")["last_timestamp"])
        print(f"flood: {len(table['robots'])} rows, {len(unknown)} unknown, "
              f"{table['unknown_names_refused']} names refused; gamma alive")
        # A robot that stops is shown departed.
        gamma.stop()
        until("gamma departed", lambda: (self.row(self.robots(), "gamma") or {}).get("presence") == "departed")


if __name__ == "__main__":
    unittest.main(verbosity=2)
