#!/usr/bin/env bash
# recipe_compare.sh — equal-budget training recipes for a residual on the closed-form floor:
# each variant trains for the same CPU-minutes on one thread (the schedule spans the budget),
# then is scored on the real validation split. Prints a markdown table (PSNR dB at each noise
# level, and the updates the budget bought).
#
#   scripts/recipe_compare.sh [MINUTES] [OUT] [PRESET] [BASE]
#     MINUTES  CPU-minutes per variant (default 5)
#     OUT      folder of the runs (default runs/recipes); a finished variant is not re-run
#     PRESET   the network (default tn-96-nc)
#     BASE     the floor it is a residual on (default models/zoo/lmmse)
# Environment: LUMOSAIC (default build/lumosaic), DATA (default ../shared/data), VARIANTS
# (indices into the list below to run, e.g. "0 8 9"; default all).
set -euo pipefail
cd "$(dirname "$0")/.."
minutes=${1:-5}
out=${2:-runs/recipes}
preset=${3:-tn-96-nc}
base=${4:-models/zoo/lmmse}
lum=${LUMOSAIC:-build/lumosaic}
data=${DATA:-../shared/data}
mkdir -p "$out"

# name | options on top of the reference recipe (lr 5e-4 cosine, batch 8 x 2 accumulated,
# 66 x 64 patches, 5 % narrowband + 5 % procedural synthetic)
variants=(
  "reference|"
  "lr 1e-3|--lr 1e-3"
  "lr 2.5e-4|--lr 2.5e-4"
  "batch 16 x 1|--batch 16 --accum-steps 1"
  "batch 4 x 1|--batch 4 --accum-steps 1"
  "patch 132 x 128, batch 2 x 2|--patch 132x128 --batch 2"
  "synthetic 10 % + 10 %|--synth-fraction 0.1 --procedural-fraction 0.1"
  "no synthetic|--synth-fraction 0 --procedural-fraction 0"
  "illumination tilt +-0.3|--illum-jitter 0.3"
  "LED gain error 3 %|--gain-jitter 0.03"
  "zoom 0.67..1.5 + transposes|--scale-jitter 0.5 --transpose 1"
  "transposes|--transpose 1"
  "clean samples only|--noise 0,0"
  "collage 50 %|--collage 0.5"
  "fine narrowband synthetic 10 %|--fine-fraction 0.1"
)

noise=0,10,20
printf '| recipe | updates | val 0 %% | val 10 %% | val 20 %% |\n|---|---:|---:|---:|---:|\n'
pick=${VARIANTS:-$(seq -s " " 0 $((${#variants[@]} - 1)))}
for i in $pick; do
  v=${variants[$i]}
  name=${v%%|*}
  opts=${v#*|}
  run="$out/v$i"
  if [ ! -f "$run/eval/eval.json" ]; then
    rm -rf "$run"
    # shellcheck disable=SC2086
    "$lum" train --model "$preset" --base "$base" --data "$data/cave" --data "$data/cave-256" \
      --lr 5e-4 --batch 8 --accum-steps 2 --schedule cosine --lr-min 1e-5 --warmup 100 \
      --synth-fraction 0.05 --procedural-fraction 0.05 --minutes "$minutes" --clock cpu \
      --iterations 100000000 --threads 1 --workers 1 --seed 1 --val-patches 32 \
      --val-interval 0 --quiet --output "$run" $opts >"$run.train.log" 2>&1
    "$lum" eval --model "$run" "$data/cave" "$data/cave-256" --split val --noise "$noise" \
      --threads 1 --rainbow 0 --output "$run/eval" >"$run.eval.log" 2>&1
  fi
  updates=$(tail -n 1 "$run/log.csv" | cut -d, -f1)
  psnr=$(python3 -c "
import json,sys
d=json.load(open('$run/eval/eval.json'))
m=d['mean'] if 'mean' in d else d['means']
print(' | '.join('%.2f' % x['psnr'] for x in m))" 2>/dev/null || echo "?")
  printf '| %s | %s | %s |\n' "$name" "$updates" "$psnr"
done
