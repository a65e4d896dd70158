#!/usr/bin/env python3
"""The separation layer's designs (docs/deviations.md D25) measured against each other.

usage: tools/separation_designs.py [DESIGN ...]

DESIGN is `barrier`, `voronoi`, `repulsive` or `none` (the layer off), optionally followed by
`+PATH=VALUE,...` overrides (e.g. `repulsive+controller.separation.repulsive_gain_m3_s2=2`);
default: the four. Each design flies the same 45 in-process runs (`formation sim`): the paper
case, abrupt-faults.toml, radius sharpness 3, 5, 10 without the shaping (D26), 10 permutations of
the paper's start positions and 10 random starts in a 6 m square at least 0.8 m apart, and a 2 s
crash of every agent at 30, 33, 36 and 39 s (warm restart). Prints per design and group the runs
under the safety distance, the closest approach and the steps under it, and the paper case's
worst RMS. Needs a release build (`cargo build --release`); JOBS=N runs N at once (default 2).
"""
import concurrent.futures as cf
import itertools
import json
import os
import random
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FORMATION = os.environ.get("FORMATION", os.path.join(ROOT, "target", "release", "formation"))
ABRUPT = os.path.join(ROOT, "config", "scenarios", "abrupt-faults.toml")
PAPER_STARTS = [[0.0, 17.64, 0.0], [-2.5, 15.83, 0.0], [-1.56, 12.88, 0.0], [1.54, 12.86, 0.0],
                [2.51, 15.8, 0.0]]


def run(out, name, scenario, sets, events=None):
    folder = os.path.join(out, name)
    cmd = [FORMATION, "sim"] + ([scenario] if scenario else []) + ["--quiet", "--out", folder]
    for s in sets:
        cmd += ["--set", s]
    if events:
        path = folder + ".events.toml"
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, "w") as f:
            f.write(events)
        cmd += ["--events", path, "--restart", "on-failure"]
    p = subprocess.run(cmd, capture_output=True, text=True)
    try:
        with open(os.path.join(folder, "summary.json")) as f:
            s = json.load(f)
    except (OSError, ValueError):
        sys.exit(f"{name}: no summary.json (exit {p.returncode}): {p.stderr[-400:]}")
    sep = s["separation"]
    whole = (sep.get("min_distance") or {}).get("whole") or {}
    rms = [a["rms_formation_error_m"] for a in s["agents"]]
    return dict(name=name, exit=p.returncode, closest=whole.get("distance_m", float("inf")),
                below=sep["steps_below_safety"], cover=max(r["cover"] for r in rms),
                enclose=max(r["enclose"] for r in rms),
                violations=sum(a["attitude_constraint_violations"] + a["rate_constraint_violations"]
                               for a in s["agents"]))


def cases(design):
    method, _, extra = design.partition("+")
    sets = (["controller.separation.enabled=false"] if method == "none"
            else [f'controller.separation.method="{method}"'])
    sets += [x for x in extra.split(",") if x]
    yield "paper", "paper", None, sets, None
    yield "abrupt", "abrupt", ABRUPT, sets, None
    for k in (3, 5, 10):
        yield "sharp", f"sharp{k}", None, sets + [f"mission.formation.radius_sharpness={k}",
                                                  "mission.shaping.enabled=false"], None
    rng = random.Random(7)
    perms = [p for p in itertools.permutations(range(5)) if p != tuple(range(5))]
    for seed in range(10):
        perm = perms[rng.randrange(len(perms))]
        starts = [f"agents[{i}].initial_position_m={PAPER_STARTS[perm[i]]}" for i in range(5)]
        yield "starts", f"perm{seed}", None, sets + starts, None
    for seed in range(10):
        r = random.Random(seed)
        pts = []
        while len(pts) < 5:
            q = [round(r.uniform(-3, 3), 3), round(15.2 + r.uniform(-3, 3), 3), 0.0]
            if all((q[0] - a[0]) ** 2 + (q[1] - a[1]) ** 2 >= 0.64 for a in pts):
                pts.append(q)
        starts = [f"agents[{i}].initial_position_m={pts[i]}" for i in range(5)]
        yield "starts", f"rand{seed}", None, sets + starts, None
    for agent in range(1, 6):
        for at in (30, 33, 36, 39):
            ev = f'[[events]]\nat_s = {at}.0\nkind = "crash"\nagent = {agent}\ndown_s = 2.0\n'
            yield "crash", f"crash{agent}at{at}", None, sets, ev


def main():
    designs = sys.argv[1:] or ["barrier", "voronoi", "repulsive", "none"]
    jobs = int(os.environ.get("JOBS", "2"))
    with tempfile.TemporaryDirectory(prefix="separation-designs-") as out:
        for n, d in enumerate(designs):
            todo = list(cases(d))
            with cf.ThreadPoolExecutor(jobs) as ex:
                res = list(ex.map(lambda c: (c[0], run(out, f"{n}/{c[1]}", *c[2:])), todo))
            groups = {}
            for g, r in res:
                groups.setdefault(g, []).append(r)
            print(f"{d}:")
            for g, rs in groups.items():
                under = sum(1 for r in rs if r["below"] > 0)
                print(f"  {g:7} {under:2}/{len(rs):2} under the safety distance, closest "
                      f"{min(r['closest'] for r in rs):.3f} m, {sum(r['below'] for r in rs)} steps "
                      f"under, {sum(r['violations'] for r in rs)} constraint violations")
            p = groups["paper"][0]
            allr = [r for _, r in res]
            print(f"  paper worst RMS cover / enclose {p['cover']:.4f} / {p['enclose']:.4f} m; "
                  f"enclose RMS median over the runs {statistics.median(r['enclose'] for r in allr):.4f} m",
                  flush=True)


main()
