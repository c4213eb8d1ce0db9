#!/usr/bin/env bash
# interrupts.sh — SIGINT / SIGTERM at any moment leave something that continues: a training run
# stopped by two signals in quick succession (whatever their timing) resumes with --resume; a
# run folder holding only its config.json starts again from it; `study --jobs` forwards a
# signal to its workers, which checkpoint and exit, and waits for them before it reports; the
# closed-form fit shows its progress, stops on SIGINT saying what was kept, and stops
# accumulating at --minutes.
# usage: interrupts.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"

# wait_for COND...: poll (up to 60 s) until the command succeeds
wait_for() {
  local k
  for k in $(seq 1 1200); do "$@" 2>/dev/null && return 0; sleep 0.05; done
  return 1
}
# watch PID: SIGKILL it after 90 s (the watchdog's pid in $dog)
watch() { (sleep 90; kill -KILL "$1") > /dev/null 2>&1 & dog=$!; }

# ---- two signals in quick succession: the run folder resumes -------------------------------
# (han-small: a first iteration of seconds, so the signals come before it ends)
SLOW="--model han-small --data $CAVE --batch 4 --accum-steps 1 --synth-fraction 0 --val-patches 1 --quiet"
for delay in 0 0.4 1.5; do
  d=$T/twice_$delay
  "$LM" train $SLOW --iterations 5 --output "$d" > "$d.out" 2> "$d.err" &
  pid=$!
  watch $pid
  wait_for [ -s "$d/config.json" ]
  sleep "$delay"
  kill -INT $pid
  sleep 0.05
  kill -INT $pid
  wait $pid
  rc=$?
  kill $dog
  check "two SIGINTs after $delay s: exit $rc: $(cat "$d.err")" [ $rc -eq 130 ]
  check "two SIGINTs after $delay s: one line: $(cat "$d.err")" [ "$(wc -l < "$d.err")" -eq 1 ]
  check "two SIGINTs after $delay s: says what is kept: $(cat "$d.err")" \
    grep -q "stopped at once: the last checkpoint in $d is kept" "$d.err"
  check "two SIGINTs after $delay s: a checkpoint: $(ls "$d")" \
    [ -s "$d/model.safetensors" -a -s "$d/optimizer.safetensors" ]
  check "two SIGINTs after $delay s: no temporary file: $(ls "$d")" [ -z "$(ls "$d" | grep tmp)" ]
  timeout 120 "$LM" train --resume "$d" --iterations 1 > "$d.res" 2>&1
  rc=$?
  check "two SIGINTs after $delay s: resumes: exit $rc: $(cat "$d.res")" [ $rc -eq 0 ]
  check "two SIGINTs after $delay s: trained: $(cat "$d.res")" grep -q "for 1 iterations" "$d.res"
done
# SIGTERM after SIGINT: the second signal is named, and gives the exit status
d=$T/int_term
"$LM" train $SLOW --iterations 5 --output "$d" > "$d.out" 2> "$d.err" &
pid=$!
watch $pid
wait_for [ -s "$d/model.safetensors" ]
kill -INT $pid
sleep 0.05
kill -TERM $pid
wait $pid
rc=$?
kill $dog
check "SIGINT then SIGTERM: exit $rc: $(cat "$d.err")" [ $rc -eq 143 ]
check "SIGINT then SIGTERM: both named: $(cat "$d.err")" grep -q "interrupted (SIGTERM after SIGINT)" "$d.err"

# a run folder with a config but no checkpoint (stopped before one was written) starts again
Q="--model linear --data $CAVE --batch 2 --accum-steps 1 --synth-fraction 0 --val-patches 1 --quiet"
"$LM" train $Q --iterations 2 --output "$T/nock" > /dev/null 2>&1
rm -f "$T/nock/model.safetensors" "$T/nock/optimizer.safetensors"
"$LM" train --resume "$T/nock" --iterations 3 > "$T/nock.out" 2> "$T/nock.err"
rc=$?
check "resume without a checkpoint: exit $rc: $(cat "$T/nock.err")" [ $rc -eq 0 ]
check "resume without a checkpoint: says so: $(cat "$T/nock.out")" \
  grep -q "has no checkpoint yet: the run starts from its beginning" "$T/nock.out"
check "resume without a checkpoint: trained 3: $(cat "$T/nock.out")" \
  grep -q "for 3 iterations" "$T/nock.out"

# ---- study: a signal reaches the workers, which checkpoint; the study waits and reports ------
printf '{"version": 1, "presets": ["rt-8", "linear"], "data": "%s", "iterations": 100000, "patch": [33, 32], "train": {"batch": 2, "accum_steps": 1, "val_interval": 0, "checkpoint_interval": 0, "val_patches": 1}}' \
  "$CAVE" > "$T/study.json"
