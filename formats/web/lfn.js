// lfn.js — light field networks (codec "lfn", docs/FORMAT.md "LFN codec") in the browser: the
// network read from an .lfc file (or the prefix fetched so far), grown by fetching further
// steps as the level rises (version 3: byte ranges of `lfn.steps`; versions 1–2: `lfn.step.NNNN`
// sections), and rendered in plain JS (double precision; the
// Python renderer computes in float32, so pixels agree within one grey level).
//
// Cameras follow lfn_stream/cameras.py: gridPose(s, t) (continuous grid position), orbitPose(v,
// yaw, pitch) (a captured view turned about the scene's pivot), with the captured intrinsics.
import { FormatError, LfcError, UnsupportedError } from "./lfc.js";
import { kernelModule } from "./lfn_kernel.js";

/** Values of all networks the viewer builds together (weights as doubles): 2^25 = 256 MiB. */
export const MAX_NETWORK_VALUES = 2 ** 25;

const HALF = (() => {                       // fp16 bit pattern → value
  const t = new Float64Array(65536);
  for (let h = 0; h < 65536; h++) {
    const s = h & 0x8000 ? -1 : 1, e = (h >> 10) & 31, m = h & 1023;
    t[h] = e === 0 ? s * m * 2 ** -24 : e === 31 ? (m ? NaN : s * Infinity) : s * (1 + m / 1024) * 2 ** (e - 15);
  }
  return t;
})();

function floats(bytes, dtype) {
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const n = dtype === "fp16" ? bytes.length >> 1 : bytes.length >> 2;
  const out = new Float64Array(n);
  if (dtype === "fp16") for (let i = 0; i < n; i++) out[i] = HALF[dv.getUint16(2 * i, true)];
  else for (let i = 0; i < n; i++) out[i] = dv.getFloat32(4 * i, true);
  for (let i = 0; i < n; i++) {                  // FORMAT.md: finite and within fp16's range, fp32 files too
    if (!(Math.abs(out[i]) <= 65504)) throw new FormatError("lfn network weights hold NaN, infinite or values beyond ±65504");
  }
  return out;
}

function intIn(obj, key, lo, hi, where, dflt) {
  const v = obj[key] === undefined ? dflt : obj[key];
  if (!Number.isInteger(v) || v < lo || v > hi) throw new FormatError(`${where}: ${key} must be an integer in ${lo}..${hi}, got ${JSON.stringify(v)}`);
  return v;
}

function finiteList(v, n, where) {
  if (!Array.isArray(v) || v.length !== n || !v.every((x) => typeof x === "number" && Number.isFinite(x))) {
    throw new FormatError(`${where} must be a list of ${n} finite numbers`);
  }
  return v;
}

/** A nested JSON list of exactly `shape` finite numbers, flattened (row-major). */
function nested(v, shape, where) {
  const out = [];
  const walk = (a, k) => {
    if (k === shape.length) {
      if (typeof a !== "number" || !Number.isFinite(a)) throw new FormatError(`${where} must hold finite numbers`);
      out.push(a);
      return;
    }
    if (!Array.isArray(a) || a.length !== shape[k]) throw new FormatError(`${where} must be a ${shape.join("x")} array`);
    for (const x of a) walk(x, k + 1);
  };
  walk(v, 0);
  return out;
}

/** The 3×3 dilation of a 0/1 grid (Uint8Array h·w, as cv2.dilate with a 3×3 kernel). */
function dilate3(src, h, w) {
  const out = new Uint8Array(h * w);
  for (let y = 0; y < h; y++) {
    for (let x = 0; x < w; x++) {
      if (!src[y * w + x]) continue;
      for (let yy = Math.max(0, y - 1); yy <= Math.min(h - 1, y + 1); yy++) {
        for (let xx = Math.max(0, x - 1); xx <= Math.min(w - 1, x + 1); xx++) out[yy * w + xx] = 1;
      }
    }
  }
  return out;
}

const stepName = (j) => `lfn.step.${String(j).padStart(4, "0")}`;

const RB = 64;                               // rays per network batch (a multiple of 4)

// LfnRenderer.render_lod_mip's constants (lfn_stream/render.py): the coarsest lattice (every 2^3
// pixels), the size each level runs (the one made for the level below), the offset of a pixel's
// level and the part of each interval between two levels that blends them
export const MIP_LEVELS = 3, MIP_SHARPEN = 1, MIP_OFFSET = 0.25, MIP_BLEND = 0.25;

/** The network's dense layers and LayerNorms on WebAssembly SIMD (lfn_kernel.wat): its weights
 *  and one batch's activations in the module's memory; the same doubles as
 *  LfnDecoder._forwardBatch's loops (every operation in the same order, each rounded once; tested). */
class DenseKernel {
  constructor(mod, Wt, b, g, be, w, ow, ob, occ, occN) {
    const inst = new WebAssembly.Instance(mod, {});
    const mem = inst.exports.memory, big = Math.max(w, 6) * RB;
    const sizes = [...Wt.map((x) => x.length), ...[b, g, be].flat().map((x) => x.length), 6 * RB, w * RB, big, big, w,
      ow.length, ob.length, 4 * RB, occ ? occ.length + 2 * occN * RB + RB : 0];
    const bytes = sizes.reduce((a, n) => a + 8 * n, 0);
    if (bytes > mem.buffer.byteLength) mem.grow(Math.ceil((bytes - mem.buffer.byteLength) / 65536));
    let off = 0;
    const take = (n, from = null) => {
      const v = new Float64Array(mem.buffer, off, n);
      if (from) v.set(from);
      off += 8 * n;
      return v;
    };
    this.W = Wt.map((x) => take(x.length, x));
    this.b = b.map((x) => take(x.length, x));
    this.g = g.map((x) => take(x.length, x));
    this.be = be.map((x) => take(x.length, x));
    Object.assign(this, { X: take(6 * RB), z: take(w * RB), h: take(big), h2: take(big), m: take(w), w,
      ow: take(ow.length, ow), ob: take(ob.length, ob), o: take(4 * RB),
      dense: inst.exports.dense, norm: inst.exports.norm, relu: inst.exports.relu });
    if (occ) Object.assign(this, { occN, occP: take(occ.length, occ), o1: take(occN * RB), o2: take(occN * RB), o3: take(RB) });
  }

  /** z[j·RB + r] = Σ_q W_i[j·stride + q]·hin[q·RB + r] + b_i[j] for j < n, r < R4 (hin and z this
   *  kernel's arrays). */
  layer(i, hin, z, k, n, R4) {
    this.dense(this.W[i].byteOffset, i === 0 ? 6 : this.w, hin.byteOffset, z.byteOffset, this.b[i].byteOffset, k, n, R4, RB, 0);
  }

  /** The output layer's sums of the rays in hin (r < R4) from the first n neurons: o[c·RB + r] =
   *  ob[c] + Σ_j ow[c·w + j]·hin[j·RB + r], each sum started from its bias (the JS loop's order). */
  outputs(hin, n, R4) {
    this.dense(this.ow.byteOffset, this.w, hin.byteOffset, this.o.byteOffset, this.ob.byteOffset, n, 4, R4, RB, 1);
    return this.o;
  }

