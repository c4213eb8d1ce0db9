#!/usr/bin/env bash
# eval.sh — end-to-end tests of `lumosaic eval`: train a linear model briefly on the CAVE scene
# balloons_crop100, evaluate it (--split all, noise 0 and 10 %, rainbow 96): eval.json holds the
# per-scene, mean and rainbow fields with sane values, PSNR at noise 0 >= PSNR at noise 10,
# eval.csv has a row per scene and level plus the means, the printed table has a row per level,
# the same seed gives the same files and another seed other noisy numbers; the scene belongs to
# exactly one of the test/val/train splits; --motion 0,240: per-scene and mean motion rows in
# eval.json and eval_motion.csv (px/frame, static reference, aligned, unaligned), the still
# row's unaligned score equals its static reference, aligned >= unaligned (- 0.1 dB) at 0 and
# 240 px/s, --align plain runs and --align bogus is refused; --photons / --read-noise add shot and
# read noise (recorded in eval.json, lower PSNR); seconds per frame in the table and eval.json;
# scoring the scene it was trained on gives a warning line, also for a renamed copy of it
# (content hashes recorded in the checkpoint), not for another scene; --scenes picks scenes by
# name (an unknown name, or --split with it, refused); bad input: missing model, not a model, no DATA,
# missing scene, bad noise / motion list, too small rainbow, bad split, unknown option, used output
# folder — one line on stderr, exit 2, no output left.
# The passive RGB baseline: a 3-iteration mst-tiny run (its saved model takes 3-channel RGB
# input: conv_in 31 x 3 x 3 x 3) evaluated with --noise 0,10 --motion 0,120 --rainbow 66: the
# same eval.json / eval.csv / eval_motion.csv fields, finite values, aligned = unaligned, the
# still motion row = its static reference; --device opencl is refused for MST++ (or no OpenCL).
# The QDO baseline: a 2-iteration qdo-mst run evaluated with --noise 0,10 --rainbow 66;
# `info --doe` on the bundled DOE and on a file missing a field (exit 2, one line).
# usage: eval.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"

R=$T/run
"$LM" train --model linear --data "$CAVE" --iterations 60 --batch 4 --accum-steps 1 --lr 5e-3 \
  --synth-fraction 0 --noise 0,0 --val-patches 1 --output "$R" --quiet > "$T/log" 2>&1
check "train: $(cat "$T/log")" [ -s "$R/model.safetensors" ]

# ---- happy path ------------------------------------------------------------------------
O=$T/ev
"$LM" eval --model "$R" "$CAVE" --split all --noise 0,10 --rainbow 96 --output "$O" \
  > "$T/table" 2> "$T/err"
check "eval run: $(cat "$T/err")" [ $? -eq 0 ]
cat "$T/table"
check "json written" [ -s "$O/eval.json" ]
check "no staging folder left" no_output "$O.tmp"
check "table has a row per noise level" \
  [ "$(grep -cE '^ +(0|10) +[0-9.]+ +[0-9.]+ +[0-9.]+ +[0-9.]+ +[0-9.]+$' "$T/table")" -eq 2 ]
check "table times the frames" grep -qE '^ +noise % +PSNR dB .* s/frame$' "$T/table"
check "seconds per frame in eval.json" python3 -c "
import json, sys
j = json.load(open(sys.argv[1]))
assert all(r['seconds_per_frame'] > 0 for r in j['mean'])
assert all(r['seconds_per_frame'] > 0 for s in j['scenes'] for r in s['results'])" "$O/eval.json"
# the model was trained on the scene it is scored on: one warning line, by content
check "training-set overlap warned: $(cat "$T/err")" \
  grep -q "^lumosaic eval: warning: scene balloons_crop100 (.*) was in the model's training set" "$T/err"
