#!/usr/bin/env bash
# hostile.sh — tiny files whose headers claim huge images or cubes (tests/fuzz/regress/): each
# command exits 2 with one line on stderr naming the file, leaves no output, and its peak
# resident memory (cli_peak_rss: the process and any child it waited for) stays within 64 MB of
# the same command failing on a missing input — the headers are refused before any allocation.
# Frames: `infer` on a hostile file alone and as the second frame of a sequence; cubes:
# `render` on CAVE folders with a hostile band, on a spectral EXR claiming a large cube, and on
# .mat files: the reliability v7.3 file with one corrupt byte (libhdf5 reads out of bounds:
# run with glibc.malloc.top_pad=0, under which the old in-process reader always crashed), a v5
# struct claiming 3.4 GB of field names, and v5 files cut short (plain and compressed; read
# with zeros for the missing bands and exit 0 before).
# A relative bound works in both builds (a sanitizer's runtime has its own, larger baseline).
# usage: hostile.sh LUMOSAIC MAKE_CUBE PEAK_RSS
source "$(dirname "$0")/lib.sh"
RSS=$3
REG=$(cd "$(dirname "$0")/../fuzz/regress" && pwd)
MODEL=$(cd "$(dirname "$0")/../.." && pwd)/models/demo/rt16nc-lmmse.safetensors
SLACK_KB=65536

# a valid frame (the first of each hostile sequence)
"$LM" simulate --input "$CAVE" --crop --output "$T/sim" > /dev/null 2>&1 || fail "simulate"
GOOD=$T/sim/frames/frame_0000.png

# the baselines: the same commands failing at once on a missing input
"$RSS" "$T/base_infer.kb" "$LM" infer --model "$MODEL" --input "$T/none.png" --output "$T/o" \
  2> /dev/null
"$RSS" "$T/base_render.kb" "$LM" render --input "$T/none.exr" --output "$T/o.png" 2> /dev/null

# bounded NAME BASE PATTERN OUTPUT -- COMMAND...: expect_error's checks (exit 2, one line with
# PATTERN, no OUTPUT), and a peak RSS within SLACK_KB of BASE's.
bounded() {
  local name=$1 base=$2 pat=$3 out=$4; shift 5
  local kb="$T/$(echo "$name" | tr -c 'a-zA-Z0-9' _).kb"
  expect_error_run "$name" 2 "$pat" "$out" -- "$RSS" "$kb" "$@"
  local peak limit
  peak=$(cat "$kb" 2> /dev/null || echo 0)
  limit=$(( $(cat "$T/base_$base.kb") + SLACK_KB ))
  echo "$name: peak RSS $peak KB (limit $limit KB)"
  check "$name: peak RSS $peak KB over $limit KB" test "$peak" -gt 0 -a "$peak" -le "$limit"
}

seq_of() { # seq_of DIR HOSTILE: DIR/f_0000.png (good) and DIR/f_0001.<ext> (hostile)
  mkdir -p "$1" && cp "$GOOD" "$1/f_0000.png" && cp "$2" "$1/f_0001.${2##*.}"
}
seq_of "$T/seq1" "$REG/frame/tiff-huge-claim-1.tif"
seq_of "$T/seq2" "$REG/frame/tiff-huge-claim-2.tif"
seq_of "$T/seq3" "$REG/frame/png-ratio-claim.png"

# one byte of the pixel data changed (bit rot): one line, not libpng's own complaint as well
cp "$GOOD" "$T/flip.png" && printf '\x5a' | dd of="$T/flip.png" bs=1 seek=$(( $(stat -c %s "$GOOD") / 2 )) conv=notrunc 2> /dev/null

I="$LM infer --model $MODEL --output $T/out"
bounded "png signature's last byte changed" infer "png-ascii-signature.png: cannot read image: not a PNG file" "$T/out" -- $I --input "$REG/frame/png-ascii-signature.png"
bounded "png with a changed byte" infer "flip.png: corrupt PNG" "$T/out" -- $I --input "$T/flip.png"
bounded "tiff 1 (256 channels), frame 2" infer "f_0001.tif: has 256 channels" "$T/out" -- $I --input "$T/seq1"
bounded "tiff 2 (3584 x 61452), frame 2" infer "f_0001.tif: image size 3584 x 61452" "$T/out" -- $I --input "$T/seq2"
bounded "png 8000 x 8000 in 700 bytes, frame 2" infer "f_0001.png" "$T/out" -- $I --input "$T/seq3"
bounded "tiff 2 alone" infer "tiff-huge-claim-2.tif" "$T/out" -- $I --input "$REG/frame/tiff-huge-claim-2.tif"
bounded "exr attribute claiming 1.76 GB" infer "exr-attr-huge-size.exr: not a readable OpenEXR" "$T/out" -- $I --input "$REG/frame/exr-attr-huge-size.exr"
bounded "png 15000 x 15000 alone" infer "png-huge-claim.png: image size 15000 x 15000" "$T/out" -- $I --input "$REG/frame/png-huge-claim.png"

cave_with() { # cave_with DIR BAND FILE: the CAVE scene with band BAND replaced by FILE
  cp -r "$CAVE" "$1" && cp "$3" "$1/balloons_crop100_ms_$2.png"
}
cave_with "$T/cave5" 05 "$REG/frame/png-huge-claim.png"
cave_with "$T/cave1" 01 "$REG/frame/png-ratio-claim.png"
bounded "CAVE band 05 claiming 15000 x 15000" render "ms_05.png" "$T/r.png" -- "$LM" render --input "$T/cave5" --output "$T/r.png"
bounded "CAVE band 01 claiming 8000 x 8000" render "ms_01.png" "$T/r.png" -- "$LM" render --input "$T/cave1" --output "$T/r.png"
bounded "EXR claiming 31 x 2900 x 2900" render "exr-window-claim.exr: a 31 x 2900 x 2900 cube" "$T/r.png" -- "$LM" render --input "$REG/exr_cube/exr-window-claim.exr" --output "$T/r.png"
R="$LM render --output $T/r.png --input"
bounded "mat v7.3, one corrupt byte (top_pad=0)" render "mat-hdf5-corrupt-byte.mat" "$T/r.png" -- env GLIBC_TUNABLES=glibc.malloc.top_pad=0 $R "$REG/mat/mat-hdf5-corrupt-byte.mat"
bounded "mat v5 struct claiming 3.4 GB" render "mat5-struct-huge-fields.mat" "$T/r.png" -- $R "$REG/mat/mat5-struct-huge-fields.mat"
bounded "mat v5 plain, truncated" render "mat5-plain-truncated.mat: truncated" "$T/r.png" -- $R "$REG/mat/mat5-plain-truncated.mat"
bounded "mat v5 zlib, truncated" render "mat5-zlib-truncated.mat: truncated" "$T/r.png" -- $R "$REG/mat/mat5-zlib-truncated.mat"
finish
