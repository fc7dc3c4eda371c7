// render.js — novel views from a TxDecoder (lfc.js): the same method as the Python renderer
// (rlfc.render.Renderer, robust by default, or robust=false): pixel (y, x) of the view at grid position
// (s, t) takes from captured view (r, c) the bicubic sample (Keys, a = −0.75) at
// (y + d·(s − r), x + d·(t − c)), d in pixels per view step; the views around (s, t) are blended
// with bilinear weights, or, for synthetic-aperture refocusing, every view within `aperture` view
// steps with weights falling off with distance, at one focus disparity everywhere. The robust
// choice samples bilinearly. Samples are taken at the exact float positions, as OpenCV 5's remap
// of float32 images and the torch path take them, so the Python renderer and this one agree within
// float rounding.
//
// Decoded views are kept in an LRU cache bounded by `cacheBytes` (the views of one frame are
// decoded whatever the budget).
import { LfcError, fromPlanes } from "./lfc.js";
import { kernelModule } from "./render_kernel.js";
import { assignSlots, growTo } from "./wasm_module.js";

/** Frames of at least this many pixels blend on the pool's workers when the renderer has one. */
export const POOL_MIN_PIXELS = 1 << 15;

export class Renderer {
  /** Whether renderers blend on WebAssembly SIMD (render_kernel.wat) where the environment has it
   *  (false: blendOne's loops; the same pixels, bit for bit). The viewer's `&wasm=0` clears it. */
  static useWasm = true;

  /** `pool`: a RenderPool (render_pool.js): bands of rows of each frame blended on its Web Workers and this thread
   *  (the same pixels as the page's thread, bit for bit); null: the page's thread. */
  constructor(dec, { cacheBytes = 256 << 20, margin = 0.5, pool = null } = {}) {
    if (dec.layout === "posed") throw new LfcError("novel views are rendered on grids; this capture is posed");
    this.d = dec;
    this.cacheBytes = cacheBytes;
    this.margin = margin;
    this.pool = pool;
    this.poolMinPixels = POOL_MIN_PIXELS;             // (smaller frames: the page's thread)
    this.cache = new Map();               // view → planes (Int32Array), in LRU order
    this.viewsDecoded = 0;
    this.users = [];
    for (let v = 0; v < dec.n0; v++) if (dec.cell[v] >= 0) this.users.push(v);
  }

  /** Bytes of decoded views held. */
  cachedBytes() { let n = 0; for (const p of this.cache.values()) n += p.byteLength; return n; }

  async view(v, level = 0) {
    const key = `${v}:${level}`;
    let p = this.cache.get(key);
    if (p) { this.cache.delete(key); this.cache.set(key, p); return p; }
    p = await this.d.decodeView(v, level);
    this.viewsDecoded += 1;
    this.cache.set(key, p);
    return p;
  }

  _trim(keep) {
    for (const k of [...this.cache.keys()]) {
      if (this.cachedBytes() <= this.cacheBytes) break;
      if (!keep.has(k)) this.cache.delete(k);
    }
  }

  /** (H·W) disparity in pixels per view step: the map of the nearest view's cell, per 8×8 block
   * (where every view is coded alone, the file's first map: the shared one, as the Python renderer). */
  disparity(s, t) {
    const d = this.d;
    if (!d.nMaps) return null;
    let m = 0;
    if (this.users.length) {
      let best = this.users[0], bd = Infinity;
      for (const v of this.users) {
        const dist = Math.hypot(d.pos[2 * v] - s, d.pos[2 * v + 1] - t);
        if (dist < bd) { bd = dist; best = v; }
      }
      m = d.cell[best];
    }
    d.needMap(m);
    const nloc = d.nby8 * d.nbx8, W = d.W;
    const out = new Float32Array(d.H * W);
    for (let y = 0; y < d.H; y++) {                 // each 8×8 block's value, written 8 pixels at a time
      const row = m * nloc + (y >> 3) * d.nbx8, o = y * W;
      for (let x = 0; x < W; x += 8) out.fill(d.disp[row + (x >> 3)] / 16, o + x, Math.min(o + x + 8, o + W));
    }
    return out;
  }

