// Time to a first frame in the browser viewer's modules, this checkout's against an older one's, in
// one Node process: a fresh open (lfc.js) and the first frame of its renderer (render.js) at
// tools.bench_open's first camera, the two checkouts alternated per round; the frames compared.
//   node tools/web_first_frame_ab.mjs OLD_CHECKOUT FILE.lfc [ROUNDS]
// Prints one JSON line: same (the first frames' pixels equal), open_old_ms / open_new_ms (median
// open), old_ms / new_ms (median open + first frame), ratio.
import fs from "fs";
import path from "path";
import { WEB, openFile, say } from "./web_node.mjs";
const [oldRoot, file, rounds = "5"] = process.argv.slice(2);
const mods = {
  new: { lfc: await import(path.join(WEB, "lfc.js")), render: await import(path.join(WEB, "render.js")) },
  old: { lfc: await import(path.resolve(oldRoot, "formats/web/lfc.js")),
         render: await import(path.resolve(oldRoot, "formats/web/render.js")) },
};
const bytes = fs.readFileSync(file);
const med = (a) => a.slice().sort((x, y) => x - y)[a.length >> 1];
const T = { old: [], new: [] }, O = { old: [], new: [] }, frames = {};
for (let r = 0; r < Number(rounds); r++) {
  for (const k of r % 2 ? ["new", "old"] : ["old", "new"]) {
    const t = performance.now();
    const dec = await openFile(bytes, { lfc: mods[k].lfc });
    const t1 = performance.now();
    const ren = new mods[k].render.Renderer(dec);
    const rad = Math.min(dec.rows, dec.cols) / 3;
    const img = await ren.render((dec.rows - 1) / 2, (dec.cols - 1) / 2 + rad);
    T[k].push(performance.now() - t);
    O[k].push(t1 - t);
    frames[k] = img.pixels || img;
  }
}
const a = frames.old, b = frames.new;
const same = a.length === b.length && a.every((x, i) => x === b[i]);
say(JSON.stringify({ file: path.basename(file), same, open_old_ms: med(O.old), open_new_ms: med(O.new),
  old_ms: med(T.old), new_ms: med(T.new), ratio: med(T.new) / med(T.old) }));
