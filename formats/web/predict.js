// predict.js — a view's reconstruction on WebAssembly SIMD (predict_kernel.wat) for lfc.js's
// TxDecoder: its prediction from its key views, then its residual blocks parsed and added; the
// same planes (and the same parse errors) as parseBlock's, _predictTb's and _addResidual's
// loops, bit for bit. The view is built in the module's memory between begin() and end() (no
// await in between: one view at a time per kernel).
import { kernelModule } from "./predict_kernel.js";
import { assignSlots, growTo } from "./wasm_module.js";

const TAB = 8192;                 // the tables' byte address (below it: the kernel's scratch and constants)
const ROW = 8;                    // int32 per prediction table row
const ZZ = 4224, T8I = 4480, T8D = 4736, PLANES = 5248, BANDS = 5344, CLASSES = 5600;

export class PredictKernel {
  /** false: every decoder predicts in its loops (the same planes). The viewer's `&wasm=0` clears it. */
  static useWasm = true;
  /** The most bytes of key views one decoder keeps in its kernel's memory. */
  static SLOT_BYTES = 256 << 20;
  /** Key views kept between views beyond a view's own (decoding views one after another copies
   *  each key once while they fit). */
  static KEEP_KEYS = 8;

  /** A kernel for one decoder, or null where this environment has no WebAssembly SIMD.
   *  `zigzag`: the scan's raster positions (64); `t8`: the 8×8 transform, row-major (64);
   *  `bands`: each scan position's magnitude context band (64). */
  static create(zigzag, t8, bands) {
    const mod = kernelModule();
    if (!mod) return null;
    try {
      return new PredictKernel(mod, zigzag, t8, bands);
    } catch {
      return null;
    }
  }

  constructor(mod, zigzag, t8, bands) {
    this.inst = new WebAssembly.Instance(mod, {});
    this.mem = this.inst.exports.memory;
    const buf = this.mem.buffer;
    new Int32Array(buf, ZZ, 64).set(zigzag);
    new Int32Array(buf, T8I, 64).set(t8);
    new Float64Array(buf, T8D, 64).set(t8);
    new Int32Array(buf, BANDS, 64).set(bands);
    this.tables = null;                  // the rANS tables copied in (a decoder's: they do not change)
    this.slots = [];                     // {a, used}: key planes in the module's memory, in slot order
    this.clock = 0;
    this.copies = 0;                     // key views copied in (for tests and benchmarks)
  }

