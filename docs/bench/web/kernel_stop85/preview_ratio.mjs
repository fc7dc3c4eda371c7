import fs from "fs";
import { createRequire } from "module";
const web = new URL("../../../../formats/web", import.meta.url).pathname;   // (run: node docs/bench/web/kernel_stop85/preview_ratio.mjs FILE.lfc)
const { openDecoder, BufferSource } = await import(web + "/lfc.js");
const { makeKeyImage } = await import(web + "/openjpeg.js");
const R = await import(web + "/render.js");
const factory = createRequire(import.meta.url)(web + "/vendor/openjpegwasm_decode.js");
const log = console.log; console.log = () => {};
const keyImage = await makeKeyImage(() => factory({ print: () => {}, printErr: () => {} }));
const d = await openDecoder(new BufferSource(fs.readFileSync(process.argv[2])), { keyImage });
const ren = new R.Renderer(d);
const s0 = Math.floor((d.rows - 1) / 2) + 0.35, t0 = Math.floor((d.cols - 1) / 2) + 0.6;
const T = { c: [], b: [] };
for (let r = 0; r < 6; r++) for (const cubic of [true, false]) for (let i = 0; i < 8; i++) {
  const t = performance.now(); await ren.render(s0 + 0.02 * i, t0 - 0.02 * i, { cubic }); if (r) T[cubic ? "c" : "b"].push(performance.now() - t); }
const med = (a) => a.slice().sort((x, y) => x - y)[a.length >> 1];
console.log = log;
console.log(process.argv[2].split("/").pop(), med(T.c).toFixed(1), med(T.b).toFixed(1), (med(T.b) / med(T.c)).toFixed(2));
