// Requests the browser viewer's modules make for a fresh open + first frame (render.js, the
// first camera of tools/web_first_frame_ab.mjs), this checkout's against an older one's, each
// read through a BufferSource that counts them (a request per range read; over HTTP, a round trip).
//   node docs/bench/web/key_span_stop88/requests.mjs OLD_CHECKOUT FILE.lfc
import fs from "fs";
import path from "path";
import { WEB, keyImage, say } from "../../../../tools/web_node.mjs";
const [oldRoot, file] = process.argv.slice(2);
const bytes = new Uint8Array(fs.readFileSync(file));
const out = { file: path.basename(file) };
for (const [k, root] of [["old", path.resolve(oldRoot, "formats/web")], ["new", WEB]]) {
  const lfc = await import(path.join(root, "lfc.js")), render = await import(path.join(root, "render.js"));
  const src = new lfc.BufferSource(bytes);
  const dec = await lfc.openDecoder(src, { name: "f", keyImage, chunkBudget: Infinity });
  const opened = src.requests;
  const ren = new render.Renderer(dec);
  const rad = Math.min(dec.rows, dec.cols) / 3;
  const img = await ren.render((dec.rows - 1) / 2, (dec.cols - 1) / 2 + rad);
  out[k] = { open_requests: opened, first_frame_requests: src.requests - opened, bytes: src.bytesFetched };
  out[k + "_frame"] = Array.from(img.pixels || img).reduce((h, x) => (h * 31 + x) >>> 0, 7);
}
out.same = out.old_frame === out.new_frame;
say(JSON.stringify(out));