  /** The occupancy net's logits of the rays in X (r < R4): Linear 6→k, ReLU, k→k, ReLU, k→1, each
   *  sum started from its bias (LfnDecoder._occupied's order). */
  occupancy(R4) {
    const k = this.occN, W1 = this.occP.byteOffset, b1 = W1 + 8 * 6 * k, W2 = b1 + 8 * k, b2 = W2 + 8 * k * k;
    const W3 = b2 + 8 * k, b3 = W3 + 8 * k, o1 = this.o1.byteOffset, o2 = this.o2.byteOffset;
    this.dense(W1, 6, this.X.byteOffset, o1, b1, 6, k, R4, RB, 1);
    this.relu(o1, o1, k * RB);
    this.dense(W2, k, o1, o2, b2, k, k, R4, RB, 1);
    this.relu(o2, o2, k * RB);
    this.dense(W3, k, o2, this.o3.byteOffset, b3, k, 1, R4, RB, 1);
    return this.o3;
  }

  /** Layer i's LayerNorm with the neuron weights m (n values, summing to msum), ReLU and mask:
   *  hout[j·RB + r] from z, for j < n, r < R4 (this kernel's arrays). */
  layerNorm(i, z, hout, m, n, R4, msum) {
    this.m.set(m);
    this.norm(z.byteOffset, hout.byteOffset, this.g[i].byteOffset, this.be[i].byteOffset, this.m.byteOffset, n, R4, RB, msum);
  }

}

// -- small 3-vector / 4×4 helpers (row-major 4×4 in a 16-array) -------------------------------------
const col = (M, j) => [M[j], M[4 + j], M[8 + j]];
const norm3 = (v) => Math.hypot(v[0], v[1], v[2]);

function rotation(axis, deg) {               // Rodrigues, as lfn_stream/cameras.py _rotation
  const [x, y, z] = axis, a = (deg * Math.PI) / 180;
  const c = Math.cos(a), s = Math.sin(a), k = 1 - c;
  return [[c + x * x * k, x * y * k - z * s, x * z * k + y * s],
    [y * x * k + z * s, c + y * y * k, y * z * k - x * s],
    [z * x * k - y * s, z * y * k + x * s, c + z * z * k]];
}
const mul3 = (A, B) => A.map((r) => [0, 1, 2].map((j) => r[0] * B[0][j] + r[1] * B[1][j] + r[2] * B[2][j]));
const mv3 = (A, v) => A.map((r) => r[0] * v[0] + r[1] * v[1] + r[2] * v[2]);

function solve3(A, b) {                       // Gaussian elimination with partial pivoting
  const M = A.map((r, i) => [...r, b[i]]);
  for (let c = 0; c < 3; c++) {
    let p = c;
    for (let r = c + 1; r < 3; r++) if (Math.abs(M[r][c]) > Math.abs(M[p][c])) p = r;
    [M[c], M[p]] = [M[p], M[c]];
    for (let r = 0; r < 3; r++) {
      if (r === c) continue;
      const f = M[r][c] / M[c][c];
      for (let k = c; k < 4; k++) M[r][k] -= f * M[c][k];
    }
  }
  return [M[0][3] / M[0][0], M[1][3] / M[1][1], M[2][3] / M[2][2]];
}

function symEigMinMax(A) {                    // smallest and largest eigenvalue of a symmetric 3×3
  const p1 = A[0][1] ** 2 + A[0][2] ** 2 + A[1][2] ** 2, q = (A[0][0] + A[1][1] + A[2][2]) / 3;
  if (p1 === 0) { const d = [A[0][0], A[1][1], A[2][2]]; return [Math.min(...d), Math.max(...d)]; }
  const p2 = (A[0][0] - q) ** 2 + (A[1][1] - q) ** 2 + (A[2][2] - q) ** 2 + 2 * p1, p = Math.sqrt(p2 / 6);
  const B = A.map((r, i) => r.map((v, j) => (v - (i === j ? q : 0)) / p));
  const det = B[0][0] * (B[1][1] * B[2][2] - B[1][2] * B[2][1]) - B[0][1] * (B[1][0] * B[2][2] - B[1][2] * B[2][0])
    + B[0][2] * (B[1][0] * B[2][1] - B[1][1] * B[2][0]);
  const phi = Math.acos(Math.min(Math.max(det / 2, -1), 1)) / 3;
  const e1 = q + 2 * p * Math.cos(phi), e3 = q + 2 * p * Math.cos(phi + (2 * Math.PI) / 3);
  return [e3, e1];
}

export class LfnDecoder {
  /** The dense layers on WebAssembly SIMD where the environment has it (false: lfn.js's own loops;
   *  the same pixels either way). */
  static useWasm = true;

  /** Open the LFN in an LfcFile (lfc.js): config and geometry checked, the base network and
   *  the steps up to `maxNeurons` neurons read (fetched) and verified. */
  static async open(file, { maxNeurons = Infinity } = {}) {
    const d = new LfnDecoder();
    const name = file.name, meta = file.meta;
    if (meta.codec !== "lfn") throw new UnsupportedError(`${name}: codec '${meta.codec}' is not a light field network`);
    const version = meta.codec_version;
    if (!Number.isInteger(version) || version < 1) throw new FormatError(`${name}: metadata codec_version must be an integer >= 1, got ${JSON.stringify(version)}`);
    if (version > 3) throw new UnsupportedError(`${name}: lfn codec version ${version} is not supported (this reader knows 1 to 3)`);
    d.packed = version >= 3;                 // version 3: every step in one section, lfn.steps
    const conf = meta.config;
    if (!conf || typeof conf !== "object" || Array.isArray(conf)) throw new FormatError(`${name}: config is not an object`);
    const net = conf.network, where = `${name}: config.network`;
    if (!net || typeof net !== "object" || Array.isArray(net)) throw new FormatError(`${where} is not an object`);
    // version 1 named the sizes *_width; decoders read either name, and refuse one named twice (FORMAT.md)
    const pick = (a, b) => {
      if (version >= 2) return a;
      if (net[a] !== undefined && net[b] !== undefined) throw new FormatError(`${where}: network size named twice: ${b} and ${a}`);
      return net[a] !== undefined ? a : b;
    };
    const k = { min: pick("min_neurons", "min_width"), max: pick("max_neurons", "max_width"), occ: pick("occupancy_neurons", "occupancy_width") };
    d.depth = intIn(net, "depth", 1, 32, where);          // the sizes are required (FORMAT.md)
    d.minN = intIn(net, k.min, 1, 4096, where);
    d.maxN = intIn(net, k.max, d.minN, 4096, where);
    d.occN = intIn(net, k.occ, 0, 4096, where);
    intIn(net, "in_features", 6, 6, where, 6);
    intIn(net, "out_features", 4, 4, where, 4);
    d.minScale = net.min_scale === undefined ? 0.125 : net.min_scale;
    if (typeof d.minScale !== "number" || !(d.minScale > 0 && d.minScale <= 1)) throw new FormatError(`${where}: min_scale must be in (0, 1]`);
    const nrm = conf.norm || {};
    d.centre = finiteList(nrm.centre, 3, `${name}: config.norm.centre`);
    d.radius = nrm.radius;
    if (typeof d.radius !== "number" || !(d.radius >= 1e-12 && d.radius <= 1e12)) throw new FormatError(`${name}: config.norm.radius must be in [1e-12, 1e12]`);
    d.dtypeW = conf.weights === undefined ? "fp16" : conf.weights;
    if (d.dtypeW !== "fp16" && d.dtypeW !== "fp32") throw new FormatError(`${name}: config.weights must be fp16 or fp32`);
    d.itemsize = d.dtypeW === "fp16" ? 2 : 4;
    // a display ladder's shape (FORMAT.md): strictly increasing integer sizes from minN, none above maxN
    const okLadder = (l) => Array.isArray(l) && l.length >= 1 && l.length <= d.maxN - d.minN + 1 && l.every(Number.isInteger)
      && l[0] === d.minN && l[l.length - 1] <= d.maxN && l.every((w, i) => i === 0 || w > l[i - 1]);
    d.display = null;                          // the display ladder (FORMAT.md), when the file has one
    if (conf.display !== undefined) {
      const v = conf.display;
      if (!okLadder(v) || v[v.length - 1] !== d.maxN) throw new FormatError(`${name}: config.display must be increasing integer sizes from ${d.minN} to ${d.maxN}`);
      d.display = v;
    }
    d.displayScales = null;                    // ladders per display scale (FORMAT.md), when the file has them
    if (conf.display_scales !== undefined) {
      const v = conf.display_scales;
      const ok = Array.isArray(v) && v.length >= 1 && v.length <= 16 && v.every((p, i) => Array.isArray(p) && p.length === 2
        && typeof p[0] === "number" && p[0] > 0 && p[0] <= 64 && (i === 0 || p[0] > v[i - 1][0]) && okLadder(p[1]));
      if (!ok) throw new FormatError(`${name}: config.display_scales must be 1 to 16 pairs [scale, sizes], scales increasing within (0, 64], sizes increasing integers from ${d.minN} up to ${d.maxN}`);
      d.displayScales = v;
    }
    d.file = file;
    d._geometry((await file.fullMeta()).scene, name);     // version 3: the cameras are in meta.more
    const base = file.info("lfn.base");
    if (base.length !== d.valuesBase() * d.itemsize) {
      throw new FormatError(`${name}: section 'lfn.base' has ${base.length} bytes, the network config needs ${d.valuesBase() * d.itemsize}`);
    }
    d.base = floats(await file.read("lfn.base"), d.dtypeW);
    d.occ = null;
    if (d.occN && file.sections.has("lfn.occ")) {
      const n = d.occN, want = 6 * n + n + n * n + n + n + 1;
      if (file.info("lfn.occ").length !== want * d.itemsize) throw new FormatError(`${name}: section 'lfn.occ' has the wrong size for the config`);
      d.occ = floats(await file.read("lfn.occ"), d.dtypeW);
    }
    d.steps = [];
    if (d.packed && file.sections.has("lfn.steps")) {
      d.offsets = [0];
      for (let j = d.minN; j < d.maxN; j++) d.offsets.push(d.offsets[d.offsets.length - 1] + d.stepValues(j) * d.itemsize);
      const have = file.info("lfn.steps").length, want = d.offsets[d.offsets.length - 1];
      if (have !== want) throw new FormatError(`${name}: section 'lfn.steps' has ${have} bytes, the network config needs ${want}`);
    }
    await d.grow(maxNeurons);
    return d;
  }