check "table reports the rainbow" grep -q '^rainbow 96 x 96: peak error mean' "$T/table"
# fields, ranges and PSNR(noise 0) >= PSNR(noise 10), per scene and for the mean
python3 - "$O/eval.json" <<'PY'
import json, math, sys
j = json.load(open(sys.argv[1]))
assert j["split"] == "all" and j["noise_percent"] == [0, 10], j
assert len(j["scenes"]) == 1 and j["scenes"][0]["name"] == "balloons_crop100"
s = j["scenes"][0]
assert s["height"] % 3 == 0 and s["width"] % 4 == 0 and s["height"] >= 66, s
for rows in (s["results"], j["mean"]):
    assert [r["noise_percent"] for r in rows] == [0, 10]
    for r in rows:
        assert 5 < r["psnr"] < 100 and 0 < r["ssim"] <= 1 and 0 < r["mae"] < 1 \
            and 0 < r["sam"] < 90, r
    assert rows[0]["psnr"] >= rows[1]["psnr"], rows
    assert rows[0]["ssim"] >= rows[1]["ssim"], rows
assert s["results"] == j["mean"]  # one scene: the mean is that scene
rb = j["rainbow"]
assert rb["size"] == 96 and rb["height"] == 96 and rb["width"] == 96
assert 0 <= rb["peak_error_mean_nm"] <= rb["peak_error_max_nm"] <= 300, rb
assert 0 <= rb["worst_row"] < 96 and math.isfinite(rb["psnr"])
PY
check "eval.json fields and PSNR(0) >= PSNR(10)" [ $? -eq 0 ]
check "csv header" [ "$(head -1 "$O/eval.csv")" = "scene,noise_percent,psnr,ssim,mae,sam" ]
check "csv rows: scene and mean per level" [ "$(grep -cE '^(balloons_crop100|mean),(0|10),' "$O/eval.csv")" -eq 4 ]

# determinism: the same seed, the same numbers; another seed, other noise
"$LM" eval --model "$R/model.safetensors" "$CAVE" --split all --noise 0,10 --rainbow 96 \
  --output "$T/ev2" > /dev/null 2>&1
check "same seed, same csv" cmp -s "$O/eval.csv" "$T/ev2/eval.csv"
"$LM" eval --model "$R" "$CAVE" --split all --noise 0,10 --rainbow 0 --seed 7 --output "$T/ev3" \
  > /dev/null 2>&1
check "rainbow 0 skips the rainbow" bash -c "! grep -q rainbow '$T/ev3/eval.json'"
check "another seed, the same noise-free rows" \
  cmp -s <(grep ',0,' "$O/eval.csv") <(grep ',0,' "$T/ev3/eval.csv")
check_not "another seed, other noise" cmp -s <(grep ',10,' "$O/eval.csv") <(grep ',10,' "$T/ev3/eval.csv")
# shot and read noise on top of the levels: recorded, and they cost PSNR at level 0
"$LM" eval --model "$R" "$CAVE" --split all --noise 0 --rainbow 0 --photons 50 --read-noise 2 \
  --output "$T/ev4" > /dev/null 2> "$T/err"
check "eval --photons: $(cat "$T/err")" [ $? -eq 0 ]
python3 - "$O/eval.json" "$T/ev4/eval.json" <<'PY'
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:])
assert a["photons"] == 0 and b["photons"] == 50 and b["read_noise"] == 2, (a["photons"], b)
assert b["mean"][0]["psnr"] < a["mean"][0]["psnr"] - 0.3 and b["mean"][0]["ssim"] < a["mean"][0]["ssim"] - 0.05, (b["mean"][0], a["mean"][0])
PY
check "eval --photons --read-noise: recorded, lower PSNR" [ $? -eq 0 ]

# the scene is in exactly one split (one scene: train; the others borrow, nothing to evaluate)
n_ok=0
for s in test val train; do
  "$LM" eval --model "$R" "$CAVE" --split $s --noise 0 --rainbow 0 > /dev/null 2> "$T/err_$s"
  rc=$?
  if [ $rc -eq 0 ]; then n_ok=$((n_ok + 1))
  else check "split $s empty: exit 2 one line" [ $rc -eq 2 ] && check "split $s message" \
    grep -q "no scene of split '$s' among the 1 given" "$T/err_$s"; fi