  sources(s, t, aperture) {
    const R = this.d.rows, C = this.d.cols;
    if (aperture > 0) {
      const sel = [];
      let best = 0, bd = Infinity;
      for (let r = 0; r < R; r++) {
        for (let c = 0; c < C; c++) {
          const dist = Math.hypot(r - s, c - t);
          if (dist < bd) { bd = dist; best = r * C + c; }
          if (dist <= aperture) sel.push([r, c, Math.max(1 - dist / (aperture + 1), 1e-3)]);
        }
      }
      if (!sel.length) sel.push([Math.floor(best / C), best % C, 1]);
      const sum = sel.reduce((a, x) => a + x[2], 0);
      return sel.map(([r, c, w]) => [r, c, w / sum]);
    }
    const clip = (v, lo, hi) => Math.min(Math.max(v, lo), hi);
    const r0 = clip(Math.floor(s), 0, R - 1), c0 = clip(Math.floor(t), 0, C - 1);
    const r1 = Math.min(r0 + 1, R - 1), c1 = Math.min(c0 + 1, C - 1);
    // a camera within 1e-9 views of a row or column of views is on it (rlfc.render.SNAP)
    const snap = (f) => (f < 1e-9 ? 0 : f > 1 - 1e-9 ? 1 : f);
    const fs = r1 > r0 ? snap(clip(s - r0, 0, 1)) : 0, ft = c1 > c0 ? snap(clip(t - c0, 0, 1)) : 0;
    const out = new Map();
    for (const [r, c, w] of [[r0, c0, (1 - fs) * (1 - ft)], [r0, c1, (1 - fs) * ft], [r1, c0, fs * (1 - ft)], [r1, c1, fs * ft]]) {
      if (w > 0) out.set(r * C + c, (out.get(r * C + c) || 0) + w);
    }
    return [...out].map(([v, w]) => [Math.floor(v / C), v % C, w]);
  }

  checkCamera(s, t) {
    const d = this.d;
    for (const [name, v, n] of [["s", s, d.rows], ["t", t, d.cols]]) {
      if (!Number.isFinite(v) || v < -this.margin || v > n - 1 + this.margin) {
        throw new LfcError(`camera ${name}=${v} is outside the grid (0..${n - 1} ± ${this.margin} views)`);
      }
    }
  }

  /** The view at grid position (s, t): {pixels (H·W·C of the file's dtype), ms}. `focus`:
   *  one disparity everywhere (null: the file's maps); `aperture`: synthetic-aperture radius
   *  in view steps; `level`: the decoder level of the source views; `robust` (default true, as
   *  the Python renderer): where the maps make the views disagree, smoother disparities
   *  (see _consistent); `cubic` (default true, as the Python renderer): the sources sampled
   *  bicubically, else bilinearly (about 0.65× the frame's time: the viewer's preview while a
   *  drag moves the camera). */
  async render(s, t, { focus = null, aperture = 0, level = 0, robust = true, cubic = true } = {}) {
    const t0 = performance.now();
    const d = this.d, H = d.H, W = d.W, P = d.P;
    this.checkCamera(s, t);
    if (!(aperture >= 0) || !Number.isFinite(aperture) || (focus !== null && !Number.isFinite(focus))) {
      throw new LfcError("aperture must be >= 0 and focus finite");
    }
    let disp = focus === null && aperture === 0 ? this.disparity(s, t) : null;
    const maps = disp !== null;
    if (!disp) disp = new Float32Array(H * W).fill(focus || 0);
    const src = this.sources(s, t, aperture);
    const keys = src.map(([r, c]) => `${r * d.cols + c}:${level}`);
    const keep = new Set(keys);
    const imgs = [];
    for (const [r, c] of src) imgs.push(await this.view(r * d.cols + c, level));
    const warp = this._warpCoefs(src);
    if (robust && maps && src.length > 1) disp = this._consistent(s, t, src, imgs, disp, warp);
    const g = { P, Wp: d.Wp, Hp: d.Hp, H, W, wasm: Renderer.useWasm };
    const jobs = src.map(([r, c, w], j) => [s - r, t - c, Math.fround(w), warp ? warp[j] : null]);
    let acc = null;
    if (this.pool && H * W >= this.poolMinPixels) {
      try {
        acc = await this.pool.blend(g, keys, imgs, disp, jobs, cubic);
      } catch (e) {                                  // (workers that cannot run: the page's thread from now on)
        console.warn(`render workers failed (${e.message}); rendering on the page's thread`);
        this.pool.terminate();
        this.pool = null;
      }
    }
    if (!acc) acc = blendBand(g, imgs, disp, jobs, cubic, 0, H);
    this._trim(keep);
    const planes = rintPlanes(acc, g.wasm !== false);
    const pixels = fromPlanes(planes, H, W, H, W, d.C, d.peak);
    return { pixels, ms: performance.now() - t0, sources: src.length, cubic, wasm: g.wasm && BlendKernel.shared() !== null };
  }

