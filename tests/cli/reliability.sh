#!/usr/bin/env bash
# reliability.sh — end-to-end regression tests of issue 16 (reliability) at the command line:
# impossible options and config values (thread counts, integers that do not fit, non-finite or
# out-of-range numbers in flags, run and study configs and system files) are refused with one
# line on stderr that says the allowed range, exit 2 and no run folder left; a training run
# started with relative paths resumes from anywhere; an output that cannot be written is exit
# status 1 with the reason, for every command; a run that fails to start leaves no folder;
# SIGINT/SIGTERM: train checkpoints and exits 130/143 (a second signal at once), infer removes
# its staging folder.
# usage: reliability.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"
SRC=$(cd "$(dirname "$0")/../.." && pwd)

# a quick training run: linear, a few iterations of 2 patches (under a timeout: some of the
# values below made a run hang or train for ever)
TR="timeout 60 $LM train --model linear --data $CAVE --batch 2 --accum-steps 1 --synth-fraction 0 --val-patches 1 --quiet"

# ---- thread counts ------------------------------------------------------------------------
printf '{"version": 1, "threads": 100000}' > "$T/threads.json"
expect_error "train --threads 100000" 2 "'threads': 100000 is out of range (0..1024)" "$T/th1" -- \
  $TR --iterations 2 --threads 100000 --output "$T/th1"
expect_error "train config threads 100000" 2 "'threads': 100000 is out of range (0..1024)" "$T/th2" -- \
  $TR --iterations 2 --config "$T/threads.json" --output "$T/th2"
expect_error "infer --threads 100000" 2 "--threads: 100000 is out of range (1..1024)" "$T/th3" -- \
  "$LM" infer --model x --input y --output "$T/th3" --threads 100000

# ---- numbers: integers range-checked before they are converted, reals finite and in range --
printf '{"version": 1, "patch": [4294967362, 64]}' > "$T/patch.json"
printf '{"version": 1, "iterations": 9223372036854775807}' > "$T/iter.json"
expect_error "config patch [2^32 + 66, 64]" 2 "'patch': 4294967362 is out of range (1..4096)" \
  "$T/n1" -- $TR --iterations 2 --config "$T/patch.json" --output "$T/n1"
expect_error "--patch 4294967362x64" 2 "'patch': 4294967362 is out of range (1..4096)" "$T/n2" -- \
  $TR --iterations 2 --patch 4294967362x64 --output "$T/n2"
expect_error "--val-patches 2^31 - 1" 2 "'val_patches': 2147483647 is out of range (0..100000)" \
  "$T/n3" -- $TR --iterations 2 --val-patches 2147483647 --output "$T/n3"
expect_error "--lr 1e39" 2 "'lr': 1e+39 is out of range (0..10)" "$T/n4" -- \
  $TR --iterations 2 --lr 1e39 --output "$T/n4"
expect_error "--batch 2^64" 2 "'batch': must be an integer in 1..4096 (got '18446744073709551616')" \
  "$T/n5" -- $TR --iterations 2 --batch 18446744073709551616 --output "$T/n5"
expect_error "--noise 0,1e39" 2 "'noise': 1e+39 is out of range (0..1)" "$T/n6" -- \
  $TR --iterations 2 --noise 0,1e39 --output "$T/n6"
expect_error "config iterations 2^63 - 1" 2 "'iterations': 9223372036854775807 is out of range (1..1000000000)" \
  "$T/n7" -- $TR --config "$T/iter.json" --output "$T/n7"
printf '{"version": 1, "presets": ["linear"], "data": "%s", "eval_size": [4294967362, 64]}' \
  "$CAVE" > "$T/study.json"
printf '{"version": 1, "presets": ["linear"], "data": "%s", "iterations": 2}' "$CAVE" \
  > "$T/study_ok.json"
expect_error "study eval_size [2^32 + 66, 64]" 2 "field 'eval_size': must be \"HxW\" or [H, W] (1..8192)" \
  "$T/n8" -- timeout 60 "$LM" study --config "$T/study.json" --output "$T/n8"
printf '{"version": 1, "presets": ["linear"], "data": "%s", "conditions": [{"family": "motion", "levels": [0, 1e308]}]}' \
  "$CAVE" > "$T/study_motion.json"
expect_error "study motion level 1e308" 2 "levels[1]': not a valid motion level (motion (px/s), 0..10000)" \
  "$T/n15" -- timeout 60 "$LM" study --config "$T/study_motion.json" --output "$T/n15"
expect_error "simulate --frames x" 2 "--frames: 'x' is not an integer in 1..10000" "$T/n9" -- \
  "$LM" simulate --input "$CAVE" --crop --video --frames x --output "$T/n9"
