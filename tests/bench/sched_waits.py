#!/usr/bin/env python3
"""What control's threads wait for beside the Horde: `perf sched` around `pavlov bench --horde`.

Usage:
    perf sched record -a -o sched.data -- pavlov bench --horde --config config/horde.toml --seconds 20
    perf script -i sched.data -F comm,pid,tid,cpu,time,event,trace > sched.txt
    tests/bench/sched_waits.py sched.txt BENCH_PID

(BENCH_PID: the bench process, the first `pavlov` in the trace. The tracepoints need root, or
`perf_event_paranoid` ≤ 1 and read access to tracefs.) The bench runs Horde, plain, plain, Horde in one
process; the Horde windows are the lifetimes of its `pavlov-horde` threads (over a second long), the plain
window the time between them (2 s in from each side). For control's threads (`pavlov-tick`, the timer
thread, and `tokio-rt-worker`, the runtime's workers) in each window, prints:

- every wait from a wake-up (or a preemption) until the thread runs: count, p50 / p99 / max, and which
  tasks held its core meanwhile (time-weighted; `bench:` marks the bench's own threads), and how much of
  the waiting was behind the Horde's threads;
- how long it ran per slice (contention for memory bandwidth or the caches would lengthen it);
- which task was on the CPU when each wake-up was signalled (the waker, or the task a timer interrupt
  landed on);

and the CPU time the Horde's thread got in each Horde window. Standard library only.
"""

import bisect
import collections
import re
import sys

LINE = re.compile(r"^\s*(.+?)\s+(\d+)/(\d+)\s+\[(\d+)\]\s+([\d.]+):\s+sched:(\w+):\s+(.*)$")
FIELD = re.compile(r"(\w+)=(\S+)")
CONTROL = ("pavlov-tick", "tokio-rt-worker")
HORDE = "pavlov-horde"


def quantile(values, q):
    v = sorted(values)
    return v[min(len(v) - 1, int(round(q * (len(v) - 1))))]


