// tiles.js — LFN tile sets in the browser (docs/FORMAT.md "Tile sets of LFN files";
// lfn_stream/tiles.py in Python): a JSON manifest names K ordinary LFN .lfc files, each trained
// on one region of camera space. TiledLfn opens the manifest, opens a tile's file (by byte
// ranges) only when a camera first needs it, and renders a camera as the blend of the tiles
// around it: Σ w_k · RGBA_k (premultiplied), w_k ∝ max(0, (1 + band)·d_min + 1e-9·s − d_k).
//
// TiledLfn has the members of LfnDecoder (lfn.js) that the viewer uses (geometry, poses, sizes,
// grow, render, toPixels), so the page shows a tile set as it shows one network; grow(n, pose)
// opens and grows the tiles that camera blends. `source` sums the requests of every file.
import { FormatError, LfcError, LfcFile } from "./lfc.js";
import { LfnDecoder } from "./lfn.js";

export const TILES_FORMAT = "lfcodec-lfn-tiles";
export const MAX_TILES = 64;
export const MAX_MANIFEST_BYTES = 1 << 20;
const NAME = /^[A-Za-z0-9._-]+(\/[A-Za-z0-9._-]+)*$/;

/** Parse and check a manifest's bytes (lfn_stream.tiles.read_manifest): {band, files, centres}. */
export function readManifest(bytes, name) {
  if (bytes.length > MAX_MANIFEST_BYTES) throw new FormatError(`${name}: a tile manifest is at most ${MAX_MANIFEST_BYTES} bytes, this is ${bytes.length}`);
  let m;
  try {
    m = JSON.parse(new TextDecoder("utf-8", { fatal: true }).decode(bytes));
  } catch (e) {
    throw new FormatError(`${name}: not a tile manifest (JSON: ${String(e.message).slice(0, 80)})`);
  }
  if (!m || typeof m !== "object" || Array.isArray(m) || m.format !== TILES_FORMAT) {
    throw new FormatError(`${name}: not a tile manifest (no "format": "${TILES_FORMAT}")`);
  }
  if (m.version !== 1) throw new FormatError(`${name}: tile manifest version ${JSON.stringify(m.version)} is not supported (this reader: 1)`);
  const band = m.band === undefined ? 0.5 : m.band, tiles = m.tiles;
  if (typeof band !== "number" || !(band >= 0 && band <= 4)) throw new FormatError(`${name}: band must be a number within 0..4, got ${JSON.stringify(band)}`);
  if (!Array.isArray(tiles) || tiles.length < 1 || tiles.length > MAX_TILES) throw new FormatError(`${name}: tiles must be a list of 1..${MAX_TILES} entries`);
  const files = [], centres = [];
  tiles.forEach((t, i) => {
    const f = t && typeof t === "object" ? t.file : undefined, c = t && typeof t === "object" ? t.centre : undefined;
    if (typeof f !== "string" || f.length > 255 || !NAME.test(f) || f.split("/").includes("..")) {
      throw new FormatError(`${name}: tile ${i}: file must be a relative name beside the manifest (letters, digits, '._-/', no '..'), got ${JSON.stringify(f)}`);
    }
    if (!Array.isArray(c) || c.length !== 3 || !c.every((v) => typeof v === "number" && Number.isFinite(v) && Math.abs(v) < 1e12)) {
      throw new FormatError(`${name}: tile ${i}: centre must be 3 finite numbers, got ${JSON.stringify(c)}`);
    }
    files.push(f);
    centres.push(c.slice());
  });
  return { band, files, centres };
}

/** Weights (Float64Array, summing to 1) of tiles with `centres` ([[x, y, z], ...]) for a camera
 *  at p ([x, y, z]) (lfn_stream.tiles.blend_weights). */
export function blendWeights(centres, p, band) {
  const d = centres.map((c) => Math.hypot(c[0] - p[0], c[1] - p[1], c[2] - p[2]));
  const dmin = Math.min(...d);
  const ext = [0, 1, 2].map((i) => Math.max(...centres.map((c) => c[i])) - Math.min(...centres.map((c) => c[i])));
  const scale = Math.hypot(...ext) || 1;
  const reach = (1 + band) * dmin + 1e-9 * scale;
  const w = Float64Array.from(d, (x) => Math.max(reach - x, 0));
  const sum = w.reduce((a, x) => a + x, 0);
  return w.map((x) => x / sum);
}

export class TiledLfn {
  /** Open a tile set: `manifest` a byte source (lfc.js BufferSource / RangeSource) named `name`,
   *  `openSource(fileName)` → the byte source of a tile file named in it (relative to the
   *  manifest); tile 0 is opened (its base network) for the geometry. */
  static async open(manifest, name, openSource, { chunkBytes = Infinity } = {}) {
    const size = await manifest.size();
    if (size > MAX_MANIFEST_BYTES) throw new FormatError(`${name}: a tile manifest is at most ${MAX_MANIFEST_BYTES} bytes, this is ${size}`);
    const m = readManifest(await manifest.read(0, size), name);
    const t = new TiledLfn();
    Object.assign(t, { name, band: m.band, files: m.files, centres: m.centres, manifestBytes: size, openSource,
      chunkBytes: chunkBytes / m.files.length, tiles: new Map(), sources: [manifest], active: [0] });
    const first = await t.tile(0);
    for (const k of ["rows", "cols", "W", "H", "C", "peak", "minN", "maxN", "depth", "layout", "occ"]) t[k] = first[k];
    const src = t.sources;
    t.source = {                                   // what the viewer's panel shows, summed over files
      get bytesFetched() { return src.reduce((a, s) => a + s.bytesFetched, 0); },
      get requests() { return src.reduce((a, s) => a + s.requests, 0); },
      get _size() { return src.reduce((a, s) => a + (s._size ?? (s.buf ? s.buf.length : 0)), 0); },
    };
    return t;
  }