workers_of() { pgrep -f -- "--output $1 .*--worker" > /dev/null; }
trained() { # trained DIR: the run's log has at least 3 rows (it is past its start)
  [ -f "$1/log.csv" ] && [ "$(wc -l < "$1/log.csv")" -gt 3 ]
}
for sg in TERM INT; do
  S=$T/study_$sg
  "$LM" study --config "$T/study.json" --output "$S" --jobs 2 --threads 1 --no-charts --quiet \
    > "$S.out" 2> "$S.err" &
  pid=$!
  watch $pid
  wait_for trained "$S/runs/rt-8"
  wait_for trained "$S/runs/linear"
  kill -$sg $pid
  wait $pid
  rc=$?
  kill $dog
  want=$([ $sg = INT ] && echo 130 || echo 143)
  check "study --jobs 2, SIG$sg: exit $rc, want $want: $(cat "$S.err")" [ $rc -eq $want ]
  check "study --jobs 2, SIG$sg: says so: $(cat "$S.err")" \
    grep -q "lumosaic study: interrupted (SIG$sg): the workers checkpointed" "$S.err"
  check_not "study --jobs 2, SIG$sg: no worker left running" workers_of "$S"
  for p in rt-8 linear; do
    check "study --jobs 2, SIG$sg: $p's worker said so: $(cat "$S.err")" \
      grep -q "interrupted (SIG$sg): $p stopped at iteration [1-9]" "$S.err"
    n=$(sed -n "s/.*$p stopped at iteration \([0-9]*\),.*/\1/p" "$S.err")
    "$LM" train --resume "$S/runs/$p" --iterations $((${n:-0} + 1)) --quiet > "$S.$p" 2>&1
    check "study --jobs 2, SIG$sg: $p resumes after iteration $n: $(cat "$S.$p")" \
      grep -q "for $((${n:-0} + 1)) iterations" "$S.$p"
  done
done
# one job: the training in the study's own process checkpoints; the study says so
S=$T/study_one
"$LM" study --config "$T/study.json" --output "$S" --threads 1 --no-charts --quiet \
  > "$S.out" 2> "$S.err" &
pid=$!
watch $pid
wait_for trained "$S/runs/rt-8"
kill -INT $pid
wait $pid
rc=$?
kill $dog
check "study, SIGINT: exit $rc: $(cat "$S.err")" [ $rc -eq 130 ]
check "study, SIGINT: one line about it: $(cat "$S.err")" [ "$(grep -c interrupted "$S.err")" -eq 1 ]
check "study, SIGINT: says what was kept: $(cat "$S.err")" \
  grep -q "interrupted (SIGINT): rt-8 stopped at iteration [1-9][0-9]*, checkpoint written" "$S.err"

# ---- the closed-form fit: progress with an ETA, SIGINT, --minutes ----------------------------
F="--data $CAVE --fit-patches 1000000 --threads 1"
progress_line() { grep -q "training patches read.*ETA" "$1"; }
d=$T/fit_int
"$LM" train --model lmmse $F --output "$d" > "$d.out" 2> "$d.err" &
pid=$!
watch $pid
wait_for progress_line "$d.err"
check "fit: a progress line with an ETA: $(tail -2 "$d.err")" progress_line "$d.err"
kill -INT $pid
wait $pid
rc=$?
kill $dog
check "fit SIGINT: exit $rc: $(tail -2 "$d.err")" [ $rc -eq 130 ]
check "fit SIGINT: says what was kept: $(tail -1 "$d.err")" \
  grep -q "interrupted (SIGINT): the closed-form fit stopped reading after [0-9]* of 1000000 training patches and was solved from them; the model is written to $d" "$d.err"
check "fit SIGINT: the model: $(ls "$d")" [ -s "$d/model.safetensors" ]
check "fit SIGINT: fit.json says so" grep -q '"stopped": "interrupted"' "$d/fit.json"
# random features: each level is a pass of its own; stopped in the first, nothing is written
d=$T/fit_rf
"$LM" train --model lmmse-rf $F --output "$d" > "$d.out" 2> "$d.err" &
pid=$!
watch $pid
wait_for progress_line "$d.err"
kill -TERM $pid
wait $pid
rc=$?
kill $dog
check "fit lmmse-rf SIGTERM: exit $rc: $(tail -1 "$d.err")" [ $rc -eq 143 ]
check "fit lmmse-rf SIGTERM: says nothing was fitted: $(tail -1 "$d.err")" \
  grep -q "interrupted (SIGTERM): the closed-form fit of lmmse-rf was stopped in pass 1 of 6.*nothing was fitted" "$d.err"
check "fit lmmse-rf SIGTERM: no run folder" [ ! -e "$d" ]
# --minutes: reading stops at the budget, the filters are solved from what was read
d=$T/fit_min
timeout -k 5 60 "$LM" train --model lmmse $F --minutes 0.05 --output "$d" > "$d.out" 2> "$d.err"
rc=$?
check "fit --minutes: exit $rc: $(tail -1 "$d.err")" [ $rc -eq 0 ]
check "fit --minutes: says so: $(cat "$d.out")" \
  grep -q "the time budget (--minutes 0.05) ended the reading after [0-9]* of 1000000" "$d.out"
check "fit --minutes: fit.json says so" grep -q '"stopped": "time budget"' "$d/fit.json"

# whatever failed above: no worker of this test outlives it
for p in $(pgrep -f -- "--output $T/study"); do kill -KILL "$p" 2> /dev/null; done
finish
