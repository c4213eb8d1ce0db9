#!/usr/bin/env bash
# fork.sh — end-to-end tests of `lumosaic train --fork DIR --output NEW`: a fork continues its
# parent exactly (the same losses as the parent resumed, bit for bit), the flags given change
# the fork's config.json and not the parent's, a later --resume keeps them (so does a --resume
# given flags), a time budget stops at the iteration cap, and bad input: exit status, one-line
# message, nothing written; a weight average switched on by a fork.
# usage: fork.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"
TR="--model rt-8 --data $CAVE --patch 24x32 --batch 2 --val-patches 2 --val-interval 3 --threads 1 --workers 0 --seed 3 --quiet"
"$LM" train $TR --iterations 6 --stop-after 3 --snapshots 0.0001 --output "$T/a" > "$T/log" 2>&1
check "parent trained to iteration 3: $(cat "$T/log")" grep -q '^3,' "$T/a/log.csv"
check "parent wrote its snapshot" [ -f "$T/a/snapshots/0.0001min/model.safetensors" ]
"$LM" train --fork "$T/a" --output "$T/b" --quiet > "$T/log" 2>&1
check "fork runs: $(cat "$T/log")" [ $? -eq 0 ]
"$LM" train --resume "$T/a" --quiet > /dev/null 2>&1
check "fork finished" grep -q '^6,' "$T/b/log.csv"
check "the fork's losses are its parent's, resumed" cmp -s "$T/a/log.csv" "$T/b/log.csv"
check "the fork neither copies nor rewrites the parent's snapshots" \
  [ ! -e "$T/b/snapshots/0.0001min" ]
cp -r "$T/a" "$T/a2" && rm -r "$T/a2/snapshots"
"$LM" train --resume "$T/a2" --iterations 7 --quiet > /dev/null 2>&1
check "the copy resumed" grep -q '^7,' "$T/a2/log.csv"
check "a resume does not write a snapshot its checkpoint had passed" [ ! -e "$T/a2/snapshots/0.0001min" ]

"$LM" train --fork "$T/a" --output "$T/c" --iterations 9 --collage 0.5 --stop-after 1 --quiet \
  > /dev/null 2>&1
check "the flags go into the fork's config" grep -q '"iterations": 9' "$T/c/config.json"
check "the collage share too" grep -q '"collage": 0.5' "$T/c/config.json"
check "the parent's config is unchanged" grep -q '"iterations": 6' "$T/a/config.json"
check "paths of the fork's config are relative to it" grep -q '"data": \[' "$T/c/config.json"
"$LM" train --resume "$T/c" --quiet > /dev/null 2>&1
check "a resume without flags keeps the fork's schedule" grep -q '^9,' "$T/c/log.csv"
"$LM" train --resume "$T/b" --iterations 8 --stop-after 1 --quiet > /dev/null 2>&1
check "a resume with flags writes them to the config" grep -q '"iterations": 8' "$T/b/config.json"

# a weight average switched on by a fork: the weights trained follow the plain run's path (the
# same losses as b, resumed to the same 8 iterations), the fork's config keeps the average, and
# it cannot be dropped again (a fork that fails so is removed)
"$LM" train --fork "$T/a" --output "$T/avg" --ema 0.99 --iterations 8 --quiet > "$T/log" 2>&1
check "a fork with --ema runs: $(cat "$T/log")" grep -q '^8,' "$T/avg/log.csv"
check "its config keeps the average" grep -q '"ema": 0.99' "$T/avg/config.json"
"$LM" train --resume "$T/b" --quiet > /dev/null 2>&1
check "the losses with the average are the plain run's" \
  cmp -s <(cut -d, -f1-2 "$T/b/log.csv") <(cut -d, -f1-2 "$T/avg/log.csv")
expect_error "dropping the average" 2 "the run averaged its weights with ema 0.99" "$T/noavg" -- \
  "$LM" train --fork "$T/avg" --output "$T/noavg" --ema 0 --iterations 9 --quiet

# a time budget with an iteration cap reached first: the run ends at the cap (not one update
# at a time at the final learning rate until the budget is spent)
"$LM" train $TR --iterations 5000 --minutes 1 --clock wall --output "$T/cap" > /dev/null 2>&1
last=$(tail -n 1 "$T/cap/log.csv" | cut -d, -f1)
check "a budget run stops at its iteration cap (last update $last)" \
  [ "${last:-0}" -ge 1 -a "${last:-0}" -le 5000 ]
cap=$(sed -n 's/.*"iterations": \([0-9]*\),.*/\1/p' "$T/cap/config.json")
check "its config keeps the cap ($cap)" [ "${cap:-0}" -ge 1 -a "${cap:-0}" -le 5000 ]

R="$LM train"
expect_error "no output" 2 "give the new run folder with --output" "$T/a.tmp" -- $R --fork "$T/a"
expect_error "same folder" 2 "--output is the same folder" "$T/x" -- $R --fork "$T/a" --output "$T/a/../a"
expect_error "not a run" 2 "config.json" "$T/d" -- $R --fork "$T/nope" --output "$T/d"
expect_error "into a run folder" 2 "$T/b" "$T/e" -- $R --fork "$T/a" --output "$T/b"
expect_error "fork and resume" 2 "--resume and --fork" "$T/f" -- $R --fork "$T/a" --resume "$T/b" --output "$T/f"
mkdir -p "$T/nock" && cp "$T/a/config.json" "$T/nock/"
expect_error "no checkpoint" 2 "no checkpoint there" "$T/g" -- $R --fork "$T/nock" --output "$T/g"
expect_error "bad flag" 2 "collage" "$T/h" -- $R --fork "$T/a" --output "$T/h" --collage 3
finish
