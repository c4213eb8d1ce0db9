#!/usr/bin/env bash
# reliability.sh — end-to-end regression tests of issue 16 (reliability) at the command line:
# impossible options and config values (thread counts, integers that do not fit, non-finite or
# out-of-range numbers) are refused with one line on stderr, exit 2 and no run folder left.
# usage: reliability.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"

# a quick training run: linear, a few iterations of 2 patches
TR="$LM train --model linear --data $CAVE --batch 2 --accum-steps 1 --synth-fraction 0 --val-patches 1 --quiet"

# ---- thread counts ------------------------------------------------------------------------
printf '{"version": 1, "threads": 100000}' > "$T/threads.json"
expect_error "train --threads 100000" 2 "'threads': 100000 is out of range (0..1024)" "$T/th1" -- \
  $TR --iterations 2 --threads 100000 --output "$T/th1"
expect_error "train config threads 100000" 2 "'threads': 100000 is out of range (0..1024)" "$T/th2" -- \
  $TR --iterations 2 --config "$T/threads.json" --output "$T/th2"
expect_error "infer --threads 100000" 2 "--threads: 100000 is out of range (1..1024)" "$T/th3" -- \
  "$LM" infer --model x --input y --output "$T/th3" --threads 100000

finish
