import fs from "fs";
import { createRequire } from "module";
// ROOT=CHECKOUT node docs/bench/web/kernel_stop85/open_first_frame.mjs FILE.lfc: 4 rounds of [open ms, first frame ms]
const web = (process.env.ROOT || new URL("../../../..", import.meta.url).pathname) + "/formats/web";
const { openDecoder, BufferSource } = await import(web + "/lfc.js");
const { makeKeyImage } = await import(web + "/openjpeg.js");
const R = await import(web + "/render.js");
const factory = createRequire(import.meta.url)(web + "/vendor/openjpegwasm_decode.js");
const log = console.log; console.log = () => {};
const keyImage = await makeKeyImage(() => factory({ print: () => {}, printErr: () => {} }));
const bytes = fs.readFileSync(process.argv[2]);
const T = [];
for (let r = 0; r < 4; r++) {
  const t0 = performance.now();
  const d = await openDecoder(new BufferSource(bytes), { keyImage });
  const t1 = performance.now();
  const ren = new R.Renderer(d);
  await ren.render((d.rows - 1) / 2 + 0.35, (d.cols - 1) / 2 + 0.4);
  T.push([t1 - t0, performance.now() - t1]);
}
console.log = log;
console.log(process.argv[2].split("/").pop(), JSON.stringify(T.map(([a, b]) => [a.toFixed(0), b.toFixed(0)])));
