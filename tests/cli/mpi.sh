#!/usr/bin/env bash
# mpi.sh — data-parallel training over MPI (issue 17), 2 ranks x 1 thread on this machine
# (--oversubscribe): (1) 2 ranks at batch 2 end with the parameters of one process at batch 4
# on the same samples, within float-summation tolerance, with and without background workers;
# log.csv and the checkpoint are written once (rank 0) and record 2 ranks; (2) interrupted
# (--stop-after) and resumed with 2 ranks it ends where the uninterrupted run ends; resuming it
# in one process is refused (one line, exit 2, saying what to do); (3) a rank killed with
# SIGKILL ends the job with a non-zero status, not a hang (timeout 120 s); (4) closed-form fits
# are refused under mpirun (exit non-zero, the reason printed, no model written); (5) `study`
# under mpirun spreads the presets over the ranks and scores them as one process does.
# usage: mpi.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
MPI="timeout 300 mpirun --oversubscribe -np 2"
C="--model rt-8 --data $CAVE --patch 33x32 --accum-steps 1 --lr 2e-3 --iterations 20
   --val-interval 10 --val-patches 4 --checkpoint-interval 10 --threads 1 --quiet"
cmp_params() { python3 - "$1" "$2" "$3" <<'PY'
import json, struct, sys
def load(p):
    f = open(p, "rb"); n = struct.unpack("<Q", f.read(8))[0]; h = json.loads(f.read(n)); d = f.read()
    return {k: struct.unpack("<%df" % ((v["data_offsets"][1] - v["data_offsets"][0]) // 4),
                             d[v["data_offsets"][0]:v["data_offsets"][1]])
            for k, v in h.items() if k != "__metadata__"}
A, B = load(sys.argv[1]), load(sys.argv[2])
assert A.keys() == B.keys()
worst = max(abs(x - y) for k in A for x, y in zip(A[k], B[k]))
scale = max(abs(x) for k in A for x in A[k])
print(f"max |diff| {worst:.3g} of max |param| {scale:.3g}")
sys.exit(not worst <= float(sys.argv[3]) * scale)
PY
}
meta() { python3 -c "
import json, struct, sys
f = open('$1', 'rb'); n = struct.unpack('<Q', f.read(8))[0]
print(json.loads(f.read(n))['__metadata__'].get('$2', ''))"; }

"$LM" train $C --batch 4 --workers 0 --output "$T/one" > /dev/null 2> "$T/err"
check "one process, batch 4: $(cat "$T/err")" [ $? -eq 0 ]
for w in 0 1; do
  $MPI "$LM" train $C --batch 2 --workers $w --output "$T/two$w" > "$T/out" 2> "$T/err"
  check "2 ranks, batch 2, workers $w: $(tail -2 "$T/err")" [ $? -eq 0 ]
  check "2 ranks: global batch reported" grep -q "2 processes x batch 2 (global batch 4)" "$T/out"
  check "2 ranks (workers $w) = one process at batch 4 ($(cmp_params "$T/one/model.safetensors" \
    "$T/two$w/model.safetensors" 1e-5))" cmp_params "$T/one/model.safetensors" \
    "$T/two$w/model.safetensors" 1e-5
done
check "log.csv written once (21 lines)" [ "$(wc -l < "$T/two0/log.csv")" -eq 21 ]
check "the checkpoint records 2 ranks" [ "$(meta "$T/two0/optimizer.safetensors" ranks)" = 2 ]
check "validation PSNR equal to one process's" python3 - "$T/one/log.csv" "$T/two0/log.csv" <<'PY'
import csv, sys
a, b = ([r for r in csv.DictReader(open(p)) if r["psnr"]] for p in sys.argv[1:3])
assert len(a) == len(b) == 2 and all(abs(float(x["psnr"]) - float(y["psnr"])) < 1e-3
                                     for x, y in zip(a, b)), (a, b)
PY

# interrupted and resumed with 2 ranks: the same end as uninterrupted
$MPI "$LM" train $C --batch 2 --workers 0 --stop-after 10 --output "$T/res" > /dev/null 2> "$T/err"
check "2 ranks, stopped after 10: $(tail -1 "$T/err")" [ $? -eq 0 ]
$MPI "$LM" train --resume "$T/res" --quiet > /dev/null 2> "$T/err"
check "2 ranks, resumed: $(tail -1 "$T/err")" [ $? -eq 0 ]
check "resumed = uninterrupted ($(cmp_params "$T/two0/model.safetensors" \
  "$T/res/model.safetensors" 1e-6))" cmp_params "$T/two0/model.safetensors" \
  "$T/res/model.safetensors" 1e-6
expect_error "resume a 2-rank run in one process" 2 "trained by 2 process(es)" "$T/none" -- \
  "$LM" train --resume "$T/two0" --iterations 30 --quiet

# the study under mpirun: presets trained by the ranks in turn, scored by rank 0: the same
# held-out scores as one process
cat > "$T/s.json" <<JSON
{"version": 1, "presets": ["lmmse-5", "linear", "rt-8+lmmse-5"], "data": ["$CAVE"],
 "iterations": 30, "seed": 1, "patch": [33, 32],
 "train": {"batch": 2, "accum_steps": 1, "lr": 0.002, "val_interval": 10, "val_patches": 2,
           "checkpoint_interval": 10, "log_interval": 10, "fit_patches": 64},
 "noise": [0, 10], "eval_scenes": 2, "eval_size": "96x96", "rainbow": 0, "frame": "120x160",
 "timing_repeats": 1}
JSON
"$LM" study --config "$T/s.json" --output "$T/s1" --threads 1 --quiet --no-charts > /dev/null \
  2> "$T/err"
check "study, one process: $(tail -1 "$T/err")" [ $? -eq 0 ]
$MPI "$LM" study --config "$T/s.json" --output "$T/s2" --threads 1 --quiet --no-charts \
  > "$T/out" 2> "$T/err"
check "study, 2 ranks: $(tail -1 "$T/err")" [ $? -eq 0 ]
check "study, 2 ranks: one summary (rank 0)" [ "$(grep -c '^results:' "$T/out")" -eq 1 ]
check "study, 2 ranks: the same scores as one process" python3 - "$T/s1" "$T/s2" <<'PY'
import json, sys
a, b = (json.load(open(d + "/results.json"))["runs"] for d in sys.argv[1:3])
assert [r["preset"] for r in a] == [r["preset"] for r in b]
for ra, rb in zip(a, b):
    assert [l["psnr"] for l in ra["eval"]["levels"]] == [l["psnr"] for l in rb["eval"]["levels"]], ra["preset"]
PY

# infer under mpirun: each rank a block of frames (aligned with the neighbours it reads
# itself), one output folder: the same cubes as one process, bit for bit
DEMO=$(dirname "$0")/../../models/demo/rt16nc-lmmse.safetensors
"$LM" simulate --input "$CAVE" --video --frames 5 --motion translate:60,0 --crop \
  --output "$T/vid" > /dev/null 2> "$T/err"
check "simulate a video: $(tail -1 "$T/err")" [ $? -eq 0 ]
"$LM" infer --model "$DEMO" --input "$T/vid/frames" --output "$T/inf1" --threads 1 \
  > /dev/null 2> "$T/err"
check "infer, one process: $(tail -1 "$T/err")" [ $? -eq 0 ]
$MPI "$LM" infer --model "$DEMO" --input "$T/vid/frames" --output "$T/inf2" --threads 1 \
  > /dev/null 2> "$T/err"
check "infer, 2 ranks: $(tail -1 "$T/err")" [ $? -eq 0 ]
check "infer, 2 ranks: every frame once" [ "$(ls "$T/inf2" | grep -c '^cube_.*exr$')" -eq 5 ]
check "infer, 2 ranks: no staging folder left" [ -z "$(ls -d "$T"/inf2.tmp.* 2> /dev/null)" ]
for f in "$T"/inf1/cube_*.exr; do
  check "infer, 2 ranks: $(basename "$f") identical" cmp -s "$f" "$T/inf2/$(basename "$f")"
done
$MPI "$LM" infer --model "$DEMO" --input "$T/vid/frames" --output "$T/inf2" --threads 1 \
  > /dev/null 2> "$T/err"
check "infer, 2 ranks: an existing output is refused" [ $? -ne 0 ]
check "infer, 2 ranks: the output is untouched" [ "$(ls "$T/inf2" | grep -c '^cube_')" -eq 5 ]

# a killed rank ends the job (non-zero), it does not hang
$MPI "$LM" train $C --batch 2 --workers 0 --iterations 100000 --output "$T/kill" \
  > /dev/null 2> "$T/kerr" &
job=$!
for i in $(seq 1 100); do
  [ -s "$T/kill/log.csv" ] && [ "$(wc -l < "$T/kill/log.csv")" -gt 3 ] && break
  sleep 0.2
done
victim=$(pgrep -f "lumosaic train.*$T/kill" | tail -1)
kill -9 "$victim" 2> /dev/null
wait $job
rc=$?
check "killed rank: the job failed (exit $rc), within the timeout" [ $rc -ne 0 -a $rc -ne 124 ]
check "killed rank: mpirun says which process ended" grep -qi "signal 9\|killed\|exited" "$T/kerr"

# (under mpirun each rank says it, and mpirun adds its own banner: not one line)
$MPI "$LM" train --model lmmse --data "$CAVE" --threads 1 --quiet --output "$T/lmmse" \
  > /dev/null 2> "$T/lerr"
check "closed form under mpirun: refused (exit $?)" [ $? -ne 0 ]
check "closed form under mpirun: says why" grep -q "run it without mpirun" "$T/lerr"
check "closed form under mpirun: nothing written" [ ! -e "$T/lmmse/model.safetensors" ]
finish
