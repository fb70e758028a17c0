#!/usr/bin/env bash
# Set-up (scripts/setup.sh) and the main job on the built-in default scene:
# `compact` on petsc-options/default.opts, then the compaction plot, the
# snapshots of the first and last levels (rigid disks grey, deformable ones
# coloured by J - 1) and the force chains of the last level. Extra arguments
# go to `compact`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
out=out/compact
build/bin/compact -options_file petsc-options/default.opts -output_dir "$out" "$@"
/usr/bin/python3 scripts/plot_compaction.py "$out/compaction.png" "$out/curve.csv"
/usr/bin/python3 scripts/plot_levels.py "$out/levels.h5" "$out/snapshots.png" 0 -1
/usr/bin/python3 scripts/plot_levels.py "$out/levels.h5" "$out/force_chains.png" --forces -1
echo "snapshots: $out/snapshots.png   force chains: $out/force_chains.png   compaction plot: $out/compaction.png"
echo "ParaView: open $out/levels.xdmf (a time series over the levels)"