  /** Per source [r, c, w] of a file with per-view warps (tx version 5), where its pixel lies
   *  from where the camera's does (the camera's warp: the sources' blend of theirs, so that a
   *  captured view is its own pixels): [yy, yx, y0, xy, xx, x0] coefficients of y and x and
   *  constants (px) of the y and x offsets; null without warps (rlfc.render.Renderer._warpCoefs). */
  _warpCoefs(src) {
    const d = this.d, W = d.warp;
    if (!W) return null;
    const cam = [0, 0, 0, 0];
    for (const [r, c, w] of src) for (let i = 0; i < 4; i++) cam[i] += w * W[4 * (r * d.cols + c) + i];
    const k = 1 / 65536;
    return src.map(([r, c]) => {
      const v = r * d.cols + c, a = W[4 * v] - cam[0], b = W[4 * v + 1] - cam[1];
      const cx = W[4 * v + 2] - cam[2], cy = W[4 * v + 3] - cam[3];
      return [a * k, b * k, cy / 256, -b * k, a * k, cx / 256];
    });
  }

  /** Bilinear samples of plane 0 of view planes `img` on a gh×gw grid of pixels every `step`
   *  pixels, displaced by D[i·gw + j]·(ds, dt): out[i·gw + j]. Positions clamped to the image,
   *  weights at the exact positions (OpenCV 5's remap); plus the source's warp offset `wc` where
   *  given. */
  _sampleGrid(img, gh, gw, step, D, ds, dt, out, wc = null) {
    const d = this.d, P = d.P, Wp = d.Wp, H = d.H, Wi = d.W, Hp1 = d.Hp - 1, Wp1 = Wp - 1, f32 = Math.fround;
    const dsf = f32(ds), dtf = f32(dt);
    for (let gy = 0, k = 0; gy < gh; gy++) {
      const y = gy * step;
      for (let gx = 0; gx < gw; gx++, k++) {
        const x = gx * step, dd = D[k];
        let Y = f32(y + f32(dd * dsf)), X = f32(x + f32(dd * dtf));
        if (wc) { Y = f32(Y + f32(wc[0] * y + wc[1] * x + wc[2])); X = f32(X + f32(wc[3] * y + wc[4] * x + wc[5])); }
        Y = Y < 0 ? 0 : Y > H - 1 ? H - 1 : Y;
        X = X < 0 ? 0 : X > Wi - 1 ? Wi - 1 : X;
        const y0 = Math.floor(Y), x0 = Math.floor(X), fy = Y - y0, fx = X - x0;
        const y1 = y0 + 1 < Hp1 ? y0 + 1 : Hp1, x1 = x0 + 1 < Wp1 ? x0 + 1 : Wp1;
        const i00 = (y0 * Wp + x0) * P, i01 = (y0 * Wp + x1) * P, i10 = (y1 * Wp + x0) * P, i11 = (y1 * Wp + x1) * P;
        out[k] = (img[i00] * (1 - fx) + img[i01] * fx) * (1 - fy) + (img[i10] * (1 - fx) + img[i11] * fx) * fy;
      }
    }
  }

  /** The robust choice's cost at each of the gh×gw grid points every S pixels (Float32Array):
   *  the sources' weighted variance about their blend, each sampled bilinearly (plane 0) at its
   *  point displaced by D (the candidate's disparities) and the source's warp, and less its own
   *  box mean over kb×kb grid points first (its brightness: rlfc.render.ROBUST_LEVEL_WINDOW). The
   *  samples on the blend's WebAssembly module where Renderer.useWasm and it can
   *  (BlendKernel.samples), else in _sampleGrid; the same float32 values. */
  _cost(s, t, src, imgs, D, gh, gw, S, kb, warp = null) {
    const d = this.d, G = gh * gw, nq = src.length, f32 = Math.fround, wfs = src.map(([, , w]) => f32(w));
    const kern = Renderer.useWasm ? BlendKernel.shared() : null;
    let smp = kern && kern.samples({ P: d.P, Wp: d.Wp, Hp: d.Hp, H: d.H, W: d.W }, imgs,
      src.map(([r, c], q) => [s - r, t - c, wfs[q], warp && warp[q]]), D, gh, gw, S);
    if (!smp) {
      smp = src.map(() => new Float32Array(G));
      src.forEach(([r, c], q) => this._sampleGrid(imgs[q], gh, gw, S, D, s - r, t - c, smp[q], warp && warp[q]));
    }
    for (const x of smp) {                                   // x − its box mean (cv2.blur: double sums, × 1/kb²)
      const m = boxMean(x, gh, gw, kb);
      for (let i = 0; i < G; i++) x[i] = f32(x[i] - m[i]);
    }
    const cost = new Float32Array(G);
    for (let i = 0; i < G; i++) {                            // the blend, then the weighted variance about it
      let a = 0, v = 0;
      for (let q = 0; q < nq; q++) a = f32(a + f32(wfs[q] * smp[q][i]));
      for (let q = 0; q < nq; q++) { const e = f32(smp[q][i] - a); v = f32(v + f32(wfs[q] * f32(e * e))); }
      cost[i] = v;
    }
    return cost;
  }

