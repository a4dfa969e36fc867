#!/usr/bin/env bash
# Physics speed side by side in one run: `motionaug bench physics` (our rapier
# humanoid tracking an HDM05 clip with action 0, one thread) against pybullet's
# DeepMimic humanoid with stable PD at 1/1200 s (benches/pybullet_deepmimic.py),
# alternating ROUNDS times so that both see the same machine load.
#
#   python3 -m venv /tmp/pyb && /tmp/pyb/bin/pip install pybullet numpy
#   PYTHON=/tmp/pyb/bin/python bash benches/physics_vs_pybullet.sh [ROUNDS]
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON="${PYTHON:-python3}"
ROUNDS="${1:-3}"
cargo build --release -q -p motionaug-cli
ours=()
theirs=()
for _ in $(seq 1 "$ROUNDS"); do
    o=$(target/release/motionaug bench physics --clip examples/data/HDM_bd_kickLFront1Reps_001_120.amc \
        --skeleton examples/data/HDM_bd.asf --seconds 3 --json)
    t=$("$PYTHON" benches/pybullet_deepmimic.py --seconds 3 2>/dev/null | tail -1)
    ours+=("$(echo "$o" | "$PYTHON" -c 'import json,sys; print(json.load(sys.stdin)["sim_seconds_per_wall_second"])')")
    theirs+=("$(echo "$t" | "$PYTHON" -c 'import json,sys; print(json.load(sys.stdin)["sim_seconds_per_wall_second"])')")
    echo "$o" | "$PYTHON" -c 'import json,sys; r=json.load(sys.stdin); print("  ours: %.1f sim s / wall s, mean joint error %.4f rad, falls %d" % (r["sim_seconds_per_wall_second"], r["mean_joint_error_rad"], r["falls"]))'
    echo "$t" | "$PYTHON" -c 'import json,sys; r=json.load(sys.stdin); print("  pybullet: %.2f sim s / wall s at dt %.5f" % (r["sim_seconds_per_wall_second"], r["dt"]))'
done
"$PYTHON" - "${ours[*]}" "${theirs[*]}" <<'PY'
import statistics, sys
ours = [float(x) for x in sys.argv[1].split()]
theirs = [float(x) for x in sys.argv[2].split()]
ratios = [o / t for o, t in zip(ours, theirs)]
print("ours / pybullet per round: " + ", ".join("%.0fx" % r for r in ratios)
      + "; median %.0fx" % statistics.median(ratios))
PY
