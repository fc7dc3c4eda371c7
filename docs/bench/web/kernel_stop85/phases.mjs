// Where a novel-view frame of the viewer's renderer goes under Node (stop 85): 8 frames of a drag
// inside one cell after 8 warm-up frames; the blend alone, _consistent and disparity timed apart.
//   node docs/bench/web/kernel_stop85/phases.mjs FILE.lfc
import path from "path";
import { WEB, openFile, say } from "../../../../tools/web_node.mjs";
const R = await import(path.join(WEB, "render.js"));
const file = process.argv[2];
const d = await openFile(file);
const ren = new R.Renderer(d);
const P = {};
const wrap = (obj, name, key) => { const f = obj[name]; obj[name] = function (...a) { const t = performance.now(); const r = f.apply(this, a); P[key] = (P[key] || 0) + performance.now() - t; return r; }; };
wrap(ren, "_consistent", "consistent"); wrap(ren, "disparity", "disparity");
const s0 = Math.floor((d.rows - 1) / 2) + 0.35, t0 = Math.floor((d.cols - 1) / 2) + 0.6;
for (let i = 0; i < 8; i++) await ren.render(s0 + 0.02 * i, t0 - 0.02 * i);
for (const k in P) P[k] = 0;
let tot = 0;
for (let i = 0; i < 8; i++) { const t = performance.now(); await ren.render(s0 + 0.02 * i, t0 - 0.02 * i); tot += performance.now() - t; }
// blend time alone
const src = ren.sources(s0, t0, 0); const imgs = []; for (const [r, c] of src) imgs.push(await ren.view(r * d.cols + c));
const disp = ren.disparity(s0, t0); const jobs = src.map(([r, c, w]) => [s0 - r, t0 - c, Math.fround(w), null]);
let tb = performance.now(); for (let i = 0; i < 8; i++) R.blendBand({ P: d.P, Wp: d.Wp, Hp: d.Hp, H: d.H, W: d.W }, imgs, disp, jobs, true, 0, d.H); tb = performance.now() - tb;
say(path.basename(file), "frame", (tot / 8).toFixed(1), "blend", (tb / 8).toFixed(1), Object.entries(P).map(([k, v]) => `${k} ${(v / 8).toFixed(1)}`).join(" "));
