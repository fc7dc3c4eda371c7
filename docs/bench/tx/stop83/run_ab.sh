. /work/main/.venv/bin/activate
cd /work/main
for spec in "stanford_chess 40" "hci_antinous 40" "lytro_dino_2067 40" "hci_buddha 40" "stanford_lytro_general_11 40" "epfl_iso_chart_1 40" "stanford_chess 36" "hci_antinous 36" "lytro_dino_2067 45" "hci_antinous 45" "stanford_chess 45" "hci_buddha 36"; do
  set -- $spec
  for mode in base noj2k; do
    if [ $mode = noj2k ]; then export LFC_EXP_NOJ2K=1; else unset LFC_EXP_NOJ2K; fi
    /usr/bin/time -f "cpu %U+%S" python docs/bench/tx/stop83/enc_passes.py /work/shared/data/$1 $2 $mode 2>&1 | grep -v warn
  done
done