  _geometry(g, name) {
    const where = `${name}: scene`;
    if (!g || typeof g !== "object" || Array.isArray(g)) throw new FormatError(`${where} is not an object`);
    this.rows = intIn(g, "rows", 1, 65536, where);
    this.cols = intIn(g, "cols", 1, 65536, where);
    if (this.rows * this.cols > 65536) throw new FormatError(`${where}: too many views`);
    this.H = intIn(g, "height", 1, 2 ** 26, where);
    this.W = intIn(g, "width", 1, 2 ** 26, where);
    if (this.H * this.W > 2 ** 26) throw new FormatError(`${where}: views of ${this.H}x${this.W} exceed the limit`);
    this.C = intIn(g, "channels", 1, 4, where);
    if (g.dtype !== "uint8" && g.dtype !== "uint16") throw new FormatError(`${where}: dtype must be uint8 or uint16 for an LFN`);
    this.peak = g.dtype === "uint8" ? 255 : 65535;
    this.layout = g.layout === undefined ? "grid" : g.layout;
    this.focal = finiteList(g.focal === undefined ? [1, 1] : g.focal, 2, `${where}.focal`);
    this.principal = g.principal === undefined ? [this.W / 2, this.H / 2] : finiteList(g.principal, 2, `${where}.principal`);
    const n = this.rows * this.cols;
    this.poses = new Array(n);
    if (g.c2w !== undefined) {
      const m = nested(g.c2w, [this.rows, this.cols, 4, 4], `${where}.c2w`);
      for (let v = 0; v < n; v++) this.poses[v] = m.slice(16 * v, 16 * v + 16);
    } else {
      let pos;
      if (g.positions !== undefined) {
        pos = nested(g.positions, [this.rows, this.cols, 3], `${where}.positions`);
      } else {
        const [bx, by] = finiteList(g.baseline === undefined ? [1, 1] : g.baseline, 2, `${where}.baseline`);
        if (!(Math.abs(bx) < 1e100 / Math.max(this.cols - 1, 1) && Math.abs(by) < 1e100 / Math.max(this.rows - 1, 1))) {
          throw new FormatError(`${where}.baseline times the grid size overflows the camera positions`);
        }
        pos = [];
        for (let r = 0; r < this.rows; r++) for (let c = 0; c < this.cols; c++) pos.push(c * bx, -r * by, 0);
      }
      for (let v = 0; v < n; v++) this.poses[v] = [1, 0, 0, pos[3 * v], 0, 1, 0, pos[3 * v + 1], 0, 0, 1, pos[3 * v + 2], 0, 0, 0, 1];
    }
    for (const P of this.poses) {                // FORMAT.md: usable cameras (rays finite in float32)
      const R = [[P[0], P[1], P[2]], [P[4], P[5], P[6]], [P[8], P[9], P[10]]];
      const det = R[0][0] * (R[1][1] * R[2][2] - R[1][2] * R[2][1]) - R[0][1] * (R[1][0] * R[2][2] - R[1][2] * R[2][0])
        + R[0][2] * (R[1][0] * R[2][1] - R[1][1] * R[2][0]);
      const far = [3, 7, 11].some((i, k) => Math.abs((P[i] - this.centre[k]) / this.radius) > 2 ** 20);
      if (R.flat().some((x) => Math.abs(x) > 2 ** 20) || !(Math.abs(det) >= 1e-9) || far) {
        throw new FormatError(`${where}: a captured camera is unusable (rotation beyond ±2^20 or singular, or more than 2^20 radii from the centre)`);
      }
    }
    this._pivot();
  }

  /** The scene's pivot and up (lfn_stream.cameras.scene_pivot). */
  _pivot() {
    const A = [[0, 0, 0], [0, 0, 0], [0, 0, 0]], b = [0, 0, 0], up = [0, 0, 0];
    for (const P of this.poses) {
      let d = col(P, 2).map((x) => -x);
      const l = norm3(d);
      d = d.map((x) => x / l);
      const o = [P[3], P[7], P[11]], dot = d[0] * o[0] + d[1] * o[1] + d[2] * o[2];
      for (let i = 0; i < 3; i++) {
        for (let j = 0; j < 3; j++) A[i][j] += (i === j ? 1 : 0) - d[i] * d[j];
        b[i] += o[i] - d[i] * dot;
        up[i] += P[4 * i + 1];
      }
    }
    const [lo, hi] = symEigMinMax(A);
    this.pivot = lo > 1e-3 * Math.max(hi, 1e-12) ? solve3(A, b) : this.centre.slice();
    const u = norm3(up);
    this.up = u > 1e-9 ? up.map((x) => x / u) : [0, 1, 0];
  }

  valuesBase() {
    const m = this.minN;
    return m * 6 + 3 * m + (this.depth - 1) * (m * m + 3 * m) + 4 * m + 4;
  }

  stepValues(j) { return 6 + 3 + (this.depth - 1) * (2 * j + 1 + 3) + 4; }

