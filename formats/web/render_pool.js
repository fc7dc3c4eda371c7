// render_pool.js — the blend of a novel view (render.js's blendBand) shared among Web Workers
// (render_worker.js) and the page's thread: the frame's rows are cut into one band per worker
// plus one that the page blends while the workers run, each from every source view, and the
// bands are put back in order. A pixel's blend does not
// depend on the pixels beside it, so the frame is the page's own thread's, bit for bit (tested in
// the page). Each worker keeps the planes of the views of the frame it blended last and is sent
// only the views it does not hold (a camera moving within one cell of the grid sends none).
// Memory: each worker holds a copy of one frame's source views (4 for a novel view, more for a
// wide synthetic aperture) besides the page's own view cache.
import { WorkerPool, defaultWorkers } from "./lfn_pool.js";
import { blendBand } from "./render.js";

export class RenderPool extends WorkerPool {
  /** `n` module workers (where the environment has Web Workers; else use no pool). */
  constructor(n = defaultWorkers()) {
    super(new URL("./render_worker.js", import.meta.url), n);
    this.held = this.workers.map(() => new Set());     // the view keys each worker holds
  }

  /** blendBand(g, imgs, disp, jobs, cubic, 0, g.H) computed in bands on the workers; `keys`
   *  names the views of imgs (the renderer's cache keys: the same key, the same planes). */
  async blend(g, keys, imgs, disp, jobs, cubic) {
    if (this.failed) throw new Error(this.failed);
    const { H, W, P } = g;
    const parts = Math.min(this.workers.length + 1, H);  // band 0: the page's thread
    const edge = (i) => Math.floor((H * i) / parts);
    const bands = [];
    for (let i = 0; i < parts - 1; i++) {
      const y0 = edge(i + 1), y1 = edge(i + 2);
      const send = {};
      keys.forEach((k, j) => { if (!this.held[i].has(k)) send[k] = imgs[j]; });
      this.held[i] = new Set(keys);                   // (the worker keeps these, drops the others)
      const band = disp.slice(y0 * W, y1 * W);
      bands.push(this._call(i, { g, keys, send, disp: band, jobs, cubic, y0, y1 }, [band.buffer]).then((m) => [y0, m.acc]));
    }
    const out = new Float32Array(H * W * P);
    out.set(blendBand(g, imgs, disp.subarray(0, edge(1) * W), jobs, cubic, 0, edge(1)));
    try {
      for (const [y0, acc] of await Promise.all(bands)) out.set(acc, y0 * W * P);
    } catch (e) {
      this.held = this.workers.map(() => new Set());  // (what a failed worker holds is unknown)
      throw e;
    }
    return out;
  }
}
