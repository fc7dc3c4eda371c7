#!/bin/bash
# Stop 86: the viewer's decoder with views built on WebAssembly SIMD against stop 85's
# (OLD = a copy of 9f27ede's formats/web), on the six grids' 40 dB files in /tmp/dec:
#   bash docs/bench/web/predict_stop86/run_ab.sh OLD_CHECKOUT OUT_DIR
OLD=$1; OUT=$2; mkdir -p "$OUT"
G="hci_antinous lytro_dino_2067 stanford_chess hci_buddha stanford_lytro_general_11 epfl_iso_chart_1"
for g in $G; do
  node tools/web_predict_kernel.mjs /tmp/dec/$g.lfc 3 | sed "s/^/$g /" >> "$OUT/kernel_vs_loops.txt"
  node tools/web_decode_ab.mjs "$OLD" /tmp/dec/$g.lfc 3 | sed "s/^/$g /" >> "$OUT/decode_ab.txt"
  for r in 1 2; do
    ROOT=$OLD node docs/bench/web/kernel_stop85/open_first_frame.mjs /tmp/dec/$g.lfc | sed "s/^/old /" >> "$OUT/open_first_frame.txt"
    node docs/bench/web/kernel_stop85/open_first_frame.mjs /tmp/dec/$g.lfc | sed "s/^/new /" >> "$OUT/open_first_frame.txt"
  done
done