  /** The size to show from the steps held: the largest size they reach of the ladder measured at
   *  the display scale nearest `scale` (config.display_scales; nearest in ratio), else of
   *  config.display (every held neuron without a ladder), so the picture does not get worse as
   *  bytes arrive. As LfnRenderer.display_neurons_at. */
  displayNeurons(scale = null) {
    let ladder = this.display;
    if (scale !== null && scale !== undefined && this.displayScales) {
      const dist = (p) => Math.abs(Math.log(p[0] / scale));
      ladder = this.displayScales.reduce((a, b) => (dist(b) < dist(a) ? b : a))[1];
    }
    return ladder ? Math.max(...ladder.filter((w) => w <= this.neurons)) : this.neurons;
  }

  /** Network size a level stands for (0 = the largest available network). */
  neuronsAt(level) { return this.neurons - level; }

  /** Image scale a (fractional) neuron count stands for (log-linear from min_scale to 1). */
  scaleOf(neurons) {
    if (this.maxN === this.minN) return 1;
    const t = Math.min(Math.max((neurons - this.minN) / (this.maxN - this.minN), 0), 1);
    return Math.exp(Math.log(this.minScale) * (1 - t));
  }

  /** Fetch the step sections up to a network of `maxNeurons` (as far as the file goes) and
   *  rebuild the weights; returns the neurons now available. */
  async grow(maxNeurons = Infinity) {
    const limit = Math.min(Math.ceil(maxNeurons), this.maxN);
    const before = this.steps.length;
    const f = this.file, names = [];
    if (this.packed) {                        // one range of lfn.steps (one request for its missing chunks)
      const k0 = this.steps.length, k1 = f.sections.has("lfn.steps") ? Math.max(limit - this.minN, k0) : k0;
      if (k1 > k0) {
        const data = await f.read("lfn.steps", this.offsets[k0], this.offsets[k1]);
        for (let k = k0; k < k1; k++) {
          this.steps.push(floats(data.slice(this.offsets[k] - this.offsets[k0], this.offsets[k + 1] - this.offsets[k0]), this.dtypeW));
        }
      }
      if (this.steps.length !== before || !this.Wt) this._build();
      return this.neurons;
    }
    for (let j = this.steps.length; this.minN + j < limit && f.sections.has(stepName(j)); j++) names.push(stepName(j));
    await f.prefetch(names);                  // one range request for all the steps this level needs
    for (let j = this.steps.length; this.minN + j < limit; j++) {
      const sname = stepName(j);
      if (!f.sections.has(sname)) break;
      const want = this.stepValues(this.minN + j) * this.itemsize;
      if (f.info(sname).length !== want) throw new FormatError(`${f.name}: section '${sname}' has ${f.info(sname).length} bytes, the network config needs ${want}`);
      this.steps.push(floats(await f.read(sname), this.dtypeW));
    }
    if (this.steps.length !== before || !this.Wt) this._build();
    return this.neurons;
  }

  _build() {
    const m = this.minN, D = this.depth, w = m + this.steps.length;
    const values = 6 * w + (D - 1) * w * w + (3 * D + 4) * w + 4 + (this.occ ? this.occ.length : 0);
    if (values > MAX_NETWORK_VALUES) throw new UnsupportedError(`${this.file.name}: a network of ${w} neurons x ${D} layers is too large for the browser viewer`);
    const Wt = [], b = [], g = [], be = [];
    for (let i = 0; i < D; i++) {
      Wt.push(new Float64Array(w * (i === 0 ? 6 : w)));
      b.push(new Float64Array(w)); g.push(new Float64Array(w)); be.push(new Float64Array(w));
    }
    const ow = new Float64Array(4 * w), ob = new Float64Array(4);
    let vals = this.base, pos = 0;
    const take = () => {
      if (pos >= vals.length) throw new FormatError("lfn network section is shorter than its configuration needs");
      return vals[pos++];
    };
    for (let i = 0; i < D; i++) {
      const k = i === 0 ? 6 : m, stride = i === 0 ? 6 : w;
      for (let r = 0; r < m; r++) for (let c = 0; c < k; c++) Wt[i][r * stride + c] = take();
      for (let r = 0; r < m; r++) b[i][r] = take();
      for (let r = 0; r < m; r++) g[i][r] = take();
      for (let r = 0; r < m; r++) be[i][r] = take();
    }
    for (let o = 0; o < 4; o++) for (let c = 0; c < m; c++) ow[o * w + c] = take();
    for (let o = 0; o < 4; o++) ob[o] = take();
    if (pos !== vals.length) throw new FormatError("lfn.base has trailing data");
    this.steps.forEach((sv, s) => {
      const j = m + s;
      vals = sv; pos = 0;
      for (let c = 0; c < 6; c++) Wt[0][j * 6 + c] = take();
      b[0][j] = take(); g[0][j] = take(); be[0][j] = take();
      for (let i = 1; i < D; i++) {
        for (let c = 0; c <= j; c++) Wt[i][j * w + c] = take();
        for (let r = 0; r < j; r++) Wt[i][r * w + j] = take();
        b[i][j] = take(); g[i][j] = take(); be[i][j] = take();
      }
      for (let o = 0; o < 4; o++) ow[o * w + j] = take();
      if (pos !== vals.length) throw new FormatError(`${stepName(s)} has ${vals.length} values, expected ${pos}`);
    });
    Object.assign(this, { Wt, b, g, be, ow, ob, w, neurons: w, levels: w - m });
  }

  /** Bytes of network weights held (as stored in the file). */
  weightBytes() {
    return this.steps.reduce((a, x) => a + x.length, this.base.length + (this.occ ? this.occ.length : 0)) * this.itemsize;
  }

  /** 4×4 pose (row-major) of captured view v. */
  pose(v) { return this.poses[v].slice(); }

  /** Pose at continuous grid position (s, t) (lfn_stream.cameras.grid_pose). */
  gridPose(s, t) {
    const R = this.rows, C = this.cols;
    if (!(s >= 0 && s <= R - 1 && t >= 0 && t <= C - 1)) throw new LfcError(`grid position (${s}, ${t}) is outside the ${R}x${C} grid`);
    const r0 = Math.min(Math.floor(s), R - 1), c0 = Math.min(Math.floor(t), C - 1);
    const r1 = Math.min(r0 + 1, R - 1), c1 = Math.min(c0 + 1, C - 1), a = s - r0, bb = t - c0;
    const P = (r, c) => this.poses[r * C + c];
    const out = P(Math.floor(s + 0.5), Math.floor(t + 0.5)).slice();
    for (const i of [3, 7, 11]) {
      out[i] = (1 - a) * (1 - bb) * P(r0, c0)[i] + (1 - a) * bb * P(r0, c1)[i] + a * (1 - bb) * P(r1, c0)[i] + a * bb * P(r1, c1)[i];
    }
    return out;
  }

  /** View v turned about the pivot: pitch degrees about its right axis, then yaw about up
   *  (lfn_stream.cameras.orbit_pose). */
  orbitPose(v, yaw, pitch = 0) {
    const P = this.poses[v], right = col(P, 0), l = norm3(right);
    const M = mul3(rotation(this.up, yaw), rotation(right.map((x) => x / l), pitch));
    const R0 = [[P[0], P[1], P[2]], [P[4], P[5], P[6]], [P[8], P[9], P[10]]];
    const R = mul3(M, R0);
    const rel = [P[3] - this.pivot[0], P[7] - this.pivot[1], P[11] - this.pivot[2]];
    const o = mv3(M, rel).map((x, i) => x + this.pivot[i]);
    return [R[0][0], R[0][1], R[0][2], o[0], R[1][0], R[1][1], R[1][2], o[1], R[2][0], R[2][1], R[2][2], o[2], 0, 0, 0, 1];
  }