  /** (H·W) disparities: per pixel the most photo-consistent of three candidates, smoothest
   *  first (the frame's median disparity, the map's 5×5-block median, the map), chosen on every
   *  4th pixel by the weighted variance of the sources' luma (each less its own mean over 16×16
   *  grid points: its brightness) around their blend, box-averaged over 4×4 grid points; a later
   *  candidate wins where its cost is below half the best so far (by more than 1e-4 relative;
   *  costs below 1e-6 count as 0).
   *  The method and constants of rlfc.render.Renderer._consistent. */
  _consistent(s, t, src, imgs, disp, warp = null) {
    const d = this.d, H = d.H, W = d.W, S = 4, f32 = Math.fround;
    const by = Math.ceil(H / 8), bx = Math.ceil(W / 8);
    const blk = new Float32Array(by * bx);
    for (let i = 0; i < by; i++) for (let j = 0; j < bx; j++) blk[i * bx + j] = disp[8 * i * W + 8 * j];
    const sorted = Float32Array.from(blk).sort(), n = sorted.length;
    const median = n % 2 ? sorted[n >> 1] : f32((sorted[n / 2 - 1] + sorted[n / 2]) / 2);
    // 5×5 median, replicated border: each window in a typed array, insertion-sorted (stable, as the
    // comparator sort before; a quarter of its time: 3 against 12 ms for 64×64 blocks)
    const med = new Float32Array(by * bx), win = new Float32Array(25);
    const brow = Int32Array.from({ length: by + 4 }, (_, i) => Math.min(Math.max(i - 2, 0), by - 1) * bx);
    const bcol = Int32Array.from({ length: bx + 4 }, (_, j) => Math.min(Math.max(j - 2, 0), bx - 1));
    for (let i = 0; i < by; i++) {
      for (let j = 0; j < bx; j++) {
        for (let a = 0, n = 0; a < 5; a++) for (let b = 0; b < 5; b++) win[n++] = blk[brow[i + a] + bcol[j + b]];
        for (let p = 1; p < 25; p++) {
          const v = win[p];
          let q = p - 1;
          for (; q >= 0 && win[q] > v; q--) win[q + 1] = win[q];
          win[q + 1] = v;
        }
        med[i * bx + j] = win[12];
      }
    }
    const gh = Math.ceil(H / S), gw = Math.ceil(W / S), G = gh * gw;
    const kb = levelBox(gh, gw, S);
    const cand = [
      () => median,
      (y, x) => med[(y >> 3) * bx + (x >> 3)],
      (y, x) => disp[y * W + x],
    ];
    const best = new Float32Array(G), choice = new Uint8Array(G);
    const D = new Float32Array(G);
    const refl = (i, m) => {                                   // BORDER_REFLECT_101
      if (m === 1) return 0;
      for (;;) {
        if (i < 0) i = -i; else if (i >= m) i = 2 * m - 2 - i; else return i;
      }
    };
    const blurred = new Float32Array(G);
    // the box's reflected rows and columns: rows[i + a] = refl(i + a − 2), a = 0..3 (no calls per tap)
    const rows = Int32Array.from({ length: gh + 3 }, (_, i) => refl(i - 2, gh));
    const cols = Int32Array.from({ length: gw + 3 }, (_, j) => refl(j - 2, gw));
    cand.forEach((fn, k) => {
      for (let i = 0; i < gh; i++) for (let j = 0; j < gw; j++) D[i * gw + j] = fn(i * S, j * S);
      const cost = this._cost(s, t, src, imgs, D, gh, gw, S, kb, warp);
      for (let i = 0; i < gh; i++) {                          // 4×4 box, anchor (2, 2)
        const r0 = rows[i] * gw, r1 = rows[i + 1] * gw, r2 = rows[i + 2] * gw, r3 = rows[i + 3] * gw;
        for (let j = 0; j < gw; j++) {
          let sum;
          if (j >= 2 && j <= gw - 2) {                       // columns j − 2 .. j + 1: no reflection
            const a = r0 + j - 2, b = r1 + j - 2, c = r2 + j - 2, e = r3 + j - 2;   // (the same order of sums)
            sum = cost[a] + cost[a + 1] + cost[a + 2] + cost[a + 3] + cost[b] + cost[b + 1] + cost[b + 2] + cost[b + 3]
              + cost[c] + cost[c + 1] + cost[c + 2] + cost[c + 3] + cost[e] + cost[e + 1] + cost[e + 2] + cost[e + 3];
          } else {
            sum = 0;
            for (const row of [r0, r1, r2, r3]) for (let q = 0; q < 4; q++) sum += cost[row + cols[j + q]];
          }
          blurred[i * gw + j] = f32(sum / 16);
        }
      }
      // rlfc.render.robust_choice: below ROBUST_FLOOR is 0; a later candidate must beat the margin
      // by more than ROBUST_TIE (exact agreement and exactly half are ties: the smoother stays)
      const floor = f32(1e-6), margin = f32(0.5 * (1 - 1e-4));
      for (let i = 0; i < G; i++) {
        const c = blurred[i] >= floor ? blurred[i] : 0;
        if (k === 0) best[i] = c;
        else if (c < f32(best[i] * margin)) { best[i] = c; choice[i] = k; }
      }
    });
    const out = new Float32Array(H * W);
    for (let y = 0; y < H; y++) {                              // (the candidates, inlined: 4 pixels a choice)
      const c = (y >> 2) * gw, b = (y >> 3) * bx, o = y * W;
      for (let x = 0; x < W; x += 4) {
        const k = choice[c + (x >> 2)], e = Math.min(x + 4, W);
        if (k === 2) for (let i = o + x; i < o + e; i++) out[i] = disp[i];
        else {
          const v = k === 0 ? median : med[b + (x >> 3)];
          for (let i = o + x; i < o + e; i++) out[i] = v;
        }
      }
    }
    return out;
  }
}

