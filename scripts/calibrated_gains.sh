#!/usr/bin/env bash
# calibrated_gains.sh — what a camera whose LED gains differ from a model's system costs, with
# and without the per-phase gain remap of `infer` / `eval --system` (docs/results.md,
# "Calibrated gains at inference"). Writes a system whose gains are the bundled system's times
# 1 + u, u uniform in [-SPREAD, SPREAD] (Python's random, seeded), then scores the model on the
# real test split three ways: frames of the bundled system (the reference), frames of the
# perturbed system rescaled to the model's gains, and the same frames given as they are.
# usage: scripts/calibrated_gains.sh LUMOSAIC [MODEL] [SEED] [SPREAD] [NOISE]
# (defaults: models/demo/rt16nc-lmmse.safetensors, 5, 0.3, 0,10); one thread, niced.
set -eu
LM=$1
ROOT=$(cd "$(dirname "$0")/.." && pwd)
MODEL=${2:-$ROOT/models/demo/rt16nc-lmmse.safetensors}
SEED=${3:-5}
SPREAD=${4:-0.3}
NOISE=${5:-0,10}
DATA="$ROOT/../shared/data/cave $ROOT/../shared/data/cave-256"
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
"$LM" info --system "$ROOT/data/systems/default.json" > "$T/info"
python3 - "$ROOT/data/systems/default.json" "$T/info" "$SEED" "$SPREAD" "$T/perturbed.json" <<'PY'
import json, os, random, sys
src, info, seed, spread, out = sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4]), sys.argv[5]
s = json.load(open(src))
d = os.path.dirname(os.path.abspath(src))
for l in s["leds"]:
    l["emission"]["csv"] = os.path.normpath(os.path.join(d, l["emission"]["csv"]))
s["sensor"]["qe"]["csv"] = os.path.normpath(os.path.join(d, s["sensor"]["qe"]["csv"]))
gain = {}
for line in open(info):  # the resolved equal-white gains: "  NAME peak subframes ... gain"
    f = line.split()
    if len(f) == 7 and f[0] in [l["name"] for l in s["leds"]]:
        gain[f[0]] = float(f[6])
random.seed(seed)
u = [random.uniform(-spread, spread) for _ in s["leds"]]
s["gains"] = [gain[l["name"]] * (1 + x) for l, x in zip(s["leds"], u)]
s["name"] = "gains perturbed (seed %d, +-%g)" % (seed, spread)
json.dump(s, open(out, "w"), indent=1)
print("gain factors: " + " ".join("%s %+.1f%%" % (l["name"], 100 * x) for l, x in zip(s["leds"], u)))
PY
run() {
  echo "== $1"
  shift
  nice "$LM" eval --model "$MODEL" $DATA --split test --noise "$NOISE" --threads 1 \
    --rainbow 0 "$@" 2>&1 | grep -v '^scene '
}
run "frames of the model's system"
run "frames of the perturbed gains, rescaled per phase" --system "$T/perturbed.json"
run "frames of the perturbed gains, as they are" --system "$T/perturbed.json" --no-gain-remap
