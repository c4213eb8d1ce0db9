# qdo.sh — the QDO baseline's DOE options end to end: train qdo-mst with a given DOE (--doe), the
# run's doe.json used by eval (removing it changes the scores), --optimise-doe changing the
# height map and writing a DOE that other commands accept, resume of an optimising run, bad DOE
# files and options (one line, exit 2). A small DOE (27 x 27 samples, grid 48, 5 x 5 PSFs)
# keeps it fast.
source "$(dirname "$0")/lib.sh"

cat > "$T/small.json" <<'JSON'
{"version": 1, "name": "small", "aperture_mm": 0.05, "doe_pitch_um": 2, "grid": 48,
 "levels": 0, "material": "fused_silica",
 "profile": {"type": "fresnel_lens", "focal_mm": 1.3, "design_nm": 550},
 "sensor_distance_mm": 1, "sensor_pitch_um": 20, "psf_size": 5}
JSON
COMMON=(--model qdo-mst --data "$CAVE" --batch 2 --accum-steps 1 --patch 24x32
        --synth-fraction 0 --noise 0,0 --val-patches 1 --threads 1 --quiet)

# ---- a fixed, given DOE ---------------------------------------------------------------------
"$LM" train "${COMMON[@]}" --iterations 2 --doe "$T/small.json" --output "$T/fixed" \
  > "$T/log1" 2>&1
check "train --doe: $(cat "$T/log1")" [ -s "$T/fixed/doe.json" ]
check "fixed run: no optimiser state" [ ! -e "$T/fixed/doe_state.safetensors" ]
check "fixed run's doe.json is a height map" grep -q '"height_map"' "$T/fixed/doe.json"
"$LM" info --doe "$T/fixed/doe.json" > "$T/info1" 2>&1
check "info --doe accepts the run's DOE: $(cat "$T/info1")" grep -q 'height map' "$T/info1"
"$LM" eval --model "$T/fixed" "$CAVE" --split all --noise 0 --output "$T/ev1" > /dev/null 2>&1
check "eval with the run's DOE" [ -s "$T/ev1/eval.csv" ]
mv "$T/fixed/doe.json" "$T/fixed/doe.moved"
"$LM" eval --model "$T/fixed" "$CAVE" --split all --noise 0 --output "$T/ev2" > /dev/null 2>&1
check "eval without it (bundled DOE)" [ -s "$T/ev2/eval.csv" ]
check_not "eval used the run's DOE (scores differ without it)" cmp -s "$T/ev1/eval.csv" "$T/ev2/eval.csv"

# ---- optimising -----------------------------------------------------------------------------
"$LM" train "${COMMON[@]}" --iterations 3 --doe "$T/small.json" --optimise-doe --doe-lr 0.05 \
  --doe-quantise ste --checkpoint-interval 2 --output "$T/opt" > "$T/log2" 2>&1
check "train --optimise-doe: $(cat "$T/log2")" [ -s "$T/opt/doe_state.safetensors" ]
check_not "the height map changed" cmp -s "$T/opt/doe_heights.png" "$T/fixed/doe_heights.png"
"$LM" train "${COMMON[@]}" --iterations 3 --doe "$T/small.json" --optimise-doe --doe-lr 0.05 \
  --doe-quantise ste --checkpoint-interval 2 --output "$T/opt_again" > /dev/null 2>&1
check "same seed, same learned DOE" cmp -s "$T/opt/doe_heights.png" "$T/opt_again/doe_heights.png"
check "same seed, same DOE state" cmp -s "$T/opt/doe_state.safetensors" "$T/opt_again/doe_state.safetensors"
# the tensors after each file's header (its metadata holds the training seconds)
tensors() { tail -c +$(( $(od -An -t u8 -N8 "$1") + 9 )) "$1"; }
check "same seed, same weights" cmp -s <(tensors "$T/opt/model.safetensors") \
  <(tensors "$T/opt_again/model.safetensors")
check_not "(the weights check can fail)" cmp -s <(tensors "$T/opt/model.safetensors") \
  <(tensors "$T/fixed/model.safetensors")
grep -q '"optimise": true' "$T/opt/config.json"
check "config.json records the doe object" [ $? -eq 0 ]
"$LM" train "${COMMON[@]}" --iterations 2 --doe "$T/opt/doe.json" --output "$T/reuse" \
  > "$T/log3" 2>&1
