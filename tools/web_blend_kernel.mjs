// The novel-view blend on WebAssembly (formats/web/render_kernel.wat, render.js BlendKernel)
// against blendOne's loops, in one Node process:
//   node tools/web_blend_kernel.mjs FILE.lfc [ROUNDS]
// First the two blend 9 cameras of the file (the maps' disparities, a focus, a synthetic
// aperture; bicubic and bilinear; with the file's warps where it has them) and their float32
// accumulators are compared bit for bit, and whole frames of Renderer.render (robust, the
// default) with and without the kernel are compared pixel for pixel, and so are the robust
// choice's costs (Renderer._cost: samples on the kernel's `samples`, brightness and variances; for the maps'
// disparities and a constant one) and its disparities (_consistent) at each camera with two or
// more sources (costs_checked: how many arrays). Then (ROUNDS > 0) the blend of one frame is
// timed, the two alternated per round. Prints one JSON line: same (every accumulator, cost and
// frame equal), kernel (whether this Node has WebAssembly SIMD), the median ms of each blend,
// their ratios, the views copied into the kernel's memory, and those copied by 8 frames of a drag
// inside one cell of the grid after a first frame there (0: the views stay).
import path from "path";
import { WEB, openFile, say } from "./web_node.mjs";
const [file, rounds = "5"] = process.argv.slice(2);
const R = await import(path.join(WEB, "render.js"));
const d = await openFile(file);
const ren = new R.Renderer(d);
const { H, W } = d;
const g = (wasm) => ({ P: d.P, Wp: d.Wp, Hp: d.Hp, H, W, wasm });
const med = (a) => a.slice().sort((x, y) => x - y)[a.length >> 1];
const R1 = d.rows - 1, C1 = d.cols - 1;
const cams = [[R1 * 0.4, C1 * 0.55], [R1 * 0.3, C1 * 0.7], [R1 * 0.5, C1 * 0.5], [0, 0], [R1, C1 * 0.25]];
const opts = [{}, { focus: 1.25 }, { focus: -0.5, aperture: 1.3 }];
let same = true, differ = 0;
async function frameJobs(s, t, { focus = null, aperture = 0 } = {}) {
  const src = ren.sources(s, t, aperture);
  const imgs = [];
  for (const [r, c] of src) imgs.push(await ren.view(r * d.cols + c));
  let disp = focus === null && aperture === 0 ? ren.disparity(s, t) : null;
  if (!disp) disp = new Float32Array(H * W).fill(focus || 0);
  const warp = ren._warpCoefs(src);
  return { imgs, disp, jobs: src.map(([r, c, w], j) => [s - r, t - c, Math.fround(w), warp ? warp[j] : null]) };
}
for (const [s, t] of cams) for (const o of opts) for (const cubic of [true, false]) {
  const { imgs, disp, jobs } = await frameJobs(s, t, o);
  const a = R.blendBand(g(false), imgs, disp, jobs, cubic, 0, H), b = R.blendBand(g(true), imgs, disp, jobs, cubic, 0, H);
  const y0 = Math.floor(H / 3), y1 = Math.floor((2 * H) / 3);         // a band, as the workers blend one
  const c = R.blendBand(g(true), imgs, disp.subarray(y0 * W, y1 * W), jobs, cubic, y0, y1);
  for (let i = 0; i < a.length; i++) if (!Object.is(a[i], b[i])) { same = false; differ += 1; }
  for (let i = 0; i < c.length; i++) if (!Object.is(a[y0 * W * d.P + i], c[i])) { same = false; differ += 1; }
}
for (const [s, t] of cams) for (const cubic of [true, false]) {
  R.Renderer.useWasm = false;
  const a = await ren.render(s, t, { cubic });
  R.Renderer.useWasm = true;
  const b = await ren.render(s, t, { cubic });
  for (let i = 0; i < a.pixels.length; i++) if (a.pixels[i] !== b.pixels[i]) { same = false; differ += 1; }
}
// the robust choice's costs (samples and variances on the kernel) and its disparities, both ways
let costsChecked = 0;
for (const [s, t] of cams) {
  const src = ren.sources(s, t, 0), disp0 = ren.disparity(s, t);
  if (src.length < 2 || !disp0) continue;
  const imgs = [];
  for (const [r, c] of src) imgs.push(await ren.view(r * d.cols + c));
  const warp = ren._warpCoefs(src), gh = Math.ceil(H / 4), gw = Math.ceil(W / 4);
  const kb = R.levelBox(gh, gw, 4);
  const D = Float32Array.from({ length: gh * gw }, (_, i) => disp0[4 * Math.floor(i / gw) * W + 4 * (i % gw)]);
  const both = (fn) => {
    R.Renderer.useWasm = false;
    const a = fn();
    R.Renderer.useWasm = true;
    return [a, fn()];
  };
  for (const [a, b] of [both(() => ren._cost(s, t, src, imgs, D, gh, gw, 4, kb, warp)),
    both(() => ren._cost(s, t, src, imgs, D.map(() => 0.75), gh, gw, 4, kb, warp)),
    both(() => ren._consistent(s, t, src, imgs, disp0, warp))]) {
    for (let i = 0; i < a.length; i++) if (!Object.is(a[i], b[i])) { same = false; differ += 1; }
    costsChecked += 1;
  }
}
// a drag: 8 frames inside one cell of the grid after a first one there copy no view into the kernel
const k = R.BlendKernel.shared();
const c0 = [Math.min(0.35, R1), Math.min(0.6, C1)];
await ren.render(c0[0], c0[1]);
const before = k ? k.copies : 0;
for (let i = 0; i < 8; i++) await ren.render(c0[0] + (R1 ? 0.02 * i : 0), c0[1] - (C1 ? 0.02 * i : 0));
const dragCopies = (k ? k.copies : 0) - before;
const T = { js: [], wasm: [], js_bilinear: [], wasm_bilinear: [] };
const { imgs, disp, jobs } = await frameJobs(cams[0][0], cams[0][1]);
for (let r = 0; r < Number(rounds); r++) for (const wasm of [false, true]) for (const cubic of [true, false]) {
  const t0 = performance.now();
  R.blendBand(g(wasm), imgs, disp, jobs, cubic, 0, H);
  T[(wasm ? "wasm" : "js") + (cubic ? "" : "_bilinear")].push(performance.now() - t0);
}
const out = { file: path.basename(file), H, W, P: d.P, warps: Boolean(d.warp), same, differ, kernel: Boolean(k),
  copies: k ? k.copies : 0, drag_copies: dragCopies, costs_checked: costsChecked };
if (Number(rounds) > 0) {
  Object.assign(out, { js_ms: med(T.js), wasm_ms: med(T.wasm), ratio: med(T.wasm) / med(T.js),
    js_bilinear_ms: med(T.js_bilinear), wasm_bilinear_ms: med(T.wasm_bilinear), ratio_bilinear: med(T.wasm_bilinear) / med(T.js_bilinear) });
}
say(JSON.stringify(out));
