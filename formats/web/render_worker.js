// render_worker.js — one worker of render_pool.js's RenderPool: answers {id, g, keys, send, disp,
// jobs, cubic, y0, y1} with {id, acc}: render.js's blendBand of rows y0..y1 from the planes of the
// views `keys` (those it holds from the frame before, plus `send`); it then holds those views only.
import { blendBand } from "./render.js";

let views = new Map();
self.onmessage = (e) => {
  const m = e.data;
  try {
    const next = new Map();
    for (const k of m.keys) {
      const p = m.send[k] || views.get(k);
      if (!p) throw new Error(`render worker: view ${k} was not sent`);
      next.set(k, p);
    }
    views = next;
    const acc = blendBand(m.g, m.keys.map((k) => views.get(k)), m.disp, m.jobs, m.cubic, m.y0, m.y1);
    self.postMessage({ id: m.id, acc }, [acc.buffer]);
  } catch (err) {
    views = new Map();
    self.postMessage({ id: m.id, error: String(err && err.message ? err.message : err) });
  }
};
