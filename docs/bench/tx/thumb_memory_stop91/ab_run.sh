# usage: bash ab_run.sh OUT.jsonl "GRID:T GRID:T ..."   (both modes per combo, order alternated)
out=$1; i=0
for c in $2; do g=${c%%:*}; t=${c##*:}; i=$((i+1))
  if [ $((i % 2)) = 1 ]; then order="old new"; else order="new old"; fi
  for m in $order; do python "$(dirname "$0")"/ab_enc.py $g $t $m >> $out 2>>$out.err; done
done; echo DONE >> $out
