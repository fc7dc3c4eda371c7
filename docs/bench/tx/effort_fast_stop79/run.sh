cd /work/main && . .venv/bin/activate
out=/tmp/fast/r1.jsonl; : > $out
for g in stanford_chess hci_antinous lytro_dino_2067 hci_buddha stanford_lytro_general_11 epfl_iso_chart_1; do
  for cfg in '{}' '{"effort":"fast"}'; do
    OMP_NUM_THREADS=1 taskset -c 0 python /tmp/enc_time.py $g "$cfg" 40 >> $out 2>/tmp/fast/err.txt
  done
done
echo done >> $out
