#!/usr/bin/env python3
"""Alternating A/B timing of two commands, for changes smaller than this
kind of machine's spread from run to run (±10 % on a shared 2-core VM).

Runs A, B, A, B, ... for --rounds rounds (the order within a round
alternates too, so that neither side always runs first), reads one time
per run from its output, and prints per side the median of the runs and
the minimum, the change of the median, and in how many rounds B was
faster than A with a two-sided sign test (the chance of at least that
lopsided a count if A and B were the same).

A run's time is, from the last JSON line of its standard output (bare or
after `RESULT `) that has it:
  - the key given by --key (e.g. `--key load_s`: the scene loading time of
    `penumbra bench` and of scripts/mitsuba/bench.py);
  - by default `warm_median_s` (`penumbra bench`, `penumbra grad --reps
    N`), or the median of a list `times` (crates/penumbra/examples/
    trace_rays.rs, scripts/embree_bench/bench.c).

  python3 scripts/ab_bench.py --rounds 10 \\
      --a "/tmp/penumbra_before bench scenes/cbox.xml --spp 16 -q" \\
      --b "target/release/penumbra bench scenes/cbox.xml --spp 16 -q"

A development tool (docs/perf/*.md quote its output), not part of the tests.
"""
import argparse
import json
import math
import shlex
import statistics
import subprocess
import sys


def run_time(cmd, key):
    out = subprocess.run(cmd, capture_output=True, text=True)
    if out.returncode:
        raise SystemExit(f"ab_bench.py: {shlex.join(cmd)} failed:\n{out.stderr}")
    for line in reversed(out.stdout.splitlines()):
        text = line[len("RESULT "):] if line.startswith("RESULT {") else line
        if not text.startswith("{"):
            continue
        d = json.loads(text)
        if key in d:
            return d[key]
        if key == "warm_median_s" and "times" in d:
            return statistics.median(d["times"])
    raise SystemExit(f"ab_bench.py: no time in the output of {shlex.join(cmd)}:\n{out.stdout}")


def sign_test(wins, n):
    """Two-sided binomial sign test: P(a count at least as far from n/2)."""
    if n == 0:
        return 1.0
    k = max(wins, n - wins)
    tail = sum(math.comb(n, i) for i in range(k, n + 1)) / 2**n
    return min(1.0, 2 * tail)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--a", required=True, help="command A (one string, split as a shell would)")
    ap.add_argument("--b", required=True, help="command B")
    ap.add_argument("--rounds", type=int, default=10)
    ap.add_argument("--key", default="warm_median_s",
                    help="the JSON key holding the time (default: warm_median_s)")
    a = ap.parse_args()
    cmds = {"A": shlex.split(a.a), "B": shlex.split(a.b)}
    times = {"A": [], "B": []}
    for r in range(a.rounds):
        for side in ("A", "B") if r % 2 == 0 else ("B", "A"):
            times[side].append(run_time(cmds[side], a.key))
        print(f"round {r + 1}: A {times['A'][-1]:.4f}  B {times['B'][-1]:.4f}", flush=True)
    med = {s: statistics.median(t) for s, t in times.items()}
    for s in ("A", "B"):
        print(f"{s}: median {med[s]:.4f} s, min {min(times[s]):.4f} s  ({a.a if s == 'A' else a.b})")
    pairs = [(x, y) for x, y in zip(times["A"], times["B"]) if x != y]
    wins = sum(y < x for x, y in pairs)
    print(f"B / A median: {med['B'] / med['A']:.3f} ({100 * (med['B'] / med['A'] - 1):+.1f} %); "
          f"B faster in {wins} of {len(pairs)} rounds (sign test p = {sign_test(wins, len(pairs)):.3f})")


if __name__ == "__main__":
    sys.exit(main())
