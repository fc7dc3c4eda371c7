// Helper of tools/bench_web_lfn.py: time the browser viewer's LFN renderer (formats/web/lfn.js)
// under Node. node web_lfn_bench.mjs FILE OUTDIR ROUNDS NEURONS,SCALE[,native] ...  (SCALE "auto" =
// the size's own; "native": on the network's own pixel grid). For each setting: grows the network (counting the section bytes read), renders the
// captured view 0 ROUNDS times, writes OUTDIR/px_I.bin (the file's pixels) and prints one JSON
// line: [{neurons, scale, native, stride, h, w, ms (median), evaluated, bytes}].
import fs from "fs";
import path from "path";
import { fileURLToPath } from "url";

const web = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "../formats/web");
const { LfcFile, BufferSource } = await import(path.join(web, "lfc.js"));
const { LfnDecoder } = await import(path.join(web, "lfn.js"));
if (process.env.LFN_NO_WASM) LfnDecoder.useWasm = false;               // lfn.js's own loops

const [file, out, rounds, ...settings] = process.argv.slice(2);
const src = new BufferSource(fs.readFileSync(file));
const dec = await LfnDecoder.open(await LfcFile.open(src, path.basename(file)), { maxNeurons: 0 });
const res = [];
for (let i = 0; i < settings.length; i++) {
  const [n, sc, nat] = settings[i].split(",");
  const native = nat === "native";
  await dec.grow(Number(n));
  const pose = dec.pose(0), times = [];
  let r;
  for (let k = 0; k < Number(rounds); k++) {
    const t = performance.now();
    r = dec.render(pose, Number(n), sc === "auto" ? null : Number(sc), { native });
    times.push(performance.now() - t);
  }
  times.sort((a, b) => a - b);
  const px = dec.toPixels(r.rgba, r.h, r.w);
  fs.writeFileSync(path.join(out, `px_${i}.bin`), Buffer.from(px.buffer, px.byteOffset, px.byteLength));
  const held = dec.weightBytes();
  res.push({ neurons: Number(n), scale: sc, native, stride: r.stride, h: r.h, w: r.w, ms: times[times.length >> 1], evaluated: r.evaluated, bytes: held });
}
console.log(JSON.stringify(res));
