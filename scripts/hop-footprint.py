#!/usr/bin/env python3
"""Per-hop figures from two callgrind runs of `hop_cost` that differ only in their number of hops.

    hop-footprint.py SHORT.out LONG.out EXTRA_HOPS [TOP]

The runs collect inside the hop loops alone (the writer's loop, the receiving thread's), and every cost that grows
with the hops is a hop's: the difference between the runs, over the extra hops, is one hop's instructions and the
cache lines it had to fetch from memory. The runs flush the simulated cache between hops (HOP_COST_FLUSH_MB), so
those lines are what a hop touches when it starts cold: code lines (ILmr), data lines read (DLmr) and written
(DLmw). The flush itself is left out. With TOP, the functions with most lines are listed.
"""

import collections
import re
import sys

FIELDS = ("Ir", "ILmr", "DLmr", "DLmw")


def name(names, text):
    """A file or function name of callgrind's output, which gives each once with a number and then the number."""
    text = text.strip()
    if text.startswith("("):
        number, _, rest = text.partition(")")
        if rest.strip():
            names[number] = rest.strip()
        return names.get(number, text)
    return text


def load(path):
    """Self costs by (file, function), summed over the lines of each (callgrind's format)."""
    costs = collections.defaultdict(lambda: collections.Counter())
    events, file, function, skip = None, None, None, False
    files, functions = {}, {}
    with open(path) as out:
        for line in out:
            if line.startswith("events:"):
                events = line.split()[1:]
            elif line.startswith(("fl=", "fi=", "fe=")):
                file = name(files, line[3:])
            elif line.startswith("fn="):
                function = name(functions, line[3:])
            elif line.startswith(("cfn=", "cfi=", "cfl=")):
                name(functions if line.startswith("cfn=") else files, line.split("=", 1)[1])
            elif line.startswith("calls="):
                skip = True  # the next cost line is the call's inclusive cost, not this function's own
            elif line[:1] in "0123456789+-*" and events:
                if skip:
                    skip = False
                    continue
                values = line.split()[1:]
                counter = costs[(file, function)]
                for event, value in zip(events, values):
                    counter[event] += int(value)
    return costs


def short_name(file, function):
    for _ in range(3):
        function = re.sub(r"<[^<>]*>", "<>", function)
    file = re.sub(r".*/(src|library)/", "", file or "")
    return f"{function[:100]}  [{file[:40]}]"


def main():
    short, long, extra = load(sys.argv[1]), load(sys.argv[2]), float(sys.argv[3])
    top = int(sys.argv[4]) if len(sys.argv) > 4 else 0
    total, rows = collections.Counter(), []
    for key in set(short) | set(long):
        if key[1] and "flush" in key[1]:
            continue
        hop = {f: (long[key][f] - short[key][f]) / extra for f in FIELDS}
        for f in FIELDS:
            total[f] += hop[f]
        rows.append((hop["ILmr"] + hop["DLmr"] + hop["DLmw"], hop, key))
    lines = total["ILmr"] + total["DLmr"] + total["DLmw"]
    print(
        f"per hop: {total['Ir']:,.0f} instructions; {lines:,.0f} cache lines from memory when cold "
        f"(code {total['ILmr']:,.0f}, data read {total['DLmr']:,.0f}, data written {total['DLmw']:,.0f})"
    )
    for lines, hop, key in sorted(rows, key=lambda row: -row[0])[:top]:
        print(f"  {lines:6.1f} lines (code {hop['ILmr']:5.1f})  {hop['Ir']:7.0f} instr  {short_name(*key)}")


if __name__ == "__main__":
    main()
