// The browser viewer's novel-view renderer (formats/web/render.js) against an older checkout's,
// on one decoder (this checkout's lfc.js), in one Node process:
//   node tools/web_render_ab.mjs OLD_CHECKOUT FILE.lfc [ROUNDS] [NEW_OPTIONS_JSON]
// First both render 11 cameras with four option sets (robust, robust=false, a focus, an
// aperture) and the pixels are compared; then 8 cameras along tools/bench_web's path, the two
// renderers alternated per round (NEW_OPTIONS_JSON, e.g. '{"cubic": false}': the new renderer's
// render options in the timed rounds, against the old one's defaults). Prints one JSON line: same
// (every pixel equal), old_ms and new_ms (median frame), ratio.
import path from "path";
import { WEB, openFile, say } from "./web_node.mjs";
const [oldRoot, file, rounds = "3", newOpts = "{}"] = process.argv.slice(2);
const NEWOPT = JSON.parse(newOpts);
const NEW = await import(path.join(WEB, "render.js"));
const OLD = await import(path.resolve(oldRoot, "formats/web/render.js"));
const dec = await openFile(file);
const rens = { old: new OLD.Renderer(dec), new: new NEW.Renderer(dec) };
const cams = [];
for (let i = 0; i < 8; i++) cams.push([(dec.rows - 1) * (0.3 + 0.05 * i), (dec.cols - 1) * (0.6 - 0.04 * i)]);
cams.push([1, 1], [0, 0], [dec.rows - 1, (dec.cols - 1) / 2]);
let same = true;
const opts = [{}, { robust: false }, { focus: 1.5 }, { aperture: 1.2, focus: 0.5 }];
for (const o of opts) for (const [s, t] of cams) {
  const a = await rens.old.render(s, t, o), b = await rens.new.render(s, t, o);
  if (a.pixels.length !== b.pixels.length || a.pixels.some((v, i) => v !== b.pixels[i])) { same = false; say("differ", s, t, JSON.stringify(o)); }
}
const T = { old: [], new: [] };
for (let r = 0; r < Number(rounds); r++) for (const k of ["old", "new"]) for (const [s, t] of cams.slice(0, 8)) {
  const t0 = performance.now(); await rens[k].render(s, t, k === "new" ? NEWOPT : {}); T[k].push(performance.now() - t0);
}
const med = (a) => a.slice().sort((x, y) => x - y)[a.length >> 1];
say(JSON.stringify({ file, same, old_ms: med(T.old), new_ms: med(T.new), ratio: med(T.new) / med(T.old) }));
