// The browser viewer's decoder (formats/web/lfc.js) against an older checkout's, in one Node
// process: every view decoded by both (planes compared), then whole-view decodes alternated.
//   node tools/web_decode_ab.mjs OLD_CHECKOUT FILE.lfc [ROUNDS]
// Prints one JSON line: same (every view's planes equal), old_ms / new_ms (median view decode
// over all views and rounds), ratio, and open_old_ms / open_new_ms (median open: header, maps,
// every key view; decodeKeys() where a reader decodes them on demand).
import fs from "fs";
import path from "path";
import { WEB, openFile, say } from "./web_node.mjs";
const [oldRoot, file, rounds = "3"] = process.argv.slice(2);
const NEW = await import(path.join(WEB, "lfc.js"));
const OLD = await import(path.resolve(oldRoot, "formats/web/lfc.js"));
const bytes = fs.readFileSync(file);
const med = (a) => a.slice().sort((x, y) => x - y)[a.length >> 1];
const T = { old: [], new: [] }, O = { old: [], new: [] };
const mods = { old: OLD, new: NEW };
let same = true, first = null;
for (let r = 0; r < Number(rounds); r++) {
  const decs = {};
  for (const k of ["old", "new"]) {
    const t = performance.now();
    decs[k] = await openFile(bytes, { lfc: mods[k] });
    if (decs[k].decodeKeys) await decs[k].decodeKeys();
    O[k].push(performance.now() - t);
  }
  for (let v = 0; v < decs.new.n0; v++) {
    const got = {};
    for (const k of ["old", "new"]) {
      const t = performance.now();
      got[k] = await decs[k].decodeView(v, 0);
      T[k].push(performance.now() - t);
    }
    if (r === 0 && (got.old.length !== got.new.length || got.old.some((x, i) => x !== got.new[i]))) {
      same = false; first = first ?? v;
    }
  }
}
say(JSON.stringify({ file: path.basename(file), same, first_differing_view: first, old_ms: med(T.old),
  new_ms: med(T.new), ratio: med(T.new) / med(T.old), open_old_ms: med(O.old), open_new_ms: med(O.new) }));