check "a learned DOE trains again: $(cat "$T/log3")" [ -s "$T/reuse/model.safetensors" ]
cp -r "$T/opt" "$T/opt2"
"$LM" train --resume "$T/opt2" --iterations 4 --quiet > "$T/log4" 2>&1
check "resume an optimising run: $(cat "$T/log4")" [ $? -eq 0 ]
check_not "resume moved the heights on" cmp -s "$T/opt2/doe_heights.png" "$T/opt/doe_heights.png"
cat > "$T/cfg.json" <<JSON
{"version": 1, "model": "qdo-mst", "doe": {"file": "small.json", "optimise": true, "lr": 0.02,
 "quantise": "progressive", "bands": 2}}
JSON
"$LM" train --config "$T/cfg.json" --data "$CAVE" --batch 2 --accum-steps 1 --patch 24x32 \
  --synth-fraction 0 --noise 0,0 --val-patches 1 --iterations 1 --output "$T/cfgrun" --quiet \
  > "$T/log5" 2>&1
check "config \"doe\" object (path relative to the config): $(cat "$T/log5")" \
  [ -s "$T/cfgrun/doe_state.safetensors" ]

echo '{"version": 1, "aperture_mm": 0.5}' > "$T/bad.json"

"$LM" train "${COMMON[@]/qdo-mst/qdo-mst-doe}" --iterations 1 --doe "$T/small.json" \
  --output "$T/preset" > "$T/log6" 2>&1
check "preset qdo-mst-doe learns the DOE: $(cat "$T/log6")" [ -s "$T/preset/doe_state.safetensors" ]

# ---- simulate --doe: the QDO camera's RGB image ----------------------------------------------
"$LM" simulate --input "$CAVE" --crop --doe default --noise 0.01 --output "$T/sim1" > /dev/null 2>&1
check "simulate --doe default" [ -s "$T/sim1/frames/frame_0000.exr" ]
check "simulate --doe preview" [ -s "$T/sim1/frames/frame_0000.png" ]
check "simulate.json names the DOE" grep -q '"doe": "default"' "$T/sim1/simulate.json"
"$LM" simulate --input "$CAVE" --crop --doe "$T/opt/doe.json" --noise 0.01 --output "$T/sim2"   > /dev/null 2>&1
check "simulate --doe with a learned DOE" [ -s "$T/sim2/frames/frame_0000.exr" ]
check_not "another DOE, another image" cmp -s "$T/sim1/frames/frame_0000.exr" "$T/sim2/frames/frame_0000.exr"
expect_error "simulate: bad DOE" 2 "bad.json: doe_pitch_um: missing" "$T/s3" -- \
  "$LM" simulate --input "$CAVE" --crop --doe "$T/bad.json" --output "$T/s3"
expect_error "simulate: --doe with --video" 2 "no --video" "$T/s4" -- \
  "$LM" simulate --input "$CAVE" --crop --doe default --video --output "$T/s4"

# ---- bad input ------------------------------------------------------------------------------
expect_error "bad DOE file" 2 "bad.json: doe_pitch_um: missing" "$T/b1" -- \
  "$LM" train "${COMMON[@]}" --iterations 1 --doe "$T/bad.json" --output "$T/b1"
expect_error "missing DOE file" 2 "nope.json" "$T/b2" -- \
  "$LM" train "${COMMON[@]}" --iterations 1 --doe "$T/nope.json" --output "$T/b2"
expect_error "bad quantise" 2 "doe_quantise" "$T/b3" -- \
  "$LM" train "${COMMON[@]}" --iterations 1 --doe-quantise round --output "$T/b3"
expect_error "doe on a non-QDO model" 2 "only for the QDO presets" "$T/b4" -- \
  "$LM" train --model mst-tiny --data "$CAVE" --synth-fraction 0 --patch 24x32 --iterations 1 \
  --optimise-doe --output "$T/b4"
sed 's/"psf_size": 5/"psf_size": 5, "extra": 1/' "$T/small.json" > "$T/extra.json"
expect_error "unknown DOE field" 2 "extra: unknown field" "$T/b5" -- \
  "$LM" train "${COMMON[@]}" --iterations 1 --doe "$T/extra.json" --output "$T/b5"
cp "$T/fixed/doe.moved" "$T/hm.json"
expect_error "height map file missing" 2 "doe_heights.png" "$T/b6" -- \
  "$LM" train "${COMMON[@]}" --iterations 1 --doe "$T/hm.json" --output "$T/b6"
cp -r "$T/opt" "$T/corrupt"
echo '{"version": 1}' > "$T/corrupt/doe.json"
expect_error "eval: the run's doe.json is bad" 2 "corrupt/doe.json: aperture_mm: missing" "$T/b7" -- \
  "$LM" eval --model "$T/corrupt" "$CAVE" --split all --noise 0 --output "$T/b7"
finish