  /** The scale of the views the full network was trained at, as the display ladders state it
   *  (the largest display scale, at most 1); 1 without them. As LfnRenderer.native_scale. */
  get nativeScale() {
    return this.displayScales ? Math.min(1, this.displayScales[this.displayScales.length - 1][0]) : 1;
  }

  /** Pixels between network samples of a native render of `neurons` at `scale`: the largest power
   *  of two up to 8 within how much finer the frame is than the network's own scale. As
   *  LfnRenderer.native_stride. */
  nativeStride(neurons, scale) {
    const over = scale / (this.nativeScale * this.scaleOf(neurons));
    return over > 0 ? 2 ** Math.min(3, Math.max(0, Math.floor(Math.log2(over) + 1e-9))) : 1;
  }

  /** Per-pixel network sizes of an h×w frame around a gaze (x, y in pixels of the frame): the
   *  full held network within inner·diagonal, falling linearly to the base network at
   *  outer·diagonal (LfnRenderer.foveation_map(gaze, dither=False)). Float64Array h·w. */
  foveationMap(gaze, h, w, inner = 0.1, outer = 0.5) {
    if (!(gaze && gaze.length === 2 && Number.isFinite(gaze[0]) && Number.isFinite(gaze[1]))) {
      throw new LfcError(`gaze must be a finite (x, y) in pixels, got ${JSON.stringify(gaze)}`);
    }
    if (!(Number.isFinite(inner) && Number.isFinite(outer) && inner >= 0 && inner <= outer)) {
      throw new LfcError(`inner and outer must be finite with 0 <= inner <= outer, got ${inner}, ${outer}`);
    }
    const lo = this.minN, hi = this.neurons, diag = Math.hypot(h, w), span = Math.max(outer - inner, 1e-9);
    const lod = new Float64Array(h * w);
    for (let y = 0, i = 0; y < h; y++) {
      for (let x = 0; x < w; x++, i++) {
        const e = Math.hypot(x + 0.5 - gaze[0], y + 0.5 - gaze[1]) / diag;
        const t = Math.min(Math.max((e - inner) / span, 0), 1);
        lod[i] = Math.min(Math.max(hi - t * (hi - lo), lo), hi);
      }
    }
    return lod;
  }

  /** Mip levels (octaves of image scale) per neuron: scaleOf is log-linear from minScale at the
   *  base network to 1 at the full one (0 if one size). As LfnRenderer._levels_per_neuron. */
  _levelsPerNeuron() {
    const span = this.maxN - this.minN;
    return span ? Math.log2(1 / this.minScale) / span : 0;
  }

  /** The integer size a mip level's lattice runs (LfnRenderer.mip_neurons). */
  mipNeurons(level) {
    const lo = this.minN, hi = this.neurons, per = this._levelsPerNeuron();
    if (!per || level <= 0) return hi;
    return Math.min(hi, Math.max(lo, Math.ceil(hi - Math.max(level - MIP_SHARPEN, 0) / per - 1e-9)));
  }

  /** A foveated frame: pixel i at the (fractional) size lod[i] (Float64Array h·w, e.g.
   *  foveationMap), drawn as a texture's mip chain is drawn (LfnRenderer.render_pose_lod_mip):
   *  level j is a lattice every 2^j pixels run at mipNeurons(j) only where some pixel reads it,
   *  each pixel blends the two levels around its own over the middle `blend` of the interval;
   *  the fovea is exactly render()'s pixels. `native`: every lattice as many octaves sparser as
   *  the frame is finer than the network (the fovea render(..., {native: true})'s pixels).
   *  Returns {rgba, h, w, evaluated, levels}. */
  renderMip(pose, lod, scale = 1, opts = {}) {
    const plan = this._mipPlan(pose, lod, scale, opts);
    return plan.finish(plan.jobs.map((job) => {
      const inside = this.occ ? this._occupiedAll(job.rays, job.n, job.ws) : null, out = new Float64Array(job.n * 4);
      return { out, evaluated: this._forwardRays(job.ws, job.rays, job.n, job.run(inside), out), inside };
    }));
  }

  /** renderMip() with the network passes shared among a ForwardPool's workers, every level's at
   *  once (the same pixels: each level's rays do not depend on another's). */
  async renderMipAsync(pose, lod, scale = 1, { pool = null, ...opts } = {}) {
    if (!pool) return this.renderMip(pose, lod, scale, opts);
    const { jobs, finish } = this._mipPlan(pose, lod, scale, opts);
    const insides = await Promise.all(jobs.map((job) => (this.occ ? pool.occupancy(this, job.rays, job.n) : null)));
    const got = await Promise.all(jobs.map((job, i) => pool.forward(this, job.neurons, job.rays, job.n, job.run(insides[i]))));
    return finish(got.map((g, i) => ({ ...g, inside: insides[i] })));
  }

  /** The mip render's levels as _jobs (each with its `neurons`), and finish(results) → the frame
   *  from each job's {out, evaluated, inside}. */
  _mipPlan(pose, lod, scale, { maxLevel = MIP_LEVELS, blend = MIP_BLEND, bias = 0, native = false } = {}) {
    if (!Number.isInteger(maxLevel) || maxLevel < 0 || maxLevel > 8) throw new LfcError(`maxLevel must be an integer in 0..8, got ${maxLevel}`);
    if (!(blend >= 0 && blend <= 1 && bias >= -8 && bias <= 8)) throw new LfcError(`blend must be within [0, 1] and bias within [-8, 8], got ${blend}, ${bias}`);
    if (!(scale > 0 && scale <= 64)) throw new LfcError(`scale must be within (0, 64], got ${scale}`);
    const H = this.H, W = this.W, h = Math.max(1, Math.round(H * scale)), w = Math.max(1, Math.round(W * scale)), n = h * w;
    if (!lod || lod.length !== n || !lod.every(Number.isFinite)) throw new LfcError(`lod must hold ${n} finite sizes (a ${h}x${w} frame)`);
    const lo = this.minN, hi = this.neurons, per = this._levelsPerNeuron(), cap = Math.min(maxLevel, (hi - lo) * per);
    const shift = native ? Math.round(Math.log2(this.nativeStride(hi, scale))) : 0;
    const lower = new Int8Array(n), wlo = new Float32Array(n), wup = new Float32Array(n);
    let top = 0;
    for (let i = 0; i < n; i++) {                  // as mip_levels, then the pixel's two levels' shares
      const m0 = Math.min(Math.max((hi - Math.min(Math.max(lod[i], lo), hi)) * per, 0), cap);
      const m = Math.min(Math.max(m0 + (MIP_OFFSET + bias), 0), maxLevel) + shift;
      const l = Math.floor(m), f = m - l;
      const up = blend > 0 ? Math.min(Math.max((f - 0.5) / blend + 0.5, 0), 1) : (f >= 0.5 ? 1 : 0);
      lower[i] = l; wlo[i] = 1 - up; wup[i] = up;
      if (l > top) top = l;
    }
    const jobs = [], adds = [];                    // per level: its job, and how its results add into the frame
    for (let j = 0; j <= top + 1; j++) {
      const wt = new Float32Array(n), used = new Uint8Array(n);
      let m = 0;
      for (let i = 0; i < n; i++) {
        wt[i] = lower[i] === j ? wlo[i] : lower[i] === j - 1 ? wup[i] : 0;
        m += used[i] = wt[i] > 0 ? 1 : 0;
      }
      if (!m) continue;
      if (j === 0) {                               // every used pixel, with the occupancy net: render()'s pixels
        const neurons = this.mipNeurons(0), at = new Int32Array(m);
        for (let i = 0, q = 0; i < n; i++) if (used[i]) at[q++] = i;
        jobs.push({ ws: this._workspace(neurons), neurons, rays: this._raysAt(pose, w, h / H, w / W, at), n: m,
          run: (inside) => inside });
        adds.push((rgba, got) => {
          for (let q = 0; q < m; q++) for (let c = 0; c < 4; c++) rgba[4 * at[q] + c] += wt[at[q]] * got.out[4 * q + c];
        });
        continue;
      }
      const neurons = this.mipNeurons(j - shift), job = this._latticeJob(pose, this._workspace(neurons), h, w, 1 << j, used);
      jobs.push(Object.assign(job, { neurons }));
      adds.push((rgba, got) => job.finish(got.out, got.evaluated, got.inside, rgba, wt));   // adds wt × the level's pixels
    }
    const finish = (results) => {
      const rgba = new Float64Array(n * 4);
      results.forEach((got, i) => adds[i](rgba, got));
      return { rgba, h, w, evaluated: results.reduce((a, g) => a + g.evaluated, 0), levels: jobs.length, stride: 1 << shift };
    };
    return { jobs, finish };
  }

