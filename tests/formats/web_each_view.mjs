// Test helper: open a tx .lfc file with the browser viewer's decoder (formats/web/lfc.js) under Node,
// then decode every view on its own, in order, each error caught: one JSON line {ok: true,
// mapsAfterOpen (maps decoded by the open), views: [{ok, name, message, cell, maps}]} (maps: those
// decoded so far), planes of decoded views in OUTDIR/view_V.bin (int32, Hp·Wp·P); or {ok: false,
// name, message} where the open fails.
// node web_each_view.mjs FILE OUTDIR
import fs from "fs";
import path from "path";
import { openFile, say } from "../../tools/web_node.mjs";

const [file, out] = process.argv.slice(2);
try {
  const dec = await openFile(file, { name: path.basename(file) });
  const count = () => (dec._maps ? dec._maps.done.reduce((a, b) => a + b, 0) : 0);
  const mapsAfterOpen = count();
  fs.mkdirSync(out, { recursive: true });
  const views = [];
  for (let v = 0; v < dec.n0; v++) {
    try {
      const planes = await dec.decodeView(v);
      fs.writeFileSync(path.join(out, `view_${v}.bin`), Buffer.from(planes.buffer, planes.byteOffset, planes.byteLength));
      views.push({ ok: true, cell: dec.cell[v], maps: count() });
    } catch (e) {
      views.push({ ok: false, name: e.name, message: e.message, cell: dec.cell[v], maps: count() });
    }
  }
  say(JSON.stringify({ ok: true, mapsAfterOpen, nMaps: dec.nMaps, Hp: dec.Hp, Wp: dec.Wp, P: dec.P, views }));
} catch (e) {
  say(JSON.stringify({ ok: false, name: e.name, message: e.message }));
}
