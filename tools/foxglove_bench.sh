#!/usr/bin/env bash
# Lockstep step time with and without a connected Foxglove viewer, in alternated runs.
#
#   tools/foxglove_bench.sh [PAIRS] [DURATION_S]      (defaults: 5 pairs of 20 s paper runs)
#
# A: `formation run --set simulation.duration_s=D` (no live view).
# B: the same with `--foxglove 127.0.0.1:0 --foxglove-wait 30`, joined by Foxglove's WebSocket
#    client (tests/js/foxglove_client.mjs: subscribes to every channel and decodes every message).
# Pairs alternate their order (AB, BA, ...). Prints timing.step_us.p50 of summary.json per run,
# the median of each side and the median of the per-pair ratios B/A. Needs the release build and
# `npm ci` in tests/js.
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${FORMATION_BIN:-target/release/formation}
pairs=${1:-5}
dur=${2:-20}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
p50() { python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["timing"]["step_us"]["p50"])' "$1/summary.json"; }
run_a() { "$bin" run --set simulation.duration_s="$dur" --out "$work/$1" >/dev/null 2>&1; p50 "$work/$1"; }
run_b() {
  "$bin" run --set simulation.duration_s="$dur" --foxglove 127.0.0.1:0 --foxglove-wait 30 \
    --out "$work/$1" >/dev/null 2>"$work/$1.err" &
  local pid=$! url=""
  for _ in $(seq 1 300); do
    url=$(grep -o 'ws://[0-9.:]*' "$work/$1.err" 2>/dev/null || true)
    [ -n "$url" ] && break
    sleep 0.1
  done
  node tests/js/foxglove_client.mjs "$url" 600 >"$work/$1.client.json"
  wait "$pid"
  p50 "$work/$1"
}
as=(); bs=(); ratios=()
for k in $(seq 1 "$pairs"); do
  if [ $((k % 2)) -eq 1 ]; then a=$(run_a a$k); b=$(run_b b$k); else b=$(run_b b$k); a=$(run_a a$k); fi
  echo "pair $k: without viewer p50 $a us, with viewer p50 $b us"
  as+=("$a"); bs+=("$b"); ratios+=("$(python3 -c "print($b / $a)")")
done
python3 - "${as[*]}" "${bs[*]}" "${ratios[*]}" <<'PY'
import statistics as st, sys
a, b, r = (list(map(float, x.split())) for x in sys.argv[1:4])
print(f"median p50 without viewer {st.median(a):.1f} us, with viewer {st.median(b):.1f} us; "
      f"median ratio with/without {st.median(r):.3f} (pairs: {', '.join(f'{x:.3f}' for x in r)})")
PY
