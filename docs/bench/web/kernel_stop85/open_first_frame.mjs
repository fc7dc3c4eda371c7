// Open and first frame of the viewer's decoder and renderer under Node (stop 85):
//   ROOT=CHECKOUT node docs/bench/web/kernel_stop85/open_first_frame.mjs FILE.lfc
// prints 4 rounds of [open ms, first frame ms] with ROOT's lfc.js and render.js (default: this checkout's).
import fs from "fs";
import path from "path";
import { WEB, openFile, say } from "../../../../tools/web_node.mjs";
const web = process.env.ROOT ? path.resolve(process.env.ROOT, "formats/web") : WEB;
const lfc = await import(path.join(web, "lfc.js"));
const R = await import(path.join(web, "render.js"));
const bytes = fs.readFileSync(process.argv[2]);
const T = [];
for (let r = 0; r < 4; r++) {
  const t0 = performance.now();
  const d = await openFile(bytes, { lfc });
  const t1 = performance.now();
  const ren = new R.Renderer(d);
  await ren.render((d.rows - 1) / 2 + 0.35, (d.cols - 1) / 2 + 0.4);
  T.push([t1 - t0, performance.now() - t1]);
}
say(path.basename(process.argv[2]), JSON.stringify(T.map(([a, b]) => [a.toFixed(0), b.toFixed(0)])));