done
check "the scene is in exactly one split ($n_ok)" [ $n_ok -eq 1 ]

# ---- motion (--motion): fields, rows, and alignment not worse at the largest speed --------
"$LM" eval --model "$R" "$CAVE" --split all --noise 0 --rainbow 0 --motion 0,240 \
  --output "$T/evm" > "$T/mtable" 2> "$T/merr"
check "eval --motion: $(cat "$T/merr")" [ $? -eq 0 ]
cat "$T/mtable"
check "motion table has a row per speed" \
  [ "$(grep -cE '^ +0 +(0|240) +[0-9.]+( +[0-9.]+){7}$' "$T/mtable")" -eq 2 ]
python3 - "$T/evm/eval.json" <<'PY'
import json, math, sys
j = json.load(open(sys.argv[1]))
assert j["motion_speeds_px_s"] == [0, 240], j
keys = ["noise_percent", "speed_px_s", "px_per_frame", "psnr_static", "psnr_aligned", "psnr_unaligned", "ssim_aligned", "ssim_unaligned",
        "mae_aligned", "mae_unaligned", "sam_aligned", "sam_unaligned"]
for rows in (j["scenes"][0]["motion"], j["motion_mean"]):
    assert [r["speed_px_s"] for r in rows] == [0, 240], rows
    for r in rows:
        assert sorted(r) == sorted(keys), r
        assert all(math.isfinite(r[k]) for k in keys), r
    still, fast = rows
    # still scene: the middle frame is the static frame, alignment keeps it
    assert abs(still["psnr_aligned"] - still["psnr_unaligned"]) < 0.05, still
    assert abs(still["psnr_unaligned"] - still["psnr_static"]) < 1e-6, still
    assert still["px_per_frame"] == 0 and abs(fast["px_per_frame"] - 8) < 1e-6, fast
    assert fast["psnr_aligned"] >= fast["psnr_unaligned"] - 0.1, fast
    assert fast["psnr_static"] > fast["psnr_unaligned"], fast
    assert fast["sam_aligned"] <= fast["sam_unaligned"] + 0.1, fast
PY
check "eval.json motion fields, still = static, aligned >= unaligned at 240 px/s" [ $? -eq 0 ]
check "motion csv header" [ "$(head -1 "$T/evm/eval_motion.csv")" = \
  "scene,motion_px_s,px_per_frame,psnr_static,psnr_aligned,psnr_unaligned,ssim_aligned,ssim_unaligned,mae_aligned,mae_unaligned,sam_aligned,sam_unaligned,noise_percent" ]
check "motion csv rows: scene and mean per speed" \
  [ "$(grep -cE '^(balloons_crop100|mean),(0|240),' "$T/evm/eval_motion.csv")" -eq 4 ]
check "no motion csv without --motion" [ ! -e "$O/eval_motion.csv" ]
"$LM" eval --model "$R" "$CAVE" --split all --noise 0 --rainbow 0 --motion 0,240 \
  --motion-noise 0,10 --output "$T/evn" > "$T/ntable" 2> "$T/nerr"
check "eval --motion-noise: $(cat "$T/nerr")" [ $? -eq 0 ]
python3 - "$T/evn/eval.json" "$T/evm/eval.json" <<'PY'
import json, sys
j, j0 = json.load(open(sys.argv[1])), json.load(open(sys.argv[2]))
assert j["motion_noise_percent"] == [0, 10], j
rows = j["motion_mean"]
assert [(r["noise_percent"], r["speed_px_s"]) for r in rows] == [(0, 0), (0, 240), (10, 0), (10, 240)], rows
assert rows[:2] == j0["motion_mean"], (rows, j0["motion_mean"])  # noise-free rows unchanged
for clean, noisy in zip(rows[:2], rows[2:]):
    assert noisy["psnr_aligned"] < clean["psnr_aligned"] - 0.3, (clean, noisy)
    assert noisy["psnr_static"] < clean["psnr_static"] - 0.3, (clean, noisy)