  /** Start view v of decoder `d` in the module's memory: its prediction from its key views before
   *  weighted prediction (predicted), or a copy of `img` (Int32Array Hp·Wp·P); room for streams
   *  of up to `maxData` bytes. false where it does not fit here (the caller's loops then build it). */
  begin(d, v, predicted, img, maxData = 0) {
    const { P, Hp, Wp } = d, n = Hp * Wp * P, slotBytes = n * 4, nTb = (Hp >> 3) * (Wp >> 3);
    const keys = [];
    for (let j = 0; predicted && j < 4; j++) {
      const k = d.refs[4 * v + j];
      if (k >= 0 && !keys.includes(k)) keys.push(k);
    }
    const planes = keys.map((k) => d.keyPlanes[d.keySlot[k]]);
    if (planes.some((kp) => !kp || kp.length !== n) || keys.length * slotBytes > PredictKernel.SLOT_BYTES) return false;
    if (slotBytes !== this.slotBytes) { this.slots = []; this.slotBytes = slotBytes; }
    const at = assignSlots(this.slots, planes, Math.max(planes.length, Math.min(PredictKernel.KEEP_KEYS,
      Math.floor(PredictKernel.SLOT_BYTES / slotBytes))), ++this.clock);
    const t = d.tables;
    const lev = TAB + nTb * 4 * ROW * 4, tbs = lev + nTb * P * 256, last = tbs + nTb * 8, rec = last + nTb * P * 4;
    const esc = rec + nTb * P * 256, slotT = esc + nTb * P * 256, freqT = slotT + t.slot.length;
    const cumT = freqT + t.freq.length * 4, outAt = (cumT + t.cum.length * 4 + 15) & ~15, slotsAt = outAt + slotBytes;
    const dataAt = slotsAt + this.slots.length * slotBytes, need = dataAt + maxData + 8;
    if (!growTo(this.mem, need)) {                             // (no memory to grow into: the loops)
      this.slots = [];
      return false;
    }
    const buf = this.mem.buffer;
    for (const [i, kp] of at.fresh) {
      new Int32Array(buf, slotsAt + i * slotBytes, n).set(kp);
      this.copies += 1;
    }
    if (this.tables !== t) {
      new Uint8Array(buf, slotT, t.slot.length).set(t.slot);
      new Int32Array(buf, freqT, t.freq.length).set(t.freq);
      new Int32Array(buf, cumT, t.cum.length).set(t.cum);
      this.tables = t;
    }
    new Int32Array(buf, CLASSES, P).set(d.pcs);
    this.d = d;
    this.at = { lev, tbs, last, rec, esc, slotT, freqT, cumT, out: outAt, data: dataAt, n, nTb };
    this.planes = new Int32Array(buf, outAt, n);
    const pp = new Int32Array(buf, PLANES, 5 * P);
    for (let p = 0; p < P; p++) pp.set([0, d.bypass[p], d.lo[p], d.hi[p], d.flat[p]], 5 * p);
    if (!predicted) {
      this.planes.set(img);
      return true;
    }
    const tab = new Int32Array(buf, TAB, nTb * 4 * ROW), tap = d._at;
    const loc = d.cell[v] * d.nby8 * d.nbx8;
    let r = 0;
    for (let y0 = 0; y0 < Hp; y0 += 8) {
      for (let x0 = 0; x0 < Wp; x0 += 8) {
        const l = loc + (y0 >> 3) * d.nbx8 + (x0 >> 3), dd = d.disp[l], mode = d.modes[l], first = r;
        const out = outAt + (y0 * Wp + x0) * P * 4;
        for (let j = 0; j < 4; j++) {
          const k = d.refs[4 * v + j];
          if (k < 0) continue;
          const w = mode === 0 ? d.weights[4 * v + j] : (mode - 1 === j ? 64 : 0);
          if (!w) continue;
          d._tapAt(v, k, dd, y0, x0);
          const ry = tap[0], rx = tap[1], o = r * ROW;
          tab[o] = slotsAt + at.slot[keys.indexOf(k)] * slotBytes;
          tab[o + 1] = ry; tab[o + 2] = rx; tab[o + 3] = tap[2]; tab[o + 4] = tap[3]; tab[o + 5] = w; tab[o + 6] = out;
          tab[o + 7] = ry >= 0 && ry + 8 <= Hp - 1 && rx >= 0 && rx + 8 <= Wp - 1 ? 0 : 4;
          r++;
        }
        if (r === first) {                     // no key view weighs: the prediction is 0
          const o = r * ROW;
          tab.fill(0, o, o + ROW);
          tab[o + 6] = out;
          r++;
        }
        tab[first * ROW + 7] |= 1;
        tab[(r - 1) * ROW + 7] |= 2;
      }
    }
    this.inst.exports.predict(TAB, r, Hp, Wp, P);
    return true;
  }

  /** Parse block stream `data` (bytes) of `nt` tbs (kind, key: parseBlock's) into the module's
   *  memory for residual(): [0, modes (Int32Array nt)], or [parseBlock's error code, null]. */
  parse(data, nt, kind, key) {
    const a = this.at, buf = this.mem.buffer;
    new Int32Array(buf, a.lev, nt * this.d.P * 64).fill(0);
    new Uint8Array(buf, a.data, data.length).set(data);
    const code = this.inst.exports.parse(a.data, a.data + data.length, nt, this.d.P, kind, key, a.lev, a.tbs, a.last,
      a.rec, a.esc, a.slotT, a.freqT, a.cumT, this.d.tables.A);
    return [code, code ? null : new Int32Array(buf, a.tbs, nt).slice()];
  }

  /** The tbs parse() just parsed (modes, nt) added to the view: tb i at pixel
   *  (ys[i], xs[i]); key: a key view's quantizer steps (else a view's). */
  residual(modes, ys, xs, key) {
    const d = this.d, { P, Wp } = d, nt = modes.length, buf = this.mem.buffer;
    const pp = new Int32Array(buf, PLANES, 5 * P), steps = d.step16[key ? 0 : 1];
    for (let p = 0; p < P; p++) pp[5 * p] = steps[p];
    const tb = new Int32Array(buf, this.at.tbs, 2 * nt);
    for (let i = 0; i < nt; i++) {
      tb[2 * i] = modes[i];
      tb[2 * i + 1] = this.at.out + (ys[i] * Wp + xs[i]) * P * 4;
    }
    this.inst.exports.residual(this.at.lev, this.at.tbs, nt, P, Wp);
  }

  /** The view copied out into `img` (null: dropped). */
  end(img) {
    if (img) img.set(this.planes);
    this.planes = null;
    this.d = null;
  }
}