/** The blend of a frame's sources over rows y0..y1: a Float32Array ((y1 − y0)·W·P), acc +=
 *  wf · (every plane of source j's planes imgs[j] sampled at each pixel (y, x), displaced by
 *  disp·(ds, dt) plus the source's warp offset wc where given), the sources in order (jobs[j] =
 *  [ds, dt, wf, wc]); `disp` holds the band's rows ((y1 − y0)·W); g = {P, Wp, Hp, H, W, wasm}: the
 *  planes' layout and the frame's size, and whether to blend on WebAssembly (BlendKernel) where
 *  this environment can. Bicubic, or bilinear where !cubic. A band's pixels do not depend on the
 *  rows beside it, so bands computed apart (render_pool.js) make the same frame; the kernel and
 *  the loops make the same accumulator, bit for bit. */
export function blendBand(g, imgs, disp, jobs, cubic, y0, y1) {
  const k = g.wasm === false ? null : BlendKernel.shared();
  const got = k && k.band(g, imgs, disp, jobs, cubic, y0, y1);
  if (got) return got;
  const acc = new Float32Array((y1 - y0) * g.W * g.P);
  jobs.forEach(([ds, dt, wf, wc], j) => blendOne(g, imgs[j], disp, ds, dt, wf, acc, wc, y0, y1, cubic));
  return acc;
}

/** A frame's accumulator (Float32Array) rounded to integer planes (Int32Array), half to even: on
 *  the blend's WebAssembly module where `wasm` and it can, else adding and taking away 1.5·2^52
 *  (the addition rounds a double to the nearest even integer; exact for |v| < 2^51, planes are far
 *  inside). The same integers either way. */
export function rintPlanes(acc, wasm = true) {
  const k = wasm ? BlendKernel.shared() : null, got = k && k.rint(acc);
  if (got) return got;
  const planes = new Int32Array(acc.length), RINT = 6755399441055744;
  for (let i = 0; i < planes.length; i++) planes[i] = (acc[i] + RINT) - RINT;
  return planes;
}

