// The viewer's bilinear preview against its bicubic frame, in one Node process (stop 85): 8 frames of
// a drag, 5 rounds each after a warm-up.  node docs/bench/web/kernel_stop85/preview_ratio.mjs FILE.lfc
import path from "path";
import { WEB, openFile, say } from "../../../../tools/web_node.mjs";
const R = await import(path.join(WEB, "render.js"));
const d = await openFile(process.argv[2]);
const ren = new R.Renderer(d);
const s0 = Math.floor((d.rows - 1) / 2) + 0.35, t0 = Math.floor((d.cols - 1) / 2) + 0.6;
const T = { c: [], b: [] };
for (let r = 0; r < 6; r++) for (const cubic of [true, false]) for (let i = 0; i < 8; i++) {
  const t = performance.now(); await ren.render(s0 + 0.02 * i, t0 - 0.02 * i, { cubic }); if (r) T[cubic ? "c" : "b"].push(performance.now() - t); }
const med = (a) => a.slice().sort((x, y) => x - y)[a.length >> 1];
say(path.basename(process.argv[2]), med(T.c).toFixed(1), med(T.b).toFixed(1), (med(T.b) / med(T.c)).toFixed(2));