class Trace:
    """The scheduler events of one `perf script` output."""

    def __init__(self, path, bench_pid):
        self.bench_pid = bench_pid
        self.tgid = {}
        self.comm = {}
        self.segments = collections.defaultdict(list)  # cpu -> [(start, end, tid, comm)]
        self.waits = []  # (from, to, cpu, tid, comm)
        self.wakings = []  # (time, waker pid, waker comm, wakee tid)
        running, pending = {}, {}
        for line in open(path, encoding="utf-8", errors="replace"):
            m = LINE.match(line)
            if not m:
                continue
            comm, pid, tid, cpu, t, event, rest = m.groups()
            pid, tid, cpu, t = int(pid), int(tid), int(cpu), float(t)
            self.tgid[tid] = pid
            if event in ("sched_waking", "sched_wakeup_new"):
                wakee = int(dict(FIELD.findall(rest))["pid"])
                pending.setdefault(wakee, t)
                if event == "sched_waking":
                    self.wakings.append((t, pid, comm, wakee))
            elif event == "sched_switch":
                prev_comm = re.search(r"prev_comm=(.*?) prev_pid=", rest).group(1)
                next_comm = re.search(r"next_comm=(.*?) next_pid=", rest).group(1)
                fields = dict(FIELD.findall(rest.split(" ==> ")[0]))
                nxt = int(re.search(r"next_pid=(\d+)", rest).group(1))
                prev = int(fields["prev_pid"])
                self.comm[prev], self.comm[nxt] = prev_comm, next_comm
                if cpu in running:
                    r_tid, r_comm, since = running[cpu]
                    self.segments[cpu].append((since, t, r_tid, r_comm))
                running[cpu] = (nxt, next_comm, t)
                if fields["prev_state"].startswith("R"):
                    pending.setdefault(prev, t)  # preempted: it waits from now
                else:
                    pending.pop(prev, None)
                if nxt in pending:
                    self.waits.append((pending.pop(nxt), t, cpu, nxt, next_comm))
        self.starts = {c: [s[0] for s in segs] for c, segs in self.segments.items()}
        span = collections.defaultdict(lambda: [float("inf"), 0.0])
        for segs in self.segments.values():
            for s, e, tid, c in segs:
                if c == HORDE and self.ours(tid):
                    span[tid][0], span[tid][1] = min(span[tid][0], s), max(span[tid][1], e)
        self.hordes = sorted(tuple(v) for v in span.values() if v[1] - v[0] > 1.0)

    def ours(self, tid):
        return self.tgid.get(tid) == self.bench_pid

    def control(self, tid, comm):
        return self.ours(tid) and comm in CONTROL

    def window(self, t):
        if any(a <= t <= b for a, b in self.hordes):
            return "horde"
        if len(self.hordes) >= 2 and self.hordes[0][1] + 2 < t < self.hordes[-1][0] - 2:
            return "plain"
        return None

    def window_seconds(self, name):
        if name == "horde":
            return sum(b - a for a, b in self.hordes)
        return max(0.0, (self.hordes[-1][0] - 2) - (self.hordes[0][1] + 2))

    def name(self, tid, comm):
        return ("bench:" + comm) if self.ours(tid) else comm

    def holders(self, cpu, a, b):
        """Who ran on `cpu` during [a, b], in seconds each."""
        out = collections.Counter()
        segs = self.segments[cpu]
        i = max(0, bisect.bisect_right(self.starts[cpu], a) - 1)
        while i < len(segs) and segs[i][0] < b:
            s, e, tid, c = segs[i]
            overlap = min(e, b) - max(s, a)
            if overlap > 0:
                out[self.name(tid, c)] += overlap
            i += 1
        return out


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    trace = Trace(sys.argv[1], int(sys.argv[2]))
    if len(trace.hordes) < 2:
        sys.exit("fewer than two Horde windows in the trace: is BENCH_PID the bench's process?")
    origin = trace.hordes[0][0]
    print("Horde windows, s:", [(round(a - origin, 1), round(b - origin, 1)) for a, b in trace.hordes])
    waits, held = collections.defaultdict(list), collections.defaultdict(collections.Counter)
    for a, b, cpu, tid, comm in trace.waits:
        w = trace.window(a)
        if w and trace.control(tid, comm):
            waits[(w, comm)].append((b - a) * 1e6)
            held[(w, comm)] += trace.holders(cpu, a, b)
    runs = collections.defaultdict(list)
    for segs in trace.segments.values():
        for s, e, tid, comm in segs:
            w = trace.window(s)
            if w and trace.control(tid, comm):
                runs[(w, comm)].append((e - s) * 1e6)
    wakers = collections.defaultdict(collections.Counter)
    for t, pid, comm, wakee in trace.wakings:
        w, wakee_comm = trace.window(t), trace.comm.get(wakee, "?")
        if w and trace.control(wakee, wakee_comm):
            wakers[(w, wakee_comm)][("bench:" + comm) if pid == trace.bench_pid else comm] += 1
    for key in sorted(waits):
        v, seconds = waits[key], trace.window_seconds(key[0])
        print(
            f"{key[0]:>6} {key[1]:<16} {seconds:5.1f} s: waits {len(v)}, µs p50 {quantile(v, .5):.0f} "
            f"p99 {quantile(v, .99):.0f} max {max(v):.0f}, {sum(v) / 1e3:.0f} ms in all"
        )
        total = sum(held[key].values()) or 1.0
        print("    its core held meanwhile by: " + ", ".join(
            f"{n} {100 * s / total:.0f} %" for n, s in held[key].most_common(7)))
        horde = sum(s for n, s in held[key].items() if n.startswith("bench:" + HORDE))
        print(f"    waiting behind the Horde's threads: {horde * 1e3:.0f} ms ({horde * 1e3 / seconds:.1f} ms a second)")
        r = runs[key]
        if r:
            print(f"    on-CPU per slice, µs: p50 {quantile(r, .5):.0f} p90 {quantile(r, .9):.0f} p99 {quantile(r, .99):.0f}")
        print("    on the CPU when its wake-ups were signalled: " + ", ".join(
            f"{n} {k}" for n, k in wakers[key].most_common(6)))
    for a, b in trace.hordes:
        got = sum(
            min(e, b) - max(s, a)
            for segs in trace.segments.values()
            for s, e, tid, c in segs
            if c == HORDE and trace.ours(tid) and e > a and s < b
        )
        print(f"the Horde's thread ran {got:.2f} s of its {b - a:.1f} s")


if __name__ == "__main__":
    main()
