// Novel views from the browser viewer's renderer (formats/web/render.js) under Node, written raw
// for tools/web_render_parity.py: node tools/web_render_frames.mjs [RENDER_ROOT] FILE.lfc CAMS.json OUT.bin
// CAMS.json: [[s, t, focus|null, aperture, robust], ...]. OUT.bin: the frames' pixels, in order,
// each H·W·C values of the file's sample type (uint8 or uint16, little-endian). RENDER_ROOT (a
// checkout, optional): render with that checkout's render.js (this checkout's decoder either way).
import fs from "fs";
import path from "path";
import { WEB, openFile, say } from "./web_node.mjs";

const args = process.argv.slice(2);
const root = args.length === 4 ? args.shift() : null;
const [file, camsFile, outFile] = args;
const { Renderer } = await import(root ? path.resolve(root, "formats/web/render.js") : path.join(WEB, "render.js"));
const dec = await openFile(file);
const ren = new Renderer(dec);
const out = [];
const ms = [];
for (const [s, t, focus, aperture, robust] of JSON.parse(fs.readFileSync(camsFile, "utf8"))) {
  const got = await ren.render(s, t, { focus, aperture, robust });
  ms.push(got.ms);
  out.push(Buffer.from(got.pixels.buffer, got.pixels.byteOffset, got.pixels.byteLength));
}
fs.writeFileSync(outFile, Buffer.concat(out));
say(JSON.stringify({ H: dec.H, W: dec.W, C: dec.C, ms }));