expect_error "render --exposure 1e999" 2 "--exposure: '1e999' is not a finite number in 1e-12..1e+06" \
  "$T/n10.png" -- "$LM" render --input "$CAVE" --exposure 1e999 --output "$T/n10.png"
expect_error "fit-auto --synth-size 4294967362x256" 2 \
  "--synth-size '4294967362x256': want HxW, from 66x64 to 4096x4096" "$T/n11.json" -- \
  "$LM" fit-auto --models a --synth 1 --synth-size 4294967362x256 --output "$T/n11.json"
expect_error "simulate --motion rotate:1e300" 2 "every number in -1e6..1e6" "$T/n12" -- \
  "$LM" simulate --input "$CAVE" --crop --video --frames 2 --motion rotate:1e300 --output "$T/n12"
printf '{"version": 1, "measure": "grad", "window": [4294967362, 64], "stride": [30, 32], "edges": [], "windows": [1], "models": [{"model": "x", "cost_s_per_window": 1, "psnr": [30]}]}' > "$T/auto.json"
expect_error "auto.json window 2^32 + 66" 2 "window / stride [h, w] (integers in 1..4096)" "$T/n14" -- \
  "$LM" infer --model auto --auto "$T/auto.json" --input "$CAVE" --output "$T/n14"
# a system file whose gain overflows the responses to inf (every frame was zero, exit 0)
sed -e "s|\"\.\./spectra/|\"$SRC/data/spectra/|g" \
    -e 's|"gains": "equal_white"|"gains": [1e308, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1]|' \
    "$SRC/data/systems/default.json" > "$T/gains.json"
check "gains fixture" grep -q 1e308 "$T/gains.json"
expect_error "system gains[0] 1e308" 2 \
  "gains[0]: must be a non-negative number of at most 1e+12 (got 1e+308)" "$T/n13" -- \
  "$LM" simulate --input "$CAVE" --crop --system "$T/gains.json" --output "$T/n13"

# ---- resume of a run started with relative paths (the README's example) ------------------
# config.json stored --data as given (relative to the working directory) and resume read it
# relative to the run folder: resuming failed, from the same working directory or another.
mkdir -p "$T/wd1/scenes" "$T/wd2"
cp -r "$CAVE" "$T/wd1/scenes/"
RT="--model linear --batch 2 --accum-steps 1 --synth-fraction 0 --val-patches 1 --quiet"
(cd "$T/wd1" && "$LM" train $RT --data scenes/balloons_crop100 --iterations 2 \
  --output runs/rel > "$T/rel.log" 2>&1)
check "relative run: $(cat "$T/rel.log")" [ -s "$T/wd1/runs/rel/model.safetensors" ]
(cd "$T/wd1" && "$LM" train --resume runs/rel --iterations 3 > "$T/rel2.log" 2>&1)
check "resume from the same folder: $(cat "$T/rel2.log")" grep -q "for 3 iterations" "$T/rel2.log"
(cd "$T/wd2" && "$LM" train --resume ../wd1/runs/rel --iterations 4 > "$T/rel3.log" 2>&1)
check "resume from another folder: $(cat "$T/rel3.log")" grep -q "for 4 iterations" "$T/rel3.log"

# ---- cannot write an output: exit status 1 for every command, with the reason --------------
R=$T/wd1/runs/rel # the model trained above
touch "$T/afile"  # a file where a folder should be: nothing can be written below it
"$LM" simulate --input "$CAVE" --crop --output "$T/frames" > /dev/null 2>&1
check "frames fixture" [ -s "$T/frames/frames/frame_0000.png" ]
expect_error "train: output cannot be written" 1 "cannot create folder $T/afile/run: Not a directory" \
  "$T/afile/run" -- $TR --iterations 2 --output "$T/afile/run"
expect_error "simulate: output cannot be written" 1 "cannot create a folder: Not a directory" \
  "$T/afile/sim" -- "$LM" simulate --input "$CAVE" --crop --output "$T/afile/sim"
expect_error "infer: output cannot be written" 1 "cannot create a folder: Not a directory" \
  "$T/afile/inf" -- "$LM" infer --model "$R" --input "$T/frames/frames" --output "$T/afile/inf"
expect_error "eval: output cannot be written" 1 "cannot create a folder: Not a directory" \
  "$T/afile/ev" -- "$LM" eval --model "$R" "$CAVE" --split all --noise 0 --rainbow 0 \
  --output "$T/afile/ev"
"$LM" fit-auto --models "$R,$R" --synth 1 --synth-size 66x64 --bins 1 \
  --output "$T/afile/auto.json" > /dev/null 2> "$T/cal.err"
