#!/usr/bin/env bash
# zoo_resume.sh — a run folder committed with the repository resumes in a fresh clone: a
# checkout-like tree (repo/ with the run folder under models/zoo/, shared/data/ beside it)
# trains half a run, is copied elsewhere as a clone would lay it out and the original is
# removed; `train --resume` in the copy continues exactly as the uninterrupted run: the same
# loss at every update of log.csv and the same reconstruction of a coded frame, bit for bit
# (same thread count). Also with a residual on a base run committed beside it.
# usage: zoo_resume.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"

A=$T/a B=$T/b
mkdir -p "$A/shared/data/cave" "$A/repo/models/zoo"
cp -r "$CAVE" "$A/shared/data/cave/"
TR="--data ../shared/data/cave --patch 24x32 --batch 2 --iterations 40 --val-patches 2 \
--threads 1 --seed 5 --checkpoint-interval 10 --val-interval 20 --quiet"
( cd "$A/repo" &&
  "$LM" train --model lmmse-5 --data ../shared/data/cave --fit-patches 64 --val-patches 2 \
      --threads 1 --quiet --output models/zoo/floor > "$T/log0" 2>&1 &&
  "$LM" train --model rt-8 --base models/zoo/floor $TR --output "$T/full" > "$T/log1" 2>&1 &&
  "$LM" train --model rt-8 --base models/zoo/floor $TR --stop-after 20 \
      --output models/zoo/run > "$T/log2" 2>&1 )
check "the floor, the whole run and half a run: $(cat "$T/log0" "$T/log1" "$T/log2")" \
  [ -s "$T/full/model.safetensors" ] && [ -s "$A/repo/models/zoo/run/model.safetensors" ]
check_not "config.json names no absolute path" grep -q '"/' "$A/repo/models/zoo/run/config.json"

cp -r "$A" "$B" && rm -rf "$A" # the clone elsewhere; the original gone
( cd "$B/repo" && "$LM" train --resume models/zoo/run --threads 1 --quiet > "$T/log3" 2>&1 )
check "resume in the copy: $(cat "$T/log3")" grep -q "for 40 iterations" "$T/log3"
losses() { awk -F, 'NR > 1 && $2 != "" { print $1, $2 }' "$1"; }
check "the same loss at every update" cmp -s <(losses "$T/full/log.csv") \
  <(losses "$B/repo/models/zoo/run/log.csv")
check "40 updates logged" [ "$(losses "$B/repo/models/zoo/run/log.csv" | wc -l)" -ge 40 ]

"$LM" simulate --input "$B/shared/data/cave/$(basename "$CAVE")" --crop --output "$T/sim" \
  --noise 0 > "$T/log4" 2>&1
F=$(ls "$T"/sim/frames/*.png | head -1)
"$LM" infer --model "$T/full" --input "$F" --output "$T/o1" --threads 1 2> "$T/log5"
"$LM" infer --model "$B/repo/models/zoo/run" --input "$F" --output "$T/o2" --threads 1 2>> "$T/log5"
check "the same reconstruction, bit for bit: $(cat "$T/log4" "$T/log5")" \
  cmp -s "$(ls "$T"/o1/cube_*.exr | head -1)" "$(ls "$T"/o2/cube_*.exr | head -1)"
finish