/** One source of blendBand: the Python renderer's _blend of one source (positions clamped to the
 *  image, taps past the decoded buffer repeat its edge, each sample rounded to float32 as stored
 *  there), bicubic or bilinear (the taps at floor and floor + 1: render(..., {cubic: false})), in
 *  one pass without index or sample arrays. */
function blendOne(g, img, disp, ds, dt, wf, acc, wc, y0, y1, cubic) {
  const { P, Wp, H, W } = g, Hp1 = g.Hp - 1, Wp1 = Wp - 1, row = Wp * P;
  const dsf = Math.fround(ds), dtf = Math.fround(dt), f32 = Math.fround, A = -0.75;
  for (let y = y0, k = 0; y < y1; y++) {
    for (let x = 0; x < W; x++, k++) {
      const dd = disp[k];
      let Y = f32(y + f32(dd * dsf)), X = f32(x + f32(dd * dtf));
      if (wc) { Y = f32(Y + f32(wc[0] * y + wc[1] * x + wc[2])); X = f32(X + f32(wc[3] * y + wc[4] * x + wc[5])); }
      Y = Y < 0 ? 0 : Y > H - 1 ? H - 1 : Y;
      X = X < 0 ? 0 : X > W - 1 ? W - 1 : X;
      const iy = Math.floor(Y), ix = Math.floor(X), fy = Y - iy, fx = X - ix, o = k * P;
      if (!cubic) {
        const iy1 = iy + 1 < Hp1 ? iy + 1 : Hp1, ix1 = ix + 1 < Wp1 ? ix + 1 : Wp1;
        const i00 = (iy * Wp + ix) * P, i01 = (iy * Wp + ix1) * P, i10 = (iy1 * Wp + ix) * P, i11 = (iy1 * Wp + ix1) * P;
        const gx = 1 - fx, gy = 1 - fy;
        for (let p = 0; p < P; p++) {
          acc[o + p] += wf * f32((img[i00 + p] * gx + img[i01 + p] * fx) * gy + (img[i10 + p] * gx + img[i11 + p] * fx) * fy);
        }
        continue;
      }
      // Keys' weights of the taps at −1, 0, +1, +2 (rlfc.render_ops.keys_weights, inlined: the frame's loop)
      const fx1 = fx + 1, gx = 1 - fx, fy1 = fy + 1, gy = 1 - fy;
      const a0 = ((A * fx1 - 5 * A) * fx1 + 8 * A) * fx1 - 4 * A, a1 = ((A + 2) * fx - (A + 3)) * fx * fx + 1;
      const a2 = ((A + 2) * gx - (A + 3)) * gx * gx + 1, a3 = 1 - a0 - a1 - a2;
      const b0 = ((A * fy1 - 5 * A) * fy1 + 8 * A) * fy1 - 4 * A, b1 = ((A + 2) * fy - (A + 3)) * fy * fy + 1;
      const b2 = ((A + 2) * gy - (A + 3)) * gy * gy + 1, b3 = 1 - b0 - b1 - b2;
      // the taps' columns and rows, clamped to the decoded buffer (its edge repeats)
      const c0 = (ix > 0 ? ix - 1 : 0) * P, c1 = (ix < Wp1 ? ix : Wp1) * P;
      const c2 = (ix + 1 < Wp1 ? ix + 1 : Wp1) * P, c3 = (ix + 2 < Wp1 ? ix + 2 : Wp1) * P;
      const r0 = (iy > 0 ? iy - 1 : 0) * row, r1 = (iy < Hp1 ? iy : Hp1) * row;
      const r2 = (iy + 1 < Hp1 ? iy + 1 : Hp1) * row, r3 = (iy + 2 < Hp1 ? iy + 2 : Hp1) * row;
      for (let p = 0; p < P; p++) {
        const q0 = r0 + p, q1 = r1 + p, q2 = r2 + p, q3 = r3 + p;
        const v = b0 * (img[q0 + c0] * a0 + img[q0 + c1] * a1 + img[q0 + c2] * a2 + img[q0 + c3] * a3)
          + b1 * (img[q1 + c0] * a0 + img[q1 + c1] * a1 + img[q1 + c2] * a2 + img[q1 + c3] * a3)
          + b2 * (img[q2 + c0] * a0 + img[q2 + c1] * a1 + img[q2 + c2] * a2 + img[q2 + c3] * a3)
          + b3 * (img[q3 + c0] * a0 + img[q3 + c1] * a1 + img[q3 + c2] * a2 + img[q3 + c3] * a3);
        acc[o + p] += wf * f32(v);
      }
    }
  }
}