check "fit-auto: output cannot be written: exit 1" [ $? -eq 1 ]
check "fit-auto: output cannot be written: the reason: $(cat "$T/cal.err")" \
  grep -q "auto: cannot write '$T/afile/auto.json': Not a directory" "$T/cal.err"
expect_error "render: output cannot be written" 1 "x.png: write failed" "$T/afile/x.png" -- \
  "$LM" render --input "$CAVE" --output "$T/afile/x.png"
expect_error "study: output cannot be written" 1 "runs: cannot create (Not a directory)" \
  "$T/afile/st" -- "$LM" study --config "$T/study_ok.json" --output "$T/afile/st" --no-charts
if [ "$(id -u)" -ne 0 ]; then # a read-only folder (root writes anyway)
  mkdir -p "$T/ro" && chmod 555 "$T/ro"
  "$LM" fit-auto --models "$R,$R" --synth 1 --synth-size 66x64 --bins 1 \
    --output "$T/ro/auto.json" > /dev/null 2> "$T/cal2.err"
  check "fit-auto: read-only folder: exit 1 and why: $(cat "$T/cal2.err")" \
    grep -q "auto.json': Permission denied" "$T/cal2.err"
  chmod 755 "$T/ro"
fi
# ... and input that cannot be read is bad input (2), for train too (it was 1)
expect_error "train: missing data" 2 "$T/nope: no such file or folder" "$T/nd" -- \
  $TR --iterations 2 --data "$T/nope" --output "$T/nd"

# ---- a run that fails to start leaves no run folder -----------------------------------------
mkdir -p "$T/badscene"
cp -r "$CAVE" "$T/badscene/"
head -c 700 "$CAVE/balloons_crop100_ms_05.png" > "$T/badscene/balloons_crop100/balloons_crop100_ms_05.png"
expect_error "train: a scene fails at the first batch" 2 "ms_05.png: truncated PNG" "$T/fs/run" -- \
  timeout 60 "$LM" train $RT --iterations 2 --data "$T/badscene" --output "$T/fs/run"
check "train: no parent folder left either" [ ! -e "$T/fs" ]

# ---- signals ----------------------------------------------------------------------------------
# (a watchdog kills the command after 60 s: before the fix, a background job ignored SIGINT, as
# a shell starts it, and ran for ever)
# wait_for COND...: poll (up to 60 s) until the command succeeds
wait_for() {
  local k
  for k in $(seq 1 1200); do "$@" 2>/dev/null && return 0; sleep 0.05; done
  return 1
}
log_rows() { [ -f "$1/log.csv" ] && [ "$(wc -l < "$1/log.csv")" -gt "$2" ]; }
# watch PID: SIGKILL it after 60 s (the watchdog's pid in $dog)
watch() { (sleep 60; kill -KILL "$1") > /dev/null 2>&1 & dog=$!; }
# train: the first SIGINT / SIGTERM finishes the iteration, writes the checkpoint, says so in
# one line and exits 130 / 143; the run resumes from there
for sg in INT TERM; do
  d=$T/sig_$sg
  "$LM" train $RT --data "$CAVE" --iterations 1000000000 --val-interval 0 \
    --checkpoint-interval 0 --output "$d" > "$d.out" 2> "$d.err" &
  pid=$!
  watch $pid
  wait_for log_rows "$d" 3
  kill -$sg $pid
  wait $pid
  rc=$?
  kill $dog
  want=$([ $sg = INT ] && echo 130 || echo 143)
  check "train SIG$sg: exit $rc, want $want: $(cat "$d.err")" [ $rc -eq $want ]
  check "train SIG$sg: one line" [ "$(wc -l < "$d.err")" -eq 1 ]
  n=$(sed -n 's/.*interrupted (SIG'$sg') at iteration \([0-9]*\): checkpoint written.*/\1/p' "$d.err")
  check "train SIG$sg: the line names the iteration: $(cat "$d.err")" [ -n "$n" ]
  check "train SIG$sg: checkpoint on disk" [ -s "$d/model.safetensors" -a -s "$d/optimizer.safetensors" ]
  check "train SIG$sg: no temporary file left" [ -z "$(ls "$d" | grep tmp)" ]
  if [ -n "$n" ]; then
    "$LM" train --resume "$d" --iterations $((n + 2)) > "$d.res" 2>&1
    check "train SIG$sg: resumes: $(cat "$d.res")" grep -q "for $((n + 2)) iterations" "$d.res"
  fi
done
# a second signal stops at once (a slow step: han-small)
d=$T/sig_twice
"$LM" train --model han-small --data "$CAVE" --batch 4 --accum-steps 1 --synth-fraction 0 \
  --val-patches 1 --iterations 5 --quiet --output "$d" > "$d.out" 2> "$d.err" &
