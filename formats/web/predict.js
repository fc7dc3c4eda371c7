// predict.js — a view's prediction from its key views on WebAssembly SIMD (predict_kernel.wat),
// for lfc.js's TxDecoder: the same planes as its _predictTb loops, bit for bit.
import { kernelModule } from "./predict_kernel.js";

const TAB = 4096;                 // the table's byte address (below it: the kernel's accumulator and window)
const ROW = 8;                    // int32 per table row

export class PredictKernel {
  /** false: every decoder predicts in its loops (the same planes). The viewer's `&wasm=0` clears it. */
  static useWasm = true;
  /** The most bytes of key views one decoder keeps in its kernel's memory. */
  static SLOT_BYTES = 256 << 20;
  /** Key views kept between views beyond a view's own (decoding views one after another copies
   *  each key once while they fit). */
  static KEEP_KEYS = 8;

  /** A kernel for one decoder, or null where this environment has no WebAssembly SIMD. */
  static create() {
    const mod = kernelModule();
    if (!mod) return null;
    try {
      return new PredictKernel(mod);
    } catch {
      return null;
    }
  }

  constructor(mod) {
    this.inst = new WebAssembly.Instance(mod, {});
    this.mem = this.inst.exports.memory;
    this.slots = [];                     // {kp, used}: key planes in the module's memory, in slot order
    this.clock = 0;
    this.copies = 0;                     // key views copied in (for tests and benchmarks)
  }

  /** View v of decoder `d` predicted into `img` (Int32Array Hp·Wp·P) before weighted prediction;
   *  false where it does not fit here (the caller's loops then predict it). */
  view(d, v, img) {
    const { P, Hp, Wp } = d, n = Hp * Wp * P, slotBytes = n * 4, nTb = (Hp >> 3) * (Wp >> 3);
    const keys = [];
    for (let j = 0; j < 4; j++) {
      const k = d.refs[4 * v + j];
      if (k >= 0 && !keys.includes(k)) keys.push(k);
    }
    const planes = keys.map((k) => d.keyPlanes[d.keySlot[k]]);
    if (planes.some((kp) => !kp || kp.length !== n) || keys.length * slotBytes > PredictKernel.SLOT_BYTES) return false;
    const at = this._slots(planes, slotBytes);
    const outAt = TAB + nTb * 4 * ROW * 4, slotsAt = outAt + slotBytes, need = slotsAt + this.slots.length * slotBytes;
    if (need > this.mem.buffer.byteLength) {
      try {
        this.mem.grow(Math.ceil((need - this.mem.buffer.byteLength) / 65536));
      } catch {                                                // (no memory to grow into: the loops)
        this.slots = [];
        return false;
      }
    }
    const buf = this.mem.buffer;
    for (const [i, kp] of at.fresh) {
      new Int32Array(buf, slotsAt + i * slotBytes, n).set(kp);
      this.copies += 1;
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
    img.set(new Int32Array(buf, outAt, n));
    return true;
  }

  /** Slots for key planes `planes` (held ones kept, the others in free or least recently used
   *  slots): {slot: per plane, fresh: [slot, planes] to copy in}. */
  _slots(planes, slotBytes) {
    if (slotBytes !== this.slotBytes) { this.slots = []; this.slotBytes = slotBytes; }
    const tick = ++this.clock, cap = Math.max(planes.length, Math.min(PredictKernel.KEEP_KEYS,
      Math.floor(PredictKernel.SLOT_BYTES / slotBytes)));
    const slot = planes.map((kp) => this.slots.findIndex((sl) => sl.kp === kp));
    slot.forEach((i) => { if (i >= 0) this.slots[i].used = tick; });
    const fresh = [];
    planes.forEach((kp, j) => {
      if (slot[j] >= 0) return;
      let i = this.slots.length;
      if (i < cap) this.slots.push(null);
      else {
        i = 0;
        this.slots.forEach((sl, q) => { if (sl.used < this.slots[i].used) i = q; });
      }
      this.slots[i] = { kp, used: tick };
      slot[j] = i;
      fresh.push([i, kp]);
    });
    return { slot, fresh };
  }
}