  /** Render a camera pose at (fractional) `neurons` and image `scale` (default: the size's own).
   *  `native`: a network trained at reduced resolution runs on a lattice every nativeStride()
   *  pixels, upsampled bilinearly, the silhouette cut per pixel (LfnRenderer.render_pose(...,
   *  native=True); a quarter of the network passes at stride 2).
   *  Returns {rgba: Float64Array h·w·4 premultiplied in [0, 1], h, w, evaluated: rays run, stride}. */
  render(pose, neurons = this.neurons, scale = null, { native = false } = {}) {
    const job = this._job(pose, neurons, scale, native);
    const inside = this.occ ? this._occupiedAll(job.rays, job.n, job.ws) : null;
    const out = new Float64Array(job.n * 4);
    return job.finish(out, this._forwardRays(job.ws, job.rays, job.n, job.run(inside), out), inside);
  }

  /** render() with the network passes (and the occupancy net's) shared among a ForwardPool's
   *  workers (lfn_pool.js; the same pixels: each ray's arithmetic does not depend on the rays
   *  beside it); without a pool, render(). */
  async renderAsync(pose, neurons = this.neurons, scale = null, { native = false, pool = null } = {}) {
    if (!pool) return this.render(pose, neurons, scale, { native });
    const job = this._job(pose, neurons, scale, native);
    const inside = this.occ ? await pool.occupancy(this, job.rays, job.n) : null;
    const { out, evaluated } = await pool.forward(this, neurons, job.rays, job.n, job.run(inside));
    return job.finish(out, evaluated, inside);
  }

  /** What a frame asks of the networks: {ws, rays (n·6), n, run(inside) → the rays the network
   *  runs given the occupancy net's answers (null: all), finish(out, evaluated, inside) → the
   *  frame}, the network's outputs for ray i at out[4i..4i+3]. */
  _job(pose, neurons, scale, native) {
    if (!(neurons >= this.minN && neurons <= this.neurons)) {
      throw new LfcError(`${neurons} neurons outside the available range [${this.minN}, ${this.neurons}]`);
    }
    if (scale === null) scale = this.scaleOf(neurons);
    const H = this.H, W = this.W;
    const h = Math.max(1, Math.round(H * scale)), w = Math.max(1, Math.round(W * scale));
    const k = native ? this.nativeStride(neurons, scale) : 1;
    const ws = this._workspace(neurons);
    if (k > 1) return this._latticeJob(pose, ws, h, w, k);
    return { ws, rays: this._rays(pose, h, w, h / H, w / W), n: h * w, run: (inside) => inside,
      finish: (rgba, evaluated) => ({ rgba, h, w, evaluated, stride: 1 }) };
  }

  /** Plücker rays (float32, as the Python renderer's) through the pixel centres of an h×w grid at
   *  `sy`, `sx` grid pixels per view pixel: Float32Array n·6 (ray i at 6i). */
  _rays(pose, h, w, sy, sx) {
    const ray = this._rayMaker(pose, sy, sx), out = new Float32Array(h * w * 6);
    for (let yy = 0, i = 0; yy < h; yy++) for (let xx = 0; xx < w; xx++, i += 6) ray(yy, xx, out, i);
    return out;
  }

  /** The rays of grid pixels `at` (flat indices into a grid `w` wide): Float32Array at.length·6. */
  _raysAt(pose, w, sy, sx, at) {
    const ray = this._rayMaker(pose, sy, sx), out = new Float32Array(at.length * 6);
    for (let q = 0; q < at.length; q++) ray(Math.floor(at[q] / w), at[q] % w, out, 6 * q);
    return out;
  }

  /** (y, x, out, i) → the ray of grid pixel (y, x) written to out[i..i+5] (lfn_stream.rays.camera_rays). */
  _rayMaker(pose, sy, sx) {
    const fx = this.focal[0] * sx, fy = this.focal[1] * sy, cx = this.principal[0] * sx, cy = this.principal[1] * sy;
    const o = [0, 1, 2].map((i) => (pose[4 * i + 3] - this.centre[i]) / this.radius);
    const f32 = Math.fround;
    return (yy, xx, out, i) => {
      const u = (xx + 0.5 - cx) / fx, v = -(yy + 0.5 - cy) / fy;
      let d0 = u * pose[0] + v * pose[1] - pose[2], d1 = u * pose[4] + v * pose[5] - pose[6], d2 = u * pose[8] + v * pose[9] - pose[10];
      const l = Math.sqrt(d0 * d0 + d1 * d1 + d2 * d2);
      d0 /= l; d1 /= l; d2 /= l;
      out[i] = f32(d0); out[i + 1] = f32(d1); out[i + 2] = f32(d2);
      out[i + 3] = f32(o[1] * d2 - o[2] * d1); out[i + 4] = f32(o[2] * d0 - o[0] * d2); out[i + 5] = f32(o[0] * d1 - o[1] * d0);
    };
  }

  /** Uint8Array n: 1 where the occupancy net lets ray i through (on the WebAssembly kernel in
   *  batches where there is one: the same doubles as _occupied). */
  _occupiedAll(rays, n, ws) {
    const inside = new Uint8Array(n), kern = ws.kern;
    if (!kern || !kern.occP) {
      for (let i = 0; i < n; i++) inside[i] = this._occupied(rays.subarray(6 * i, 6 * i + 6), ws) ? 1 : 0;
      return inside;
    }
    const X = kern.X;
    for (let a = 0; a < n; a += RB) {
      const cnt = Math.min(RB, n - a), R4 = (cnt + 3) & ~3;
      for (let r = 0; r < R4; r++) for (let q = 0; q < 6; q++) X[q * RB + r] = r < cnt ? rays[6 * (a + r) + q] : 0;
      const s = kern.occupancy(R4);
      for (let r = 0; r < cnt; r++) inside[a + r] = 1 / (1 + Math.exp(-s[r])) > 0.1 ? 1 : 0;
    }
    return inside;
  }

