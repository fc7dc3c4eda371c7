// Test helper: render views of an LFN .lfc file with the browser viewer's JavaScript renderer
// (formats/web/lfn.js) under Node.
// node web_lfn.mjs FILE OUTDIR CAM...   CAM = view,V,N,S | grid,S,T,N,S | orbit,V,YAW,PITCH,N,S
// (N neurons, "max" = all, "display" = the display ladder's size for what is held; S image scale, "auto" = the size's own;
// a trailing ",native" renders on the network's own pixel grid, ",fovea:X:Y" foveated around the gaze (X, Y)
// in pixels of the frame (renderMip of foveationMap); LFN_NO_WASM=1: without the WebAssembly kernel).
// Writes OUTDIR/render_I.bin
// (pixels of the file's dtype, h·w·C) per camera and prints one JSON line: {ok: true, renders:
// [{h, w, pose, evaluated}], neurons, bytesRead} or {ok: false, name, message}.
import fs from "fs";
import path from "path";
import { fileURLToPath } from "url";

const web = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "../../formats/web");
const { LfcFile, BufferSource, LfcError } = await import(path.join(web, "lfc.js"));
const { LfnDecoder } = await import(path.join(web, "lfn.js"));
if (process.env.LFN_NO_WASM) LfnDecoder.useWasm = false;                 // lfn.js's own loops

const [file, out, ...cams] = process.argv.slice(2);
try {
  const src = new BufferSource(fs.readFileSync(file));
  const f = await LfcFile.open(src, path.basename(file));
  const first = Number(process.env.LFN_FIRST_NEURONS || Infinity);      // open with a smaller network, then grow
  const dec = await LfnDecoder.open(f, { maxNeurons: first });
  const opened = dec.neurons;
  fs.mkdirSync(out, { recursive: true });
  const renders = [];
  for (let i = 0; i < cams.length; i++) {
    const a = cams[i].split(",");
    const fovea = a[a.length - 1].startsWith("fovea:") ? a.pop().split(":").slice(1).map(Number) : null;
    const native = a[a.length - 1] === "native";
    if (native) a.pop();
    let pose, rest;
    if (a[0] === "view") { pose = dec.pose(Number(a[1])); rest = a.slice(2); }
    else if (a[0] === "grid") { pose = dec.gridPose(Number(a[1]), Number(a[2])); rest = a.slice(3); }
    else { pose = dec.orbitPose(Number(a[1]), Number(a[2]), Number(a[3])); rest = a.slice(4); }
    const n = rest[0] === "max" || rest[0] === "display" ? Infinity : Number(rest[0]);
    if (rest[0] !== "display") await dec.grow(n);            // display: what the opened steps show
    const use = rest[0] === "display" ? dec.displayNeurons(rest[1] === "auto" ? null : Number(rest[1])) : Math.min(n, dec.neurons);
    const scale = rest[1] === "auto" ? null : Number(rest[1]);
    let r;
    if (fovea) {
      const h = Math.max(1, Math.round(dec.H * scale)), w = Math.max(1, Math.round(dec.W * scale));
      r = dec.renderMip(pose, dec.foveationMap(fovea, h, w), scale, { native });
    } else r = dec.render(pose, use, scale, { native });
    const px = dec.toPixels(r.rgba, r.h, r.w);
    fs.writeFileSync(path.join(out, `render_${i}.bin`), Buffer.from(px.buffer, px.byteOffset, px.byteLength));
    renders.push({ h: r.h, w: r.w, pose, evaluated: r.evaluated, stride: r.stride, levels: r.levels, neurons: dec.neurons,
      shown: use });
  }
  console.log(JSON.stringify({ ok: true, renders, opened, pivot: dec.pivot, up: dec.up, wasm: Boolean(dec._kernel()) }));
} catch (e) {
  if (!(e instanceof LfcError)) throw e;
  process.stdout.write(JSON.stringify({ ok: false, name: e.name, message: e.message }) + "\n");
}
