// Timings of the browser viewer's decoder and renderer under Node (V8, one thread), for
// tools/bench_web.py: node tools/web_bench.mjs FILE ROUNDS → one JSON line {open_ms (with every key
// view decoded), view_ms (median per view over all views), frame_ms (median novel-view frame, 4
// sources)}.
import fs from "fs";
import path from "path";
import { WEB, openFile, say } from "./web_node.mjs";

const { Renderer } = await import(path.join(WEB, "render.js"));
const [file, rounds = "1"] = process.argv.slice(2);
const bytes = fs.readFileSync(file);
const med = (a) => a.slice().sort((x, y) => x - y)[a.length >> 1];
const opens = [], views = [], frames = [];
for (let r = 0; r < Number(rounds); r++) {
  let t = performance.now();
  const dec = await openFile(bytes);
  await dec.decodeKeys();                  // (the open decodes none; timed with it, as Python's decode_keys())
  opens.push(performance.now() - t);
  for (let v = 0; v < dec.n0; v++) {
    t = performance.now();
    await dec.decodeView(v, 0);
    views.push(performance.now() - t);
  }
  const ren = new Renderer(dec);
  for (let i = 0; i < 8; i++) {
    const s = (dec.rows - 1) * (0.3 + 0.05 * i), tt = (dec.cols - 1) * (0.6 - 0.04 * i);
    t = performance.now();
    await ren.render(s, tt);
    frames.push(performance.now() - t);
  }
}
say(JSON.stringify({ open_ms: med(opens), view_ms: med(views), frame_ms: med(frames.slice(1)) }));