  /** Rays i < n with run[i] set (all when run is null) through the network into rgba (4i..4i+3);
   *  returns how many ran. */
  _forwardRays(ws, rays, n, run, rgba) {
    const RB = ws.RB, X = ws.X;
    let evaluated = 0, cnt = 0;
    const flush = () => {
      this._forwardBatch(ws, cnt);
      for (let r = 0; r < cnt; r++) {
        const p = 4 * ws.pix[r];
        for (let c = 0; c < 4; c++) rgba[p + c] = ws.out[c * RB + r];
      }
      evaluated += cnt;
      cnt = 0;
    };
    for (let i = 0; i < n; i++) {
      if (run && !run[i]) continue;
      for (let q = 0; q < 6; q++) X[q * RB + cnt] = rays[6 * i + q];
      ws.pix[cnt++] = i;
      if (cnt === RB) flush();
    }
    if (cnt) flush();
    return evaluated;
  }

  /** The native render of an h×w frame from a lattice every k pixels (LfnRenderer._lattice with
   *  every pixel used, or only where `used` (Uint8Array h·w) is set: then only the lattice points
   *  those pixels' bilinear taps read), as a _job: the occupancy net at those lattice points, the
   *  network at the ones within one of an occupied one; finish() resizes as OpenCV does (pixel y
   *  reads the lattice at (y + 0.5)/k − 0.5, clamped), then keeps each pixel where all its taps
   *  are occupied, cuts it where none is, and asks the occupancy net at its own ray where they
   *  are mixed. */
  _latticeJob(pose, ws, h, w, k, used = null) {
    const hj = Math.ceil(h / k), wj = Math.ceil(w / k);
    let cand = null;                               // the lattice points run (null: all)
    if (used) {
      const block = new Uint8Array(hj * wj);
      for (let y = 0; y < h; y++) for (let x = 0; x < w; x++) if (used[y * w + x]) block[((y / k) | 0) * wj + ((x / k) | 0)] = 1;
      const need = dilate3(block, hj, wj);
      let m = 0;
      for (let i = 0; i < need.length; i++) m += need[i];
      cand = new Int32Array(m);
      for (let i = 0, j = 0; i < need.length; i++) if (need[i]) cand[j++] = i;
    }
    const grid = (vals, per) => {                  // per-candidate values → the whole lattice (0 elsewhere)
      if (!cand) return vals;
      const g = new (vals.constructor)(hj * wj * per);
      for (let q = 0; q < cand.length; q++) for (let c = 0; c < per; c++) g[per * cand[q] + c] = vals[per * q + c];
      return g;
    };
    const run = (inside) => {
      if (!inside) return null;
      const near = dilate3(grid(inside, 1), hj, wj);
      if (!cand) return near;
      const out = new Uint8Array(cand.length);
      for (let q = 0; q < cand.length; q++) out[q] = near[cand[q]];
      return out;
    };
    const sy = h / (this.H * k), sx = w / (this.W * k);
    return { ws, rays: cand ? this._raysAt(pose, wj, sy, sx, cand) : this._rays(pose, hj, wj, sy, sx),
      n: cand ? cand.length : hj * wj, run,
      finish: (lat, evaluated, inside, into = null, weight = null) => this._upsample(pose, ws, grid(lat, 4),
        inside && grid(inside, 1), hj, wj, h, w, k, evaluated, used, into, weight) };
  }

  /** The h×w frame from the hj×wj lattice's outputs `lat` (and occupancy `inside`, or null), at
   *  the pixels `used` marks (null: all; the others 0); with `into` (Float64Array h·w·4), each
   *  pixel's value times weight[pixel] is added there instead. */
  _upsample(pose, ws, lat, inside, hj, wj, h, w, k, evaluated, used = null, into = null, weight = null) {
    const taps = (m, size) => {                    // per output coordinate: lower tap and weight
      const i0 = new Int32Array(m), wt = new Float64Array(m);
      for (let y = 0; y < m; y++) {
        const f = (y + 0.5) / k - 0.5;
        let s = Math.floor(f), a = f - s;
        if (s < 0) { s = 0; a = 0; }
        if (s >= size - 1) { s = size - 1; a = 0; }
        i0[y] = s; wt[y] = a;
      }
      return [i0, wt];
    };
    const [ty, ay] = taps(h, hj), [tx, ax] = taps(w, wj);
    const rgba = into || new Float64Array(h * w * 4);
    const put = (y, x) => {                        // pixel (y, x) from its four taps
      const r0 = ty[y] * wj, r1 = Math.min(ty[y] + 1, hj - 1) * wj, b = ay[y];
      const c0 = tx[x], c1 = Math.min(tx[x] + 1, wj - 1), a = ax[x];
      const w00 = (1 - b) * (1 - a), w01 = (1 - b) * a, w10 = b * (1 - a), w11 = b * a;
      const p = 4 * (y * w + x), q00 = 4 * (r0 + c0), q01 = 4 * (r0 + c1), q10 = 4 * (r1 + c0), q11 = 4 * (r1 + c1);
      if (into) {
        const s = weight[y * w + x];
        for (let c = 0; c < 4; c++) rgba[p + c] += s * (w00 * lat[q00 + c] + w01 * lat[q01 + c] + w10 * lat[q10 + c] + w11 * lat[q11 + c]);
      } else {
        for (let c = 0; c < 4; c++) rgba[p + c] = w00 * lat[q00 + c] + w01 * lat[q01 + c] + w10 * lat[q10 + c] + w11 * lat[q11 + c];
      }
    };
    const mixed = [];                              // pixels whose taps are partly occupied
    for (let y = 0; y < h; y++) {
      const r0 = ty[y] * wj, r1 = Math.min(ty[y] + 1, hj - 1) * wj, b = ay[y];
      for (let x = 0; x < w; x++) {
        if (used && !used[y * w + x]) continue;
        if (inside) {
          const c0 = tx[x], c1 = Math.min(tx[x] + 1, wj - 1), a = ax[x];
          const frac = (1 - b) * (1 - a) * inside[r0 + c0] + (1 - b) * a * inside[r0 + c1] + b * (1 - a) * inside[r1 + c0]
            + b * a * inside[r1 + c1];
          if (!(frac > 1 - 1e-4)) {
            if (frac > 1e-4) mixed.push(y * w + x);   // (none occupied: empty)
            continue;
          }
        }
        put(y, x);
      }
    }
    if (mixed.length) {                            // the occupancy net at those pixels' own rays (the dense render's), in batches
      const at = Int32Array.from(mixed), ins = this._occupiedAll(this._raysAt(pose, w, h / this.H, w / this.W, at), at.length, ws);
      for (let q = 0; q < at.length; q++) if (ins[q]) put(Math.floor(at[q] / w), at[q] % w);
    }
    return { rgba, h, w, evaluated, stride: k, asked: mixed.length };
  }

  _workspace(neurons) {
    const n0 = Math.floor(neurons + 1e-9), a = neurons - n0;
    const n = a > 1e-6 ? n0 + 1 : n0, m = new Float64Array(n).fill(1);
    if (a > 1e-6) m[n - 1] = a;
    let msum = 0;
    for (let i = 0; i < n; i++) msum += m[i];
    const kern = this._kernel(), big = Math.max(n, 6) * RB;
    // the activations: in the kernel's memory where there is one
    const { X, z, h, h2 } = kern || { X: new Float64Array(6 * RB), z: new Float64Array(n * RB), h: new Float64Array(big),
      h2: new Float64Array(big) };
    return { n, m, msum, RB, kern, X, z, h, h2, out: new Float64Array(4 * RB), pix: new Int32Array(RB),
      o1: new Float64Array(this.occN), o2: new Float64Array(this.occN) };
  }