/** blendBand on WebAssembly SIMD (render_kernel.wat: blendOne's operations in its order, two
 *  planes at a time). The module's memory holds the planes of the views blended lately, one slot
 *  of Hp·Wp·P int32 each (least recently used first out; a view is copied in when a call first
 *  names it: along a camera path most frames copy none), then the band's disparities and
 *  accumulator. One per thread (`shared()`; null where WebAssembly SIMD is missing). */
export class BlendKernel {
  /** The most bytes of views one call may blend here (a wider synthetic aperture blends in the loops). */
  static SLOT_BYTES = 256 << 20;
  /** Views kept between calls beyond a call's own (a camera crossing a row or column of views and
   *  back copies none); the module's memory stays as large as the most views it held at once. */
  static KEEP_VIEWS = 8;
  static _shared;

  static shared() {
    if (BlendKernel._shared === undefined) {
      const mod = kernelModule();
      try {
        BlendKernel._shared = mod ? new BlendKernel(mod) : null;
      } catch {
        BlendKernel._shared = null;
      }
    }
    return BlendKernel._shared;
  }

  constructor(mod) {
    this.inst = new WebAssembly.Instance(mod, {});
    this.mem = this.inst.exports.memory;
    this.slotBytes = 0;
    this.slots = [];                     // {a, used}: the views in the module's memory, in slot order
    this.clock = 0;
    this.copies = 0;                     // views copied in (for tests and benchmarks)
  }

  /** rintPlanes' integers, or null where they do not fit in the module's memory. The values go
   *  past the views kept (the next band() overwrites them). */
  rint(acc) {
    const n = acc.length, at = 64 + this.slots.length * (this.slotBytes || 0);
    if (!growTo(this.mem, at + 8 * n)) return null;
    const buf = this.mem.buffer;
    new Float32Array(buf, at, n).set(acc);
    this.inst.exports.rint(at, at + 4 * n, n);
    return new Int32Array(buf, at + 4 * n, n).slice();
  }

  /** Views `imgs` (planes of g's layout) in the module's slots (those held kept, the others copied
   *  in), with `extra` bytes free after the slots: {at: each view's byte address, end: the free
   *  bytes' address}, or null where they do not fit (the caller's loops then do the work). */
  _place(g, imgs, extra) {
    const { P, Wp, Hp } = g, slotBytes = Hp * Wp * P * 4;
    if (imgs.some((m) => m.length !== Hp * Wp * P) || imgs.length * slotBytes > BlendKernel.SLOT_BYTES) return null;
    if (slotBytes !== this.slotBytes) { this.slots = []; this.slotBytes = slotBytes; }
    const { slot, fresh } = assignSlots(this.slots, imgs, Math.max(imgs.length, BlendKernel.KEEP_VIEWS), ++this.clock);
    const SLOTS = 64, end = SLOTS + this.slots.length * slotBytes;
    if (!growTo(this.mem, end + extra)) {                      // (no memory to grow into: the loops)
      this.slots = [];
      return null;
    }
    for (const [i, img] of fresh) {
      new Int32Array(this.mem.buffer, SLOTS + i * slotBytes, Hp * Wp * P).set(img);
      this.copies += 1;
    }
    return { at: slot.map((i) => SLOTS + i * slotBytes), end };
  }

  /** The robust choice's samples of one candidate (Renderer._consistent's, the same float32
   *  values): per source a Float32Array (gh·gw), or null where the views do not fit. jobs: per
   *  source [ds, dt, wf (a float32 value), warp coefficients or null]. */
  samples(g, imgs, jobs, D, gh, gw, step) {
    const G = gh * gw, nq = jobs.length;
    const got = this._place(g, imgs, 4 * G + 4 * nq * G + 8 + nq * 96);
    if (!got) return null;
    const { at, end } = got, outAt = end + 4 * G, srcAt = (outAt + 4 * nq * G + 7) & ~7, buf = this.mem.buffer;
    new Float32Array(buf, end, G).set(D);
    const iv = new Int32Array(buf, srcAt, nq * 24), fv = new Float64Array(buf, srcAt, nq * 12);
    jobs.forEach(([ds, dt, wf, wc], q) => {
      iv[24 * q] = at[q];
      iv[24 * q + 1] = wc ? 1 : 0;
      fv.set([Math.fround(ds), Math.fround(dt), wf, ...(wc || [0, 0, 0, 0, 0, 0])], 12 * q + 1);
    });
    this.inst.exports.samples(end, outAt, gh, gw, step, g.W, g.H, g.Wp, g.Hp, g.P, srcAt, nq, G);
    return jobs.map((_, q) => new Float32Array(buf, outAt + 4 * q * G, G).slice());
  }

