#!/usr/bin/env bash
# install.sh — the library as a user gets it: `cmake --install` into a temporary prefix, then
# examples/reconstruct.c compiled with nothing but `pkg-config --cflags --libs lumosaic`
# (PKG_CONFIG_PATH=$PREFIX/lib/pkgconfig) and run on the CAVE scene cd_256 with the bundled
# demo model; its PSNR must be a real reconstruction's. Also: the header compiles on its own
# as C and as C++, and the shared library exports the lm_api_* functions only.
# usage: install.sh BUILD_DIR SOURCE_DIR
set -euo pipefail
build=$1
src=$2
scene=${LM_SHARED_DIR:-$src/../shared}/data/cave-256/cd_256
[ -d "$scene" ] || { echo "skipped: $scene not found"; exit 77; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

cmake --install "$build" --prefix "$tmp/prefix" >"$tmp/install.log"
libdir=$(ls -d "$tmp"/prefix/lib*/pkgconfig | head -1 | xargs dirname)
for f in "$tmp/prefix/include/lumosaic.h" "$libdir/liblumosaic.so" "$libdir/pkgconfig/lumosaic.pc" \
         "$tmp/prefix/bin/lumosaic" "$tmp/prefix/bin/lumosaic-reader"; do
  [ -e "$f" ] || { echo "not installed: $f"; exit 1; }
done

export PKG_CONFIG_PATH=$libdir/pkgconfig
flags=$(pkg-config --cflags --libs lumosaic)
# LM_EXAMPLE_CFLAGS: the sanitizer build's library needs its runtime in the program too
cc -std=c11 -Wall -Wextra -Werror ${LM_EXAMPLE_CFLAGS:-} "$src/examples/reconstruct.c" $flags \
  -o "$tmp/reconstruct"
loaded=$(ldd "$tmp/reconstruct" | awk '$1 ~ /^liblumosaic\.so/ { print $3 }')
[ -n "$loaded" ] && [ "$(realpath "$loaded")" = "$(realpath "$libdir/liblumosaic.so")" ] || {
  echo "reconstruct does not load the installed library ($loaded)"; exit 1; }

# the header alone, in C and C++
echo '#include <lumosaic.h>
int main(void) { return LM_API_VERSION_MAJOR < 0; }' >"$tmp/h.c"
cc -std=c99 -Wall -Wextra -Werror -pedantic $(pkg-config --cflags lumosaic) -c "$tmp/h.c" -o "$tmp/h.o"
c++ -Wall -Wextra -Werror -x c++ $(pkg-config --cflags lumosaic) -c "$tmp/h.c" -o "$tmp/h2.o"

# only the API is exported
other=$(nm -D --defined-only "$libdir/liblumosaic.so" | awk '{print $3}' | grep -v '^lm_api_' || true)
[ -z "$other" ] || { echo "exported beyond lm_api_*:"; echo "$other" | head; exit 1; }

out=$("$tmp/reconstruct" "$src/models/demo/rt16nc-lmmse.safetensors" "$scene" 0.05 "$tmp/r.exr")
echo "$out"
psnr=$(echo "$out" | sed -n 's/.*PSNR \([0-9.]*\) dB.*/\1/p')
[ -n "$psnr" ] && awk -v p="$psnr" 'BEGIN { exit !(p > 25 && p < 60) }' || {
  echo "PSNR '$psnr' is not a reconstruction's"; exit 1; }
[ -s "$tmp/r.exr" ] || { echo "no cube written"; exit 1; }

# an error is a message and a non-zero status, not a crash
if "$tmp/reconstruct" "$tmp/missing.safetensors" "$scene" 2>"$tmp/err"; then
  echo "a missing model was accepted"; exit 1
fi
grep -q "missing.safetensors" "$tmp/err" || { echo "no message naming the file:"; cat "$tmp/err"; exit 1; }
echo "install: ok"
