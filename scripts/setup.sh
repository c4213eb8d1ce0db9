#!/usr/bin/env bash
# setup.sh — everything a fresh Debian 12 machine needs, then a Release build in build/.
# Installs (apt-get, only what is missing): compiler, CMake, OpenBLAS, jansson, OpenImageIO,
# libpng, matio, HDF5 (headers: the .mat reader's v7.3 checks), OpenEXR, the OpenCL ICD loader + headers
# and PoCL (CPU OpenCL driver), gnuplot (the charts of `lumosaic study`), Open MPI (data-parallel
# training: `mpirun -np N lumosaic train`), FFTW
# (single precision: the DOE optics and PSF convolution of the QDO baseline), Chromium (the
# headless browser that loads the page of `lumosaic report` in its test, label "browser"),
# python3-venv and Ninja (`pip install ./python`: a virtual environment, the library's parallel
# build).
set -euo pipefail
cd "$(dirname "$0")/.."

pkgs=(build-essential cmake pkg-config libopenblas-dev libjansson-dev libopenimageio-dev
      libpng-dev libmatio-dev libhdf5-dev libopenexr-dev zlib1g-dev ocl-icd-opencl-dev
      opencl-headers pocl-opencl-icd clinfo python3 python3-venv ninja-build gnuplot-nox
      libopenmpi-dev openmpi-bin libfftw3-dev chromium)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  sudo=""
  [ "$(id -u)" -ne 0 ] && sudo="sudo"
  echo "setup: installing ${missing[*]}"
  $sudo apt-get update -q
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -q --no-install-recommends "${missing[@]}"
fi

# A portable build (any x86-64 CPU; the hot kernels are chosen at run time) that never stops on
# a compiler warning. LM_NATIVE=ON builds for this machine only; LM_WERROR=ON (the test suite)
# makes warnings errors.
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DLM_WERROR="${LM_WERROR:-OFF}" \
    -DLM_NATIVE="${LM_NATIVE:-OFF}" > /dev/null
cmake --build build -j"$(nproc)"