  /** blendBand's accumulator, or null where this call does not fit (the loops then blend it). */
  band(g, imgs, disp, jobs, cubic, y0, y1) {
    const { P, Wp, Hp, H, W } = g, n = (y1 - y0) * W;
    const got = this._place(g, imgs, n * 4 + n * P * 4);
    if (!got) return null;
    const { at, end: dispAt } = got, accAt = dispAt + n * 4, buf = this.mem.buffer;
    new Float32Array(buf, dispAt, n).set(disp.subarray(0, n));
    new Float32Array(buf, accAt, n * P).fill(0);
    const blend = this.inst.exports.blend, wcs = new Float64Array(buf, 16, 6);
    jobs.forEach(([ds, dt, wf, wc], j) => {
      if (wc) wcs.set(wc);
      blend(at[j], dispAt, accAt, W, H, Wp, Hp, P, y0, y1, ds, dt, wf, wc ? 16 : 0, cubic ? 1 : 0);
    });
    return new Float32Array(buf, accAt, n * P).slice();
  }
}

/** The robust choice's brightness box in points of its gh×gw grid (every S pixels):
 *  rlfc.render.ROBUST_LEVEL_WINDOW (64 px), at most 2·min(gh, gw) − 1 points (one reflection). */
export function levelBox(gh, gw, S) {
  return Math.max(1, Math.min(Math.floor(64 / S), 2 * Math.min(gh, gw) - 1));
}

/** The box mean over k×k of a gh×gw float32 plane, as OpenCV's cv2.blur gives it (anchor k>>1,
 *  BORDER_REFLECT_101 edges, running sums in double along the rows and then the columns, × 1/k²,
 *  rounded to float32; k ≤ 2·min(gh, gw) − 1, so one reflection reaches every tap): a
 *  Float32Array. */
export function boxMean(x, gh, gw, k) {
  const a0 = k >> 1, scale = 1 / (k * k);
  const refl = (i, m) => (m === 1 ? 0 : i < 0 ? -i : i >= m ? 2 * m - 2 - i : i);
  const cols = Int32Array.from({ length: gw + k - 1 }, (_, j) => refl(j - a0, gw));
  const rows = Int32Array.from({ length: gh + k - 1 }, (_, i) => refl(i - a0, gh) * gw);
  const hs = new Float64Array(gh * gw), out = new Float32Array(gh * gw), col = new Float64Array(gw);
  for (let i = 0; i < gh; i++) {                             // row sums: the first window, then slide
    const o = i * gw;
    let sum = 0;
    for (let q = 0; q < k; q++) sum += x[o + cols[q]];
    hs[o] = sum;
    for (let j = 1; j < gw; j++) {
      sum += x[o + cols[j + k - 1]] - x[o + cols[j - 1]];
      hs[o + j] = sum;
    }
  }
  for (let q = 0; q < k; q++) for (let j = 0, r = rows[q]; j < gw; j++) col[j] += hs[r + j];
  for (let i = 0; i < gh; i++) {                             // column sums likewise, a row at a time
    if (i > 0) {
      const add = rows[i + k - 1], sub = rows[i - 1];
      for (let j = 0; j < gw; j++) col[j] += hs[add + j] - hs[sub + j];
    }
    for (let j = 0, o = i * gw; j < gw; j++) out[o + j] = Math.fround(col[j] * scale);
  }
  return out;
}

/** RGBA bytes (H·W·4) for a canvas from pixels of C channels (16-bit: the high byte). */
export function toRGBA(px, H, W, C, peak) {
  const out = new Uint8ClampedArray(H * W * 4);
  const sh = peak > 255 ? 8 : 0;
  for (let i = 0; i < H * W; i++) {
    const g = px[i * C] >> sh;
    if (C >= 3) { out[4 * i] = g; out[4 * i + 1] = px[i * C + 1] >> sh; out[4 * i + 2] = px[i * C + 2] >> sh; }
    else { out[4 * i] = out[4 * i + 1] = out[4 * i + 2] = g; }
    out[4 * i + 3] = C === 2 || C === 4 ? px[i * C + C - 1] >> sh : 255;
  }
  return out;
}
