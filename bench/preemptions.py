#!/usr/bin/env python3
"""What held mppid's loop thread off its core: each time the loop was preempted (switched out
while runnable), who took the core and how long until the loop ran again, from a scheduler
trace of that core. Prints JSON: per preempting thread (name and kernel priority), how often,
the total and the longest; the preemptions longer than --long-ms, with their time; and the
loop's longest cycles (woken to asleep again), each split into the time the loop itself ran
and the time it was preempted: a cycle that ran long on its own had the core to itself.

    perf record -e sched:sched_switch -C 1 -o sched.data &    # the core mppid is pinned to
    ... the flight ...; kill -INT %1
    perf script -i sched.data -F comm,tid,time,event,trace > sched.txt
    bench/preemptions.py sched.txt [--loop-prio 18] [--long-ms 1.5]

The loop thread is the one switched out most often at --loop-prio (the kernel's priority,
99 minus the SCHED_FIFO priority: mppid's loop at 81 is 18; docs/first-flight.md)."""
import argparse
import collections
import json
import re
import sys

SWITCH = re.compile(r"\s*\S.*?\s+\d+\s+([\d.]+): sched:sched_switch: prev_comm=(.*?) prev_pid=(\d+) "
                    r"prev_prio=(\d+) prev_state=(\S+) ==> next_comm=(.*?) next_pid=(\d+) next_prio=(\d+)")


def switches(lines):
    """(time s, prev tid, prev prio, prev state, next comm, next tid, next prio) of each switch."""
    for line in lines:
        m = SWITCH.match(line)
        if m:
            yield (float(m[1]), int(m[3]), int(m[4]), m[5], m[6], int(m[7]), int(m[8]))


def loop_tid(events, prio: int) -> int:
    counts = collections.Counter(e[1] for e in events if e[2] == prio)
    if not counts:
        sys.exit(f"preemptions.py: no thread switched out at priority {prio}")
    return counts.most_common(1)[0][0]


def preemptions(events, loop: int):
    """(start s, duration s, who) of each preemption of `loop`."""
    pending = None
    for t, prev, _, state, next_comm, nxt, next_prio in events:
        if prev == loop and state.startswith("R"):
            pending = (t, f"{next_comm} ({next_prio})")
        elif pending and nxt == loop:
            yield pending[0], t - pending[0], pending[1]
            pending = None


def cycles(events, loop: int, prio: int):
    """(start s, wall s, own running s) of each of the loop's cycles at its real-time priority."""
    start = running = None
    own = 0.0
    for t, prev, _, state, _, nxt, next_prio in events:
        if nxt == loop:
            if start is None and next_prio == prio:
                start, own = t, 0.0
            running = t
        if prev == loop:
            if running is not None:
                own, running = own + t - running, None
            if state.startswith("S") and start is not None:
                yield start, t - start, own
                start = None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("trace", help="perf script output (see above)")
    ap.add_argument("--loop-prio", type=int, default=18)
    ap.add_argument("--long-ms", type=float, default=1.5)
    ap.add_argument("--cycles", type=int, default=10, help="the longest cycles to list")
    a = ap.parse_args()
    with open(a.trace) as f:
        events = list(switches(f))
    loop = loop_tid(events, a.loop_prio)
    t0 = events[0][0]
    by = collections.defaultdict(lambda: {"n": 0, "total_ms": 0.0, "max_ms": 0.0})
    long = []
    for start, d, who in preemptions(events, loop):
        b = by[who]
        b["n"], b["total_ms"], b["max_ms"] = b["n"] + 1, b["total_ms"] + d * 1e3, max(b["max_ms"], d * 1e3)
        if d * 1e3 > a.long_ms:
            long.append({"t_s": round(start - t0, 3), "ms": round(d * 1e3, 2), "by": who})
    out = {"loop_tid": loop, "trace_s": round(events[-1][0] - t0, 1),
           "by": {k: {**v, "total_ms": round(v["total_ms"], 1), "max_ms": round(v["max_ms"], 2)}
                  for k, v in sorted(by.items(), key=lambda kv: -kv[1]["total_ms"])},
           "longer": long,
           "longest_cycles": [{"t_s": round(t - t0, 3), "wall_ms": round(w * 1e3, 1), "own_ms": round(o * 1e3, 1),
                               "preempted_ms": round((w - o) * 1e3, 1)}
                              for t, w, o in sorted(cycles(events, loop, a.loop_prio), key=lambda c: -c[1])[:a.cycles]]}
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