  /** Tile j's LfnDecoder (its file opened, base network read, on first use; checked against tile 0). */
  async tile(j) {
    if (!this.tiles.has(j)) {
      const fname = this.files[j], src = this.openSource(fname);
      this.sources.push(src);
      const f = await LfcFile.open(src, fname, this.chunkBytes);
      if (f.meta.codec !== "lfn") throw new FormatError(`${fname}: a tile must be a light field network file, not '${f.meta.codec}'`);
      const d = await LfnDecoder.open(f, { maxNeurons: 0 });
      const ref = this.tiles.get(0);
      if (ref && ["rows", "cols", "W", "H", "C", "peak", "minN", "maxN"].some((k) => d[k] !== ref[k])) {
        throw new FormatError(`${fname}: tile ${j}'s scene or network sizes differ from the others'`);
      }
      this.tiles.set(j, d);
    }
    return this.tiles.get(j);
  }

  /** {tile: weight} of the tiles a camera (4×4 row-major pose) blends. */
  weights(pose) {
    const w = blendWeights(this.centres, [pose[3], pose[7], pose[11]], this.band), out = new Map();
    w.forEach((x, j) => { if (x > 0) out.set(j, x); });
    return out;
  }

  /** Open the tiles `pose` blends (all opened tiles without one) and fetch their steps up to a
   *  network of `maxNeurons`; returns the neurons every one of them holds. */
  async grow(maxNeurons = Infinity, pose = null) {
    this.active = pose ? [...this.weights(pose).keys()] : [...this.tiles.keys()];
    for (const j of this.active) await (await this.tile(j)).grow(maxNeurons);
    return this.neurons;
  }

  _activeTiles() { return this.active.filter((j) => this.tiles.has(j)).map((j) => this.tiles.get(j)); }

  /** Neurons held by every tile of the last camera (tile 0 before any). */
  get neurons() { return Math.min(...this._activeTiles().map((d) => d.neurons)); }

  displayNeurons(scale = null) { return Math.min(...this._activeTiles().map((d) => d.displayNeurons(scale))); }

  weightBytes() { return [...this.tiles.values()].reduce((a, d) => a + d.weightBytes(), 0); }

  scaleOf(neurons) { return this.tiles.get(0).scaleOf(neurons); }

  pose(v) { return this.tiles.get(0).pose(v); }

  gridPose(s, t) { return this.tiles.get(0).gridPose(s, t); }

  orbitPose(v, yaw, pitch = 0) { return this.tiles.get(0).orbitPose(v, yaw, pitch); }

  /** Render a camera as the blend of its tiles (each opened and grown by grow(n, pose) first),
   *  every tile at `neurons` and `scale` (and `native`, as LfnDecoder.render):
   *  {rgba (premultiplied), h, w, evaluated, stride, tiles}. */
  render(pose, neurons, scale = null, opts = {}) {
    return this._blendEach(pose, (d) => d.render(pose, neurons, scale, opts));
  }

  /** render() with each tile's network passes on `opts.pool`'s workers (LfnDecoder.renderAsync). */
  renderAsync(pose, neurons, scale = null, opts = {}) {
    return this._blendEachAsync(pose, (d) => d.renderAsync(pose, neurons, scale, opts));
  }

  /** Per-pixel sizes around a gaze (LfnDecoder.foveationMap) over the sizes every tile of the
   *  last camera holds. */
  foveationMap(gaze, h, w, inner = 0.1, outer = 0.5) {
    return this._activeTiles().reduce((a, d) => (d.neurons < a.neurons ? d : a)).foveationMap(gaze, h, w, inner, outer);
  }

  /** A foveated frame: the blend of the tiles' own renderMip frames (TiledLfnRenderer.render_pose_lod_mip). */
  renderMip(pose, lod, scale = 1, opts = {}) {
    return this._blendEach(pose, (d) => d.renderMip(pose, lod, scale, opts));
  }

  /** renderMip() with each tile's passes on `opts.pool`'s workers (LfnDecoder.renderMipAsync). */
  renderMipAsync(pose, lod, scale = 1, opts = {}) {
    return this._blendEachAsync(pose, (d) => d.renderMipAsync(pose, lod, scale, opts));
  }

  /** The blend of render(tile decoder) over the tiles `pose` blends. */
  _blendEach(pose, render) {
    return this._blend([...this.weights(pose)].map(([j, wj]) => [j, wj, render(this._opened(j))]));
  }

  /** _blendEach with an async render, the tiles one after another (each shares the workers). */
  async _blendEachAsync(pose, render) {
    const parts = [];
    for (const [j, wj] of this.weights(pose)) parts.push([j, wj, await render(this._opened(j))]);
    return this._blend(parts);
  }

  _opened(j) {
    const d = this.tiles.get(j);
    if (!d) throw new LfcError(`tile ${j} is not open: call grow(neurons, pose) before render`);
    return d;
  }

  /** The weighted sum of the tiles' renders [[tile, weight, render]]. */
  _blend(parts) {
    let out = null, evaluated = 0, h = 0, w = 0, stride = 1, levels;
    for (const [, wj, r] of parts) {
      if (out === null) { out = new Float64Array(r.rgba.length); h = r.h; w = r.w; stride = r.stride; levels = r.levels; }
      for (let i = 0; i < out.length; i++) out[i] += wj * r.rgba[i];
      evaluated += r.evaluated;
    }
    return { rgba: out, h, w, evaluated, stride, levels, tiles: parts.map(([j]) => j) };
  }

  toPixels(rgba, h, w) { return this.tiles.get(0).toPixels(rgba, h, w); }
}
