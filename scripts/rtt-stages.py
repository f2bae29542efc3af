#!/usr/bin/env python3
"""Splits a ping-pong's round trips into stages from a Linux scheduler trace (the README's "Where a round trip goes
today", fourteenth session).

Usage:
    perf sched record -o sched.data -- sleep 2          # while `cortex bench rtt --shm ...` runs its loop
    perf sched timehist -i sched.data -w > timehist.txt
    python3 scripts/rtt-stages.py timehist.txt WRITER ECHO RECEIVER

WRITER, ECHO and RECEIVER name the threads of the loop by a piece of their `perf sched timehist` task name: the
thread that writes the ping, the one that takes it and writes the pong, the one that takes the pong. For the agents'
loop they are `cortex` (the bench's own thread), `agent-2` and `agent-1`; for the raw loop, where the pinging
thread takes its own pong, pass its `[PID]` as both WRITER and RECEIVER and the echo process's `[PID]` as ECHO.

A ping is timed from the wake-up of ECHO by WRITER to the wake-up of
whatever RECEIVER wakes next (the agents' callback handing the pong to the bench's thread) or, where RECEIVER is
WRITER, to RECEIVER running again. Each ping is put in one of two kinds: RECEIVER ran on the core ECHO was woken on
(one core), or on the other (both cores). Printed per kind: the pings, and p50 / p90 in µs of each stage. The
trace's own cost is in every figure. A ping is timed only if RECEIVER was asleep when its pong came (its wake-up is
the mark); a raw loop's pinging thread often is not asleep yet, and those pings, the fastest, are left out. The
write before ECHO's wake-up is not timed: in about half of the agents' pings the trace shows WRITER running since
long before it, with no switch-in to time the write from.
"""

import re
import statistics
import sys


def events(path):
    """(kind, time_us, cpu, task, wakee, sched_delay_us) for every wake-up and switch-out line of the trace."""
    out = []
    with open(path, encoding="utf-8") as lines:
        for line in lines:
            fields = line.split()
            if len(fields) < 3 or not re.match(r"^\d+\.\d+$", fields[0]):
                continue
            time_us, cpu, task = float(fields[0]) * 1e6, fields[1], fields[2]
            if "awakened:" in line:
                out.append(("wake", time_us, cpu, task, line.split("awakened:")[1].strip(), None))
                continue
            try:
                delay_us = float(fields[4]) * 1e3
            except (IndexError, ValueError):
                continue
            out.append(("out", time_us, cpu, task, None, delay_us))
    return out


def pings(trace, writer, echo, receiver):
    """Per ping: (kind, echo queued, echo's work until it woke RECEIVER, RECEIVER queued, RECEIVER until its
    hand-off, from the echo's wake-up to the end)."""
    def role(task):
        """"W", "E" or "R"; the pinging thread of a raw loop is "W" as a waker and as the one woken."""
        return next((r for r, name in (("E", echo), ("W", writer), ("R", receiver)) if name in task), None)

    same = writer == receiver
    receiver_role = "W" if same else "R"
    trace = [e for e in trace if role(e[3])]
    found = []
    for i, (kind, t1, cpu, task, wakee, _) in enumerate(trace):
        if not (kind == "wake" and role(task) == "W" and wakee and role(wakee) == "E"):
            continue
        echo_delay = woke_receiver = receiver_delay = receiver_cpu = handed = None
        for kind2, t, cpu2, task2, wakee2, delay in trace[i + 1:i + 12]:
            if kind2 == "wake" and role(task2) == "W" and role(wakee2 or "") == "E":
                break  # the next ping: this one's trace is incomplete
            if kind2 == "out" and role(task2) == "E" and echo_delay is None:
                echo_delay = delay
            if kind2 == "wake" and role(task2) == "E" and role(wakee2 or "") == receiver_role and woke_receiver is None:
                woke_receiver = t
            if kind2 == "out" and role(task2) == receiver_role and woke_receiver is not None and receiver_delay is None:
                receiver_delay, receiver_cpu = delay, cpu2
            if kind2 == "wake" and role(task2) == "R" and not same and woke_receiver is not None and handed is None:
                handed = t
            if receiver_delay is not None and (same or handed is not None):
                break
        if None in (echo_delay, woke_receiver, receiver_delay) or (not same and handed is None):
            continue
        end = woke_receiver + receiver_delay if same else handed
        found.append((
            "one core" if receiver_cpu == cpu else "both cores",
            echo_delay,
            woke_receiver - t1 - echo_delay,
            receiver_delay,
            0.0 if same else end - woke_receiver - receiver_delay,
            end - t1,
        ))
    return found


def main(argv):
    if len(argv) != 5:
        sys.exit(__doc__)
    found = pings(events(argv[1]), argv[2], argv[3], argv[4])
    names = ["echo queued", "echo's work, to RECEIVER's wake-up",
             "RECEIVER queued", "RECEIVER, running to hand-off", "in all, from the echo's wake-up"]
    for kind in ("one core", "both cores"):
        rows = [p[1:] for p in found if p[0] == kind]
        print(f"{kind}: {len(rows)} pings")
        for name, column in zip(names, zip(*rows)):
            ordered = sorted(column)
            print(f"  {name:40s} p50 {statistics.median(ordered):7.1f}  p90 {ordered[int(len(ordered) * 0.9)]:7.1f}")


if __name__ == "__main__":
    main(sys.argv)
