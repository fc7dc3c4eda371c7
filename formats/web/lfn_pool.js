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

/** Module workers that answer messages {id, ...} with {id, ...} or {id, error}: the bookkeeping
 *  ForwardPool and render_pool.js's RenderPool share. A worker that cannot start or throws fails
 *  every call from then on (the caller falls back to the page's thread). */
export class WorkerPool {
  /** `n` module workers running `script` (a URL; where the environment has Web Workers). */
  constructor(script, n) {
    if (typeof Worker === "undefined") throw new Error("this environment has no Web Workers");
    this.workers = Array.from({ length: n }, () => new Worker(script, { type: "module" }));
    this.next = 0;
    this.waiting = new Map();
    this.failed = null;
    for (const w of this.workers) {
      w.onmessage = (e) => {
        const p = this.waiting.get(e.data.id);
        this.waiting.delete(e.data.id);
        if (p) (e.data.error ? p.reject(new Error(e.data.error)) : p.resolve(e.data));
      };
      w.onerror = (e) => {
        this.failed = e.message || "a worker failed";
        for (const p of this.waiting.values()) p.reject(new Error(this.failed));
        this.waiting.clear();
      };
    }
  }

  get size() { return this.workers.length; }

  /** Post `msg` (given an id here) to worker i; resolves with its answer. */
  _call(i, msg, transfer = []) {
    if (this.failed) throw new Error(this.failed);
    const id = this.next++;
    const answer = new Promise((resolve, reject) => this.waiting.set(id, { resolve, reject }));
    this.workers[i].postMessage({ ...msg, id }, transfer);
    return answer;
  }

  terminate() { for (const w of this.workers) w.terminate(); this.workers = []; }
}

export class ForwardPool extends WorkerPool {
  /** `n` module workers (where the environment has Web Workers; else use no pool). */
  constructor(n = defaultWorkers()) {
    super(new URL("./lfn_worker.js", import.meta.url), n);
    this.sent = null;                 // the weights the workers hold (LfnDecoder.Wt identity: rebuilt on grow)
  }

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
      jobs.push(this._call(p, { op, neurons, n: b - a, rays: chunk }, [chunk.buffer]).then((res) => [a, b, res.out]));
    }
    return Promise.all(jobs);
  }
}
