#!/usr/bin/env python3
"""Robustness of a gain set over perturbed scenarios (the scenarios nobody tuned on).

usage: tools/robustness.py [SCENARIO] [extra `formation sim` args, e.g. --set ...]

Runs the in-process simulation on each perturbation below and prints the worst RMS formation error per
window, coverage, constraint violations, the smallest attitude margin and the torque saturation.
Needs a release build (`cargo build --release`).
"""
import concurrent.futures as cf
import json
import os
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FORMATION = os.path.join(ROOT, "target", "release", "formation")
N = 5


def each(fmt):
    return sum((["--set", fmt.format(i=i)] for i in range(N)), [])


def delays(base, amp, rate=None):
    out = each("agents[{i}].delay.base_s=%s" % base) + each("agents[{i}].delay.amplitude_s=%s" % amp)
    return out + (each("agents[{i}].delay.angular_rate_rad_s=%s" % rate) if rate else [])


PERTURBATIONS = {
    "nominal": [],
    "delays at tau_M": delays(0.05, 0.0),
    "no delays": delays(0.0, 0.0),
    "fast-varying delays": delays(0.025, 0.025, 3.0),
    "target 2x faster": ["--set", "mission.target.angular_rate_rad_s=0.052"],
    "target 3x faster": ["--set", "mission.target.angular_rate_rad_s=0.078"],
    "severe faults": each("agents[{i}].fault.gamma_final=[0.45,0.45,0.5]")
    + each("agents[{i}].fault.gamma_initial_excess=[0.55,0.55,0.5]")
    + each("agents[{i}].fault.delta_bias_nm=[0.1,-0.1,0.5]"),
    "spin 1.2 rad/s": ["--set", "mission.formation.spin_rate_rad_s=1.2"],
    "printed sharp phase changes": ["--set", "mission.formation.spin_onset_sharpness=50.0", "--set", "mission.formation.radius_sharpness=5.0"],
    "acceleration limit 8 m/s2": ["--set", "controller.position.max_horizontal_accel_m_s2=8.0"],
    "other RBFNN seed": ["--set", "controller.rbfnn.seed=12345"],
}


def main():
    args = sys.argv[1:]
    work = tempfile.mkdtemp(prefix="formation-robust-")

    def run(item):
        name, extra = item
        out = os.path.join(work, name.replace(" ", "_").replace("/", ""))
        subprocess.run([FORMATION, "sim"] + args + extra + ["--out", out, "--quiet"], capture_output=True)
        try:
            with open(os.path.join(out, "summary.json")) as f:
                return name, json.load(f)
        except OSError:
            return name, None

    print(f"{'perturbation':30s} {'rms cover':>9s} {'rms encl':>9s} {'coverage':>8s} {'att/rate viol':>13s} {'att margin':>10s} {'sat':>5s}")
    with cf.ThreadPoolExecutor(2) as ex:
        for name, s in ex.map(run, PERTURBATIONS.items()):
            if s is None:
                print(f"{name:30s} FAILED")
                continue
            a = s["agents"]
            w = lambda k, win: max((x[k][win] if x[k][win] is not None else 99.0) for x in a)
            av = sum(x["attitude_constraint_violations"] for x in a)
            rv = sum(x["rate_constraint_violations"] for x in a)
            am = min((x["min_attitude_margin_rad"] if x["min_attitude_margin_rad"] is not None else -9) for x in a)
            sat = max(x["torque_saturation_fraction"] for x in a)
            cov = s["coverage_fraction"] or 0.0
            print(f"{name:30s} {w('rms_formation_error_m','cover'):9.3f} {w('rms_formation_error_m','enclose'):9.3f} {cov:8.3f} {av:>6d}/{rv:<6d} {am:10.3f} {sat:5.3f}{' DIVERGED' if s['diverged'] else ''}")


if __name__ == "__main__":
    main()
