#!/usr/bin/env bash
# Set-up (scripts/setup.sh) and the main job on the built-in default scene.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
build/bin/single-particle -output_dir out/single-particle "$@"
