#!/usr/bin/env python3
"""Fault-estimate errors of a run: per agent and channel, |Gamma-hat - Gamma| / Gamma and
|delta-hat - delta| (N m) at `onset + 15 s`, the worst over [onset + 15 s, end], and at the end.

usage: tools/fault_estimates.py RUN_DIR [--onset T]   (RUN_DIR holds trajectory.csv; onset default 0)
Exit code 1 when a channel misses the targets (10 % on Gamma, 0.05 N m on delta, from onset + 15 s on).
"""
import csv
import sys

GAMMA_TOL = 0.10
DELTA_TOL = 0.05
SETTLE_S = 15.0


def main():
    run = sys.argv[1]
    onset = float(sys.argv[sys.argv.index("--onset") + 1]) if "--onset" in sys.argv else 0.0
    rows = {}
    with open(f"{run}/trajectory.csv") as f:
        for r in csv.DictReader(f):
            rows.setdefault(int(r["agent"]), []).append(r)
    ok = True
    print(f"{'agent':>5} {'ch':>3} | {'Gamma err %':>27} | {'delta err N m':>27}")
    print(f"{'':>5} {'':>3} | {'@+15s':>8} {'max>=+15s':>9} {'final':>8} | {'@+15s':>8} {'max>=+15s':>9} {'final':>8}")
    for a, rs in sorted(rows.items()):
        after = [r for r in rs if float(r["t"]) >= onset + SETTLE_S - 1e-9]
        for ch in "xyz":
            def ge(r):
                g = float(r[f"gamma_{ch}"])
                return abs(float(r[f"gamma_hat_{ch}"]) - g) / g

            def de(r):
                return abs(float(r[f"delta_hat_{ch}"]) - float(r[f"delta_{ch}"]))

            g15, gmax, gend = ge(after[0]), max(map(ge, after)), ge(rs[-1])
            d15, dmax, dend = de(after[0]), max(map(de, after)), de(rs[-1])
            bad = gmax > GAMMA_TOL or dmax > DELTA_TOL
            ok &= not bad
            print(f"{a:>5} {ch:>3} | {100*g15:8.2f} {100*gmax:9.2f} {100*gend:8.2f} | {d15:8.4f} {dmax:9.4f} {dend:8.4f}{'  MISS' if bad else ''}")
    print("all channels within targets" if ok else "some channel misses the targets")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
