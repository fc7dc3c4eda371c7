#!/bin/bash
# Prepare what tools/gpu_check.sh needs on a device machine, here (a few minutes on 2 cores):
#   .gpu/mitsuba128.npz, .gpu/mitsuba128_test.npz, .gpu/statue128.npz  (scenes at 128 px)
#   .gpu/GRID.lfc for the six dense grids at --target-psnr 40
#   .whl/imagecodecs-*.whl for the device's Python 3.12 (x86-64)
# Both folders are added to .git/info/exclude (name them in the device run's `carry`).
# Usage: bash tools/gpu_prepare.sh [SHARED_DATA]   (default ../shared/data; run from the repo root)
set -euo pipefail
D=${1:-../shared/data}
for x in /.gpu/ /.whl/; do grep -qxF "$x" .git/info/exclude 2>/dev/null || echo "$x" >> .git/info/exclude; done
mkdir -p .gpu .whl
python -m tools.bench_lfn "$D/mitsuba_objects_360" --test-scene "$D/mitsuba_objects_360" --out .gpu --export .gpu/mitsuba128.npz
python -m tools.bench_lfn "$D/llff_statue" --out .gpu --export .gpu/statue128.npz
for g in hci_antinous lytro_dino_2067 hci_buddha stanford_chess epfl_iso_chart_1 stanford_lytro_general_11; do
  [ -e ".gpu/$g.lfc" ] || python -m formats encode "$D/$g" ".gpu/$g.lfc" --target-psnr 40 --quiet
done
ls .whl/imagecodecs-*.whl >/dev/null 2>&1 || python -m pip download -q --no-deps --only-binary=:all: \
  --python-version 3.12 --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 \
  --platform manylinux2014_x86_64 -d .whl imagecodecs
du -sh .gpu .whl