pid=$!
watch $pid
wait_for [ -s "$d/config.json" ]
kill -INT $pid
sleep 0.1
kill -INT $pid
wait $pid
rc=$?
kill $dog
check "train: second SIGINT: exit $rc: $(cat "$d.err")" [ $rc -eq 130 ]
check "train: second SIGINT stops at once: $(cat "$d.err")" grep -q "stopped at once" "$d.err"
# infer: a signal removes the staging folder (a long sequence: the signal comes after the first
# cube is staged; a FIFO as frame 1 no longer works, every frame's header is read first)
mkdir -p "$T/long"
for i in $(seq -w 0 399); do
  ln -s "$T/frames/frames/frame_0000.png" "$T/long/frame_0$i.png"
done
O=$T/inf_sig
"$LM" infer --model "$R" --input "$T/long" --no-align --output "$O" > "$T/isig.out" 2> "$T/isig.err" &
pid=$!
watch $pid
staged() { ls "$O".tmp.*/cube_0000.exr; } # the glob is expanded at each try
wait_for staged
kill -INT $pid
wait $pid
rc=$?
kill $dog
check "infer SIGINT: exit $rc: $(cat "$T/isig.err")" [ $rc -eq 130 ]
check "infer SIGINT: one line: $(cat "$T/isig.err")" [ "$(grep -vc -e '^frame ' -e '^model ' "$T/isig.err")" -eq 1 ]
check "infer SIGINT: says so: $(cat "$T/isig.err")" \
  grep -q "interrupted (SIGINT): partial output removed" "$T/isig.err"
check "infer SIGINT: no staging folder or output left: $(ls -d "$O"* 2>&1)" no_output "$O"
check "infer SIGINT: nothing set aside either" [ -z "$(ls -d "$O".* 2>/dev/null)" ]

# ---- library messages: only ours ------------------------------------------------------------
# a PNG whose image data is damaged (IDAT CRC, and a bad filter byte with a good CRC): libpng
# printed "libpng error: ..." on stderr before our line
python3 - "$CAVE" "$T/png" <<'PY'
import os, shutil, struct, sys, zlib
src, out = sys.argv[1], sys.argv[2]
def chunks(b):
    pos = 8
    while pos < len(b):
        n = struct.unpack('>I', b[pos:pos + 4])[0]
        yield pos, n, b[pos + 4:pos + 8]
        pos += 12 + n
for name in ('crc', 'filter'):
    d = os.path.join(out, name, 'balloons_crop100')
    shutil.copytree(src, d)
    p = os.path.join(d, 'balloons_crop100_ms_01.png')
    b = bytearray(open(p, 'rb').read())
    pos, n, _ = next(c for c in chunks(bytes(b)) if c[2] == b'IDAT')
    if name == 'crc':
        b[pos + 8 + n] ^= 0xff
    else:  # zlib data of a bad filter byte (5) before the first row, with a valid CRC
        raw = zlib.decompress(bytes(b[pos + 8:pos + 8 + n]))
        comp = zlib.compress(b'\x05' + raw[1:])
        c = struct.pack('>I', len(comp)) + b'IDAT' + comp
        c += struct.pack('>I', zlib.crc32(b'IDAT' + comp) & 0xffffffff)
        b[pos:pos + 12 + n] = c
    open(p, 'wb').write(bytes(b))
PY
check "corrupt PNG fixtures" [ -d "$T/png/filter/balloons_crop100" ]
expect_error "PNG with a bad IDAT CRC: one line" 2 "ms_01.png: corrupt PNG: chunk IDAT at byte 33 fails its CRC" \
  "$T/p1" -- "$LM" simulate --input "$T/png/crc/balloons_crop100" --crop --output "$T/p1"
expect_error "PNG with a bad filter byte: one line" 2 "ms_01.png: truncated or corrupt image: bad adaptive filter value" \
  "$T/p2" -- "$LM" simulate --input "$T/png/filter/balloons_crop100" --crop --output "$T/p2"

# the progress output says "noise: none" for a run without training noise, not "U[0, 0]"
"$LM" train --model linear --data "$CAVE" --batch 2 --accum-steps 1 --iterations 1 --noise 0,0 \
  --val-patches 1 --output "$T/nonoise" > "$T/nonoise.log" 2>&1
check "train --noise 0,0: progress says 'noise: none'" grep -q "; noise: none;" "$T/nonoise.log"
check_not "train --noise 0,0: no empty range" grep -q "U\[0, 0\]" "$T/nonoise.log"

finish
