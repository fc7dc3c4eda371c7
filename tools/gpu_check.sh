#!/bin/bash
# GPU checks for a lent device machine (see DEVELOPERS.md): the renderer's frame rate on the GPU
# (issue 16), LFN training and its curves (issue 17), batched GPU decode (issue 19). Run from the
# repository root on the device, with .gpu/ and .whl/ carried (both ignored by git):
#   .gpu/*.npz   scenes exported here: python -m tools.bench_lfn SCENE --export .gpu/NAME.npz
#                (mitsuba128.npz with --test-scene SCENE for mitsuba128_test.npz; statue128.npz)
#   .gpu/*.lfc   the six dense grids encoded here at --target-psnr 40, and stanford_chess with
#                --warps (tx version 5: the per-view warps' offsets on the device path too)
#   .whl/        the imagecodecs wheel for the device's Python (the device has no OpenImageIO and
#                no imagecodecs; pip download ... --python-version 3.12 imagecodecs)
# Results land in $OUT/results.tgz. LFN_SECONDS (default 150) sets each training's time limit.
set -u
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=8
R=$OUT/r; mkdir -p "$R"
S=${LFN_SECONDS:-150}
T0=$(date +%s); el() { echo "== $(( $(date +%s) - T0 )) s: $*"; }
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv > "$R/gpu.txt"
el render
timeout 170 python3 -m tools.bench_render .gpu/*.lfc --device cuda --out "$R/render" > "$R/render.log" 2>&1
el lfn
L="--depth 8 --min-neurons 16 --max-neurons 256 --steps 1000000 --batch 65536 --time-limit $S --device cuda --no-single-scale"
timeout $((S + 130)) python3 -m tools.bench_lfn .gpu/mitsuba128.npz --test-scene .gpu/mitsuba128_test.npz --out "$R/mitsuba" $L > "$R/mitsuba.log" 2>&1
tail -n 9 "$R/mitsuba.log"
el curve
timeout 60 python3 -m tools.bench_lfn_curve "$R/mitsuba/lfn.lfc" .gpu/mitsuba128.npz --test-scene .gpu/mitsuba128_test.npz --device cuda --out "$R/mitsuba/curve.json"
el ladder
timeout 90 python3 -m tools.bench_lfn_ladder "$R/mitsuba/lfn.lfc" .gpu/mitsuba128.npz --test-scene .gpu/mitsuba128_test.npz --device cuda --out "$R/mitsuba/ladder.json" > "$R/mitsuba/ladder.md" 2>&1
el steps
timeout 120 python3 -m tools.bench_lfn_steps .gpu/mitsuba128.npz --device cuda --out "$R/steps.json"
el decode
# (--check 200000: two chunks in flight compared with numpy, twice; rlfc.torch_decode.PIPELINE stays 1 until this passes)
for f in .gpu/*.lfc; do timeout 60 python3 -m tools.bench_gpu_decode "$f" --counts 200000,1000000 --check 200000 --numpy-max 20000 --parse host,auto,inflight2; done > "$R/decode.txt" 2>&1
el done
cd "$OUT" && tar czf results.tgz r
