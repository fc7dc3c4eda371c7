// lfn_pool.js — a light field network's passes shared among Web Workers (lfn_worker.js): the
// rays a frame runs are cut into one contiguous run per worker, each worker runs the same
// code as the page's thread on its run (LfnDecoder._occupiedAll for the occupancy net, then
// LfnDecoder._forwardRays for the network), and the answers are put back in ray order.
// Each ray's arithmetic does not depend on the rays beside it, so the pixels are those of a
// render on the page's own thread, bit for bit (tested in the page).

/** Workers a page gets by default: the cores the browser reports, 1..8 (the page's own thread
 *  waits while they run). */
export function defaultWorkers() {
  const n = typeof navigator !== "undefined" && navigator.hardwareConcurrency ? navigator.hardwareConcurrency : 1;
  return Math.max(1, Math.min(8, n));
}

export class ForwardPool {
  /** `n` module workers (where the environment has Web Workers; else use no pool). */
  constructor(n = defaultWorkers()) {
    if (typeof Worker === "undefined") throw new Error("this environment has no Web Workers");
    this.workers = Array.from({ length: n }, () => new Worker(new URL("./lfn_worker.js", import.meta.url), { type: "module" }));
    this.sent = null;                 // the weights the workers hold (LfnDecoder.Wt identity: rebuilt on grow)
    this.next = 0;
    this.waiting = new Map();
    this.failed = null;
    for (const w of this.workers) {
      w.onmessage = (e) => {
        const { id, out, error } = e.data, p = this.waiting.get(id);
        this.waiting.delete(id);
        if (p) (error ? p.reject(new Error(error)) : p.resolve(out));
      };
      w.onerror = (e) => {             // (a worker that cannot start or throws: every call fails from now on)
        this.failed = e.message || "a worker failed";
        for (const p of this.waiting.values()) p.reject(new Error(this.failed));
        this.waiting.clear();
      };
    }
  }

  get size() { return this.workers.length; }

  /** The occupancy net's answers for rays i < n: Uint8Array n (1 = let through). */
  async occupancy(dec, rays, n) {
    const out = new Uint8Array(n);
    for (const [a, b, res] of await this._map(dec, "occ", null, rays, n, null)) out.set(res, a);
    return out;
  }

  /** The network outputs of rays i < n with run[i] set (all when run is null): {out (n·4,
   *  zeros where not run), evaluated}. */
  async forward(dec, neurons, rays, n, run) {
    let idx = null, m = n;
    if (run) {
      m = 0;
      for (let i = 0; i < n; i++) m += run[i];
      idx = new Int32Array(m);
      for (let i = 0, j = 0; i < n; i++) if (run[i]) idx[j++] = i;
    }
    const out = new Float64Array(n * 4);
    for (const [a, b, res] of await this._map(dec, "net", neurons, rays, m, idx)) {
      if (idx) for (let j = a; j < b; j++) out.set(res.subarray(4 * (j - a), 4 * (j - a) + 4), 4 * idx[j]);
      else out.set(res, 4 * a);
    }
    return { out, evaluated: m };
  }

  /** Rays idx[0..m) (rays 0..m when idx is null) cut into one contiguous run per worker, each
   *  answered by op ("occ" or "net"); resolves to [[a, b, answer of rays a..b)]]. */
  async _map(dec, op, neurons, rays, m, idx) {
    if (this.failed) throw new Error(this.failed);
    if (this.sent !== dec.Wt) {      // the network grew (or another one): send its weights first
      const net = { depth: dec.depth, w: dec.w, Wt: dec.Wt, b: dec.b, g: dec.g, be: dec.be, ow: dec.ow, ob: dec.ob,
        occ: dec.occ, occN: dec.occN, useWasm: dec.constructor.useWasm };
      for (const w of this.workers) w.postMessage({ net });
      this.sent = dec.Wt;
    }
    const parts = Math.min(this.workers.length, Math.max(1, Math.ceil(m / 256)));
    const jobs = [];
    for (let p = 0; p < parts; p++) {
      const a = Math.floor((m * p) / parts), b = Math.floor((m * (p + 1)) / parts);
      const chunk = new Float32Array((b - a) * 6);
      if (idx) for (let j = a; j < b; j++) chunk.set(rays.subarray(6 * idx[j], 6 * idx[j] + 6), 6 * (j - a));
      else chunk.set(rays.subarray(6 * a, 6 * b));
      const id = this.next++;
      jobs.push(new Promise((resolve, reject) => this.waiting.set(id, { resolve, reject })).then((res) => [a, b, res]));
      this.workers[p].postMessage({ id, op, neurons, n: b - a, rays: chunk }, [chunk.buffer]);
    }
    return Promise.all(jobs);
  }

  terminate() { for (const w of this.workers) w.terminate(); this.workers = []; }
}