PY
check "motion rows at 0 and 10 % noise (noise-free rows as without the flag)" [ $? -eq 0 ]
# the same scene copied under another name is still the training scene; another scene is not
mkdir -p "$T/copy" "$T/other"
cp -r "$CAVE" "$T/copy/renamed"
for f in "$T/copy/renamed"/*; do mv "$f" "$(dirname "$f")/$(basename "$f" | sed 's/^balloons_crop100/renamed/')"; done
"$MK" "$T/other/synthetic.exr" good 66 64
"$LM" eval --model "$R" "$T/copy" "$T/other" --scenes renamed,synthetic --noise 0 --rainbow 0 \
  > "$T/stable" 2> "$T/serr"
check "eval --scenes: $(cat "$T/serr")" [ $? -eq 0 ]
check "--scenes: two scenes scored" grep -q '^2 scene(s), chosen by --scenes' "$T/stable"
check "a renamed copy of a training scene is warned" \
  grep -q "warning: scene renamed (.*) was in the model's training set" "$T/serr"
check "one warning only (not the other scene)" [ "$(grep -c 'warning: scene' "$T/serr")" -eq 1 ]
"$LM" eval --model "$R" "$T/other" --split all --noise 0 --rainbow 0 > /dev/null 2> "$T/serr"
check "no training scene scored: no warning ($(cat "$T/serr"))" bash -c "! grep -q warning '$T/serr'"
# many training scenes scored (the bundled model on its own training split): one line names them
BM=$(cd "$(dirname "$0")/../.." && pwd)/models/demo/tn160nc-lmmse.safetensors
"$LM" eval --model "$BM" "$SHARED/data/cave" "$SHARED/data/cave-256" --split train --noise 0 \
  --rainbow 0 > /dev/null 2> "$T/terr"
check "--split train: one warning line ($(head -c 300 "$T/terr"))" \
  [ "$(grep -c warning "$T/terr")" -eq 1 ]
check "--split train: it counts and names the training scenes" \
  grep -q "warning: 21 of the 21 scored scenes were in the model's training set (.*balloons" "$T/terr"
expect_error "--scenes: unknown name" 2 "--scenes: no scene 'nope' among the 2 given" "$T/e14" -- \
  "$LM" eval --model "$R" "$T/copy" "$T/other" --scenes synthetic,nope --output "$T/e14"
expect_error "--scenes with --split" 2 "not both" "$T/e15" -- \
  "$LM" eval --model "$R" "$CAVE" --scenes balloons_crop100 --split all --output "$T/e15"
expect_error "bad motion noise" 2 "--motion-noise" "$T/e13" -- "$LM" eval --model "$R" "$CAVE" --motion 0 --motion-noise 0,x --output "$T/e13"
"$LM" eval --model "$R" "$CAVE" --split all --noise 0 --rainbow 0 --motion 240 --align plain \
  > "$T/ptable" 2> "$T/perr"
check "eval --align plain: $(cat "$T/perr")" [ $? -eq 0 ]
check "plain alignment is named in the table" grep -q 'alignment plain' "$T/ptable"
"$LM" eval --model "$R" "$CAVE" --split all --noise 0 --rainbow 0 --motion 240 --align bogus \
  > /dev/null 2> "$T/perr"
check "eval --align bogus refused (exit 2)" [ $? -eq 2 ]

# ---- the passive RGB baseline (MST++): train briefly on RGB, evaluate --------------------
RM=$T/run_mst
"$LM" train --model mst-tiny --data "$CAVE" --iterations 3 --batch 2 --accum-steps 1 \
  --synth-fraction 0 --noise 0,0 --val-patches 1 --output "$RM" --quiet > "$T/mlog" 2>&1
check "train mst-tiny: $(cat "$T/mlog")" [ -s "$RM/model.safetensors" ]
python3 - "$RM/model.safetensors" <<'PY'
import json, struct, sys
f = open(sys.argv[1], "rb"); n = struct.unpack("<Q", f.read(8))[0]; h = json.loads(f.read(n))
assert h["__metadata__"]["preset"] == "mst-tiny", h["__metadata__"]
assert h["conv_in.weight"]["shape"] == [31, 3, 3, 3], h["conv_in.weight"]  # RGB input
PY
check "mst-tiny run takes RGB input" [ $? -eq 0 ]
"$LM" eval --model "$RM" "$CAVE" --split all --noise 0,10 --rainbow 66 --motion 0,120 \
  --output "$T/evr" > "$T/rtable" 2> "$T/rerr"
check "eval mst-tiny: $(cat "$T/rerr")" [ $? -eq 0 ]
cat "$T/rtable"
check "mst table has a row per noise level" \
  [ "$(grep -cE '^ +(0|10) +[0-9.]+ +[0-9.]+ +[0-9.]+ +[0-9.]+ +[0-9.]+$' "$T/rtable")" -eq 2 ]
check "mst table reports the rainbow" grep -q '^rainbow 64 x 66: peak error mean' "$T/rtable"
python3 - "$T/evr/eval.json" <<'PY'
import json, math, sys
j = json.load(open(sys.argv[1]))
assert j["noise_percent"] == [0, 10] and len(j["scenes"]) == 1, j
s = j["scenes"][0]
for rows in (s["results"], j["mean"]):
    assert [r["noise_percent"] for r in rows] == [0, 10]
    for r in rows:
        assert sorted(r) == ["mae", "noise_percent", "psnr", "sam", "seconds_per_frame", "ssim"], r
        assert all(math.isfinite(v) for v in r.values()) and r["mae"] > 0, r
for rows in (s["motion"], j["motion_mean"]):
    assert [r["speed_px_s"] for r in rows] == [0, 120], rows
    for r in rows:  # one RGB frame: nothing to align
        for m in ("psnr", "ssim", "mae", "sam"):
            assert math.isfinite(r[m + "_aligned"]) and r[m + "_aligned"] == r[m + "_unaligned"], r
    assert abs(rows[0]["psnr_unaligned"] - rows[0]["psnr_static"]) < 1e-6, rows
rb = j["rainbow"]
assert rb["height"] == 66 and rb["width"] == 64 and math.isfinite(rb["psnr"]), rb
assert 0 <= rb["peak_error_mean_nm"] <= rb["peak_error_max_nm"] <= 300, rb
PY
check "mst eval.json fields, aligned = unaligned, still = static reference" [ $? -eq 0 ]
check "mst csv rows" [ "$(grep -cE '^(balloons_crop100|mean),(0|10),' "$T/evr/eval.csv")" -eq 4 ]
check "mst motion csv rows" \
  [ "$(grep -cE '^(balloons_crop100|mean),(0|120),' "$T/evr/eval_motion.csv")" -eq 4 ]
"$LM" eval --model "$RM" "$CAVE" --split all --noise 0 --rainbow 0 --device opencl \
  --output "$T/evo" > /dev/null 2> "$T/oerr"
check "mst on opencl refused (exit 2)" [ $? -eq 2 ]
check "mst on opencl: one line" [ "$(wc -l < "$T/oerr")" -eq 1 ]
check "mst on opencl: message" grep -qE "CPU only|device" "$T/oerr"
check "mst on opencl: no output" no_output "$T/evo"

# ---- the QDO baseline (MST++-tiny behind the bundled DOE): train briefly, evaluate ---------
RQ=$T/run_qdo
"$LM" train --model qdo-mst --data "$CAVE" --iterations 2 --batch 2 --accum-steps 1 --patch 24x32 \
  --synth-fraction 0 --noise 0,0 --val-patches 1 --output "$RQ" --quiet > "$T/qlog" 2>&1
check "train qdo-mst: $(cat "$T/qlog")" [ -s "$RQ/model.safetensors" ]
"$LM" eval --model "$RQ" "$CAVE" --split all --noise 0,10 --rainbow 66 --output "$T/evq" \
  > "$T/qtable" 2> "$T/qerr"
check "eval qdo-mst: $(cat "$T/qerr")" [ $? -eq 0 ]
check "qdo table has a row per noise level" \
  [ "$(grep -cE '^ +(0|10) +[0-9.]+ +[0-9.]+ +[0-9.]+ +[0-9.]+ +[0-9.]+$' "$T/qtable")" -eq 2 ]
check "qdo csv rows" [ "$(grep -cE '^(balloons_crop100|mean),(0|10),' "$T/evq/eval.csv")" -eq 4 ]
"$LM" info --doe default > "$T/doe_info" 2>&1
check "info --doe default: $(cat "$T/doe_info")" grep -qE '^ +550 +0\.[0-9]+ ' "$T/doe_info"
echo '{"version": 1, "aperture_mm": 0.5}' > "$T/bad_doe.json"
"$LM" info --doe "$T/bad_doe.json" > /dev/null 2> "$T/doe_err"
check "bad DOE file: exit 2" [ $? -eq 2 ]
check "bad DOE file: one line" [ "$(wc -l < "$T/doe_err")" -eq 1 ]
check "bad DOE file: names the file and field" grep -q 'bad_doe.json: doe_pitch_um: missing' "$T/doe_err"

# ---- bad input ---------------------------------------------------------------------------
expect_error "missing model" 2 "no such model" "$T/e1" -- "$LM" eval --model "$T/nope" "$CAVE" --output "$T/e1"
echo "not safetensors" > "$T/bogus.safetensors"
expect_error "not a model" 2 "bogus.safetensors" "$T/e2" -- "$LM" eval --model "$T/bogus.safetensors" "$CAVE" --output "$T/e2"
expect_error "no DATA" 2 "no DATA given" "$T/e3" -- "$LM" eval --model "$R" --output "$T/e3"
expect_error "missing scene" 2 "nothing_here" "$T/e4" -- "$LM" eval --model "$R" "$T/nothing_here" --split all --output "$T/e4"
expect_error "bad noise" 2 "--noise" "$T/e5" -- "$LM" eval --model "$R" "$CAVE" --noise 0,abc --output "$T/e5"
expect_error "noise > 100" 2 "--noise" "$T/e6" -- "$LM" eval --model "$R" "$CAVE" --noise 0,150 --output "$T/e6"
expect_error "rainbow too small" 2 "--rainbow" "$T/e7" -- "$LM" eval --model "$R" "$CAVE" --rainbow 10 --output "$T/e7"
expect_error "bad split" 2 "--split" "$T/e8" -- "$LM" eval --model "$R" "$CAVE" --split bogus --output "$T/e8"
expect_error "bad motion" 2 "--motion" "$T/e11" -- "$LM" eval --model "$R" "$CAVE" --motion 0,fast --output "$T/e11"
expect_error "negative motion" 2 "--motion" "$T/e12" -- "$LM" eval --model "$R" "$CAVE" --motion -5 --output "$T/e12"
expect_error "unknown option" 2 "unknown option" "$T/e9" -- "$LM" eval --model "$R" "$CAVE" --bogus --output "$T/e9"
expect_error "missing --model" 2 "--model is required" "$T/e10" -- "$LM" eval "$CAVE" --output "$T/e10"
mkdir -p "$T/used" && touch "$T/used/x"
"$LM" eval --model "$R" "$CAVE" --split all --noise 0 --rainbow 0 --output "$T/used" > /dev/null 2> "$T/err"
check "used output folder refused (exit 2)" [ $? -eq 2 ]
check "used output folder untouched" [ "$(ls "$T/used")" = x ]

finish
