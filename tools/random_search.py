#!/usr/bin/env python3
"""Random search of controller gains with the fast in-process runner (`formation sim --set ...`).

usage: tools/random_search.py N SEED [extra `formation sim` args...]

Samples N gain sets from SPACE (log-uniform or uniform), runs the paper scenario with each on two
threads, and prints the best by the score max(worst RMS cover, worst RMS enclose), with +10 for any
constraint violation or divergence and +5 x the torque saturation fraction. Needs a release build
(`cargo build --release`). This is how the gains of config/scenarios/paper.toml were found
(docs/tuning.md).
"""
import concurrent.futures as cf
import json
import math
import os
import random
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FORMATION = os.path.join(ROOT, "target", "release", "formation")

SPACE = {
    "controller.position.k_p": (0.8, 3.0, "log"),
    "controller.position.k_v": (0.8, 3.0, "log"),
    "controller.position.leader_velocity_damping": (1.0, 4.0, "log"),
    "controller.position.leader_position_gain": (0.05, 1.5, "log"),
    "controller.position.nn_learning_rate": (5, 40, "log"),
    "controller.position.nn_k_p": (0.02, 0.3, "log"),
    "controller.position.nn_k_v": (0.02, 0.3, "log"),
    "controller.rbfnn.spread": (0.3, 0.9, "lin"),
    "controller.rbfnn.velocity_span_m_s": (1.0, 4.0, "log"),
    "controller.attitude_command_filter.natural_frequency_rad_s": (15, 60, "log"),
    "controller.attitude_command_filter.damping": (0.7, 1.0, "lin"),
    "controller.rate_command_filter.natural_frequency_rad_s": (80, 160, "lin"),
    "controller.attitude.k1_alpha": (4, 9, "lin"),
    "controller.attitude.k2_phi": (9, 18, "lin"),
}


def sample(rng):
    sets = {}
    for key, (lo, hi, kind) in SPACE.items():
        v = math.exp(rng.uniform(math.log(lo), math.log(hi))) if kind == "log" else rng.uniform(lo, hi)
        sets[key] = f"{v:.4g}"
    r = rng.uniform(0.4, 1.0)
    sets["controller.attitude_command_filter.rate_limit"] = f"[{r:.3f},{r:.3f},{r:.3f}]"
    return sets


def score(s):
    a = s["agents"]

    def worst(key, w):
        return max((x[key][w] if x[key][w] is not None else 99.0) for x in a)

    rc, re = worst("rms_formation_error_m", "cover"), worst("rms_formation_error_m", "enclose")
    viol = sum(x["attitude_constraint_violations"] + x["rate_constraint_violations"] for x in a)
    sat = max(x["torque_saturation_fraction"] for x in a)
    total = max(rc, re) + (10 if viol else 0) + (10 if s["diverged"] else 0) + 5 * sat
    return total, rc, re, viol, sat


def main():
    n, seed, extra = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3:]
    rng = random.Random(seed)
    candidates = [sample(rng) for _ in range(n)]
    work = tempfile.mkdtemp(prefix="formation-search-")

    def run(i):
        out = os.path.join(work, str(i))
        args = [FORMATION, "sim"] + extra
        for k, v in candidates[i].items():
            args += ["--set", f"{k}={v}"]
        subprocess.run(args + ["--out", out, "--quiet"], capture_output=True)
        try:
            with open(os.path.join(out, "summary.json")) as f:
                return score(json.load(f)), i
        except OSError:
            return None

    with cf.ThreadPoolExecutor(2) as ex:
        results = [r for r in ex.map(run, range(n)) if r]
    results.sort(key=lambda r: r[0][0])
    for (total, rc, re, viol, sat), i in results[:8]:
        print(f"score={total:.3f} rms_cover={rc:.3f} rms_enclose={re:.3f} violations={viol} saturation={sat:.3f}")
        print("   " + " ".join(f"--set {k}={v}" for k, v in candidates[i].items()))


if __name__ == "__main__":
    main()
