# Renderers with keep_freed (the default since stop 89) against --malloc-default (glibc's own
# settings, the library's renderer before), fresh processes, the order alternated per round.
# Prints: grid, mode, first frame ms, warm fps, first frame ms (fast), warm fps (fast).
# usage: bash ab.sh ROUNDS > ab.txt   (files from `lfcodec encode ... --target-psnr 40` in /tmp/dec)
for r in $(seq "${1:-3}"); do for g in epfl_iso_chart_1 stanford_lytro_general_11 stanford_chess hci_buddha hci_antinous lytro_dino_2067; do
  if [ $((r % 2)) = 1 ]; then order="default keep"; else order="keep default"; fi
  for m in $order; do
    flag=""; [ $m = default ] && flag="--malloc-default"
    python -m tools.bench_render /tmp/dec/$g.lfc $flag 2>&1 | python -c "
import sys, json
t = sys.stdin.read(); s = json.loads(t[t.index('{'):])['scenes'][0]
print('$g', '$m', s['first_frame_ms'], s['warm_fps'], s['first_frame_ms_fast'], s['warm_fps_fast'], flush=True)"
  done
done; done
