#!/usr/bin/env bash
# Installs what deformix needs on Debian 12 (as root, idempotent, quiet when
# everything is there) and builds it in Release into build/.
#   bash scripts/setup.sh          what the build, the drivers and the scripts need
#   bash scripts/setup.sh --tests  and what only the tests need (python3-meshio,
#                                  the independent XDMF reader of tests/xdmf_tests.py)
set -euo pipefail
cd "$(dirname "$0")/.."

# libopenblas0-serial: the optimized BLAS behind MUMPS' dense kernels (Debian's
# alternatives prefer it to the reference BLAS that petsc-dev pulls in); one
# thread, so that MPI ranks and ctest -j 2 do not compete for the cores.
packages=(g++ make cmake pkg-config petsc-dev libmetis-dev libhdf5-openmpi-dev openmpi-bin libopenmpi-dev
          libopenblas0-serial googletest libgtest-dev python3 python3-numpy python3-scipy python3-matplotlib python3-h5py)
if [ "${1:-}" = "--tests" ]; then
  packages+=(python3-meshio)
fi
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" -ne 0 ]; then
    echo "deformix setup: missing Debian packages: ${missing[*]}; run as root or install them first" >&2
    exit 1
  fi
  echo "deformix setup: installing ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j "$(nproc)" 2>&1 | grep -E "error|Error|Built target" || true
test -x build/bin/single-particle || { echo "deformix setup: build failed" >&2; exit 1; }
