#!/bin/bash
. /work/main/.venv/bin/activate
cd /tmp
for round in 1 2 3; do
  for f in llff_statue llff_canclip llff_ollie mitsuba_objects_360 hci_buddha epfl_iso_chart_1; do
    for ver in old new; do
      if [ $ver = old ]; then P=/tmp/old; else P=/work/main; fi
      echo "{\"file\": \"$f\", \"ver\": \"$ver\", \"round\": $round, \"r\": $(OMP_NUM_THREADS=1 PYTHONPATH=$P python /tmp/w/posed_ab.py /tmp/dec/$f.lfc $round)}"
    done
  done
done