  /** The DenseKernel of the weights held (rebuilt when the network grows); null without
   *  WebAssembly SIMD or with LfnDecoder.useWasm false. */
  _kernel() {
    if (!LfnDecoder.useWasm || !this.Wt) return null;
    if (!this._kern || this._kern.Wt !== this.Wt) {
      const mod = kernelModule();
      this._kern = { Wt: this.Wt, k: mod ? new DenseKernel(mod, this.Wt, this.b, this.g, this.be, this.w, this.ow, this.ob, this.occ, this.occN) : null };
    }
    return this._kern.k;
  }

  /** The occupancy net lets ray x through: sigmoid(logit) > 0.1. */
  _occupied(x, ws) { return 1 / (1 + Math.exp(-this._occupancyLogit(x, ws))) > 0.1; }

  /** The occupancy net's logit of ray x (Linear 6→k, ReLU, k→k, ReLU, k→1; each sum from its bias). */
  _occupancyLogit(x, ws) {
    const k = this.occN, P = this.occ, h1 = ws.o1, h2 = ws.o2;
    const b1 = 6 * k, W2 = b1 + k, b2 = W2 + k * k, W3 = b2 + k, b3 = W3 + k;
    for (let j = 0; j < k; j++) {
      let s = P[b1 + j];
      for (let q = 0; q < 6; q++) s += P[j * 6 + q] * x[q];
      h1[j] = s > 0 ? s : 0;
    }
    for (let j = 0; j < k; j++) {
      let s = P[b2 + j];
      for (let q = 0; q < k; q++) s += P[W2 + j * k + q] * h1[q];
      h2[j] = s > 0 ? s : 0;
    }
    let s = P[b3];
    for (let q = 0; q < k; q++) s += P[W3 + q] * h2[q];
    return s;
  }

  /** `cnt` rays (ws.X, feature q of ray r at q·RB + r) through the nested network at the
   *  workspace's (fractional) size → ws.out (channel c of ray r at c·RB + r). Matrix products on
   *  the WebAssembly kernel (ws.kern), else in 2-neuron × 4-ray register blocks (about 3× a
   *  ray-at-a-time loop in V8; the kernel is ~4.5× these loops, the same doubles). */
  _forwardBatch(ws, cnt) {
    const { n, m, msum, z, kern } = ws, w = this.w, R4 = (cnt + 3) & ~3;
    let hin = ws.X, hout = ws.h, k = 6;
    for (let r = cnt; r < R4; r++) for (let q = 0; q < 6; q++) hin[q * RB + r] = 0;     // padding rays
    for (let i = 0; i < this.depth; i++) {
      const Wi = this.Wt[i], stride = i === 0 ? 6 : w, bi = this.b[i], gi = this.g[i], bei = this.be[i];
      if (kern) kern.layer(i, hin, z, k, n, R4);
      else for (let r = 0; r < R4; r += 4) {
        let j = 0;
        for (; j + 1 < n; j += 2) {
          const ra = j * stride, rb = ra + stride;
          let a0 = 0, a1 = 0, a2 = 0, a3 = 0, b0 = 0, b1 = 0, b2 = 0, b3 = 0;
          for (let q = 0; q < k; q++) {
            const wa = Wi[ra + q], wb = Wi[rb + q], o = q * RB + r;
            const x0 = hin[o], x1 = hin[o + 1], x2 = hin[o + 2], x3 = hin[o + 3];
            a0 += wa * x0; a1 += wa * x1; a2 += wa * x2; a3 += wa * x3;
            b0 += wb * x0; b1 += wb * x1; b2 += wb * x2; b3 += wb * x3;
          }
          const za = j * RB + r, zb = za + RB, ba = bi[j], bb = bi[j + 1];
          z[za] = a0 + ba; z[za + 1] = a1 + ba; z[za + 2] = a2 + ba; z[za + 3] = a3 + ba;
          z[zb] = b0 + bb; z[zb + 1] = b1 + bb; z[zb + 2] = b2 + bb; z[zb + 3] = b3 + bb;
        }
        if (j < n) {
          const ra = j * stride;
          let a0 = 0, a1 = 0, a2 = 0, a3 = 0;
          for (let q = 0; q < k; q++) {
            const wa = Wi[ra + q], o = q * RB + r;
            a0 += wa * hin[o]; a1 += wa * hin[o + 1]; a2 += wa * hin[o + 2]; a3 += wa * hin[o + 3];
          }
          const za = j * RB + r, ba = bi[j];
          z[za] = a0 + ba; z[za + 1] = a1 + ba; z[za + 2] = a2 + ba; z[za + 3] = a3 + ba;
        }
      }
      if (kern) kern.layerNorm(i, z, hout, m, n, R4, msum);
      else for (let r = 0; r < R4; r++) {       // LayerNorm with the neuron weights, ReLU, mask
        let mean = 0;
        for (let j = 0; j < n; j++) mean += z[j * RB + r] * m[j];
        mean /= msum;
        let vr = 0;
        for (let j = 0; j < n; j++) { const e = z[j * RB + r] - mean; vr += e * e * m[j]; }
        const inv = 1 / Math.sqrt(vr / msum + 1e-5);
        for (let j = 0; j < n; j++) {
          const y = (z[j * RB + r] - mean) * inv * gi[j] + bei[j];
          hout[j * RB + r] = (y > 0 ? y : 0) * m[j];
        }
      }
      if (i === 0) { hin = hout; hout = ws.h2; } else { const t = hin; hin = hout; hout = t; }
      k = n;
    }
    if (kern) {
      const o = kern.outputs(hin, n, R4);
      for (let c = 0; c < 4; c++) for (let r = 0; r < cnt; r++) ws.out[c * RB + r] = 1 / (1 + Math.exp(-o[c * RB + r]));
      return;
    }
    for (let c = 0; c < 4; c++) {
      const oc = c * w, bc = this.ob[c];
      for (let r = 0; r < cnt; r++) {
        let s = bc;
        for (let j = 0; j < n; j++) s += this.ow[oc + j] * hin[j * RB + r];
        ws.out[c * RB + r] = 1 / (1 + Math.exp(-s));
      }
    }
  }

  /** Premultiplied RGBA → the file's pixels (H·W·C, Uint8Array/Uint16Array), as LfnRenderer.to_pixels. */
  toPixels(rgba, h, w) {
    const C = this.C, peak = this.peak;
    const out = peak > 255 ? new Uint16Array(h * w * C) : new Uint8Array(h * w * C);
    const q = (v) => {
      const x = Math.min(Math.max(v, 0), 1) * peak, f = Math.floor(x), r = x - f;
      return r > 0.5 ? f + 1 : r < 0.5 ? f : (f % 2 === 0 ? f : f + 1);       // rint: half to even
    };
    const c01 = (v) => Math.min(Math.max(v, 0), 1);
    for (let i = 0; i < h * w; i++) {
      const p = 4 * i, a0 = c01(rgba[p]), a1 = c01(rgba[p + 1]), a2 = c01(rgba[p + 2]), al = c01(rgba[p + 3]);
      const un = (v) => (al >= 2 ** -20 ? v / al : 0);                // FORMAT.md: colour 0 below α = 2^-20
      if (C === 4) { out[4 * i] = q(un(a0)); out[4 * i + 1] = q(un(a1)); out[4 * i + 2] = q(un(a2)); out[4 * i + 3] = q(al); }
      else if (C === 2) { out[2 * i] = q(un(a0)); out[2 * i + 1] = q(al); }
      else if (C === 1) out[i] = q(a0);
      else { out[3 * i] = q(a0); out[3 * i + 1] = q(a1); out[3 * i + 2] = q(a2); }
    }
    return out;
  }
}
