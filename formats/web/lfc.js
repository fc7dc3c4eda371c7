// lfc.js — a reader of .lfc files (container + RLFC profile "tx") in plain JavaScript, for the
// browser viewer and for Node (>= 18). Written from docs/FORMAT.md alone (no code shared with the
// Python decoder), so it doubles as the format's independent reference decoder: the tests
// compare its integers with the Python decoder's on real files.
//
// Bytes come from a source with `size()` and `read(a, b)` (HTTP Range requests: RangeSource; an
// in-memory buffer: BufferSource). Every section chunk read is checked against its CRC-32 the
// first time it arrives. Units: planes are Int32Array of Hp·Wp·P values, row-major, planes last
// (YCoCg-R for RGB, grey, alpha last); pixels are H·W·C values of the file's dtype.
import { PredictKernel } from "./predict.js";

export class LfcError extends Error {
  constructor(msg) { super(msg); this.name = "LfcError"; }
}
export class FormatError extends LfcError {
  constructor(msg) { super(msg); this.name = "FormatError"; }
}
export class UnsupportedError extends LfcError {
  constructor(msg) { super(msg); this.name = "UnsupportedError"; }
}

const MAGIC = [0x89, 0x4c, 0x46, 0x43, 0x0d, 0x0a, 0x1a, 0x0a];
export const LIMITS = {
  views: 65536, viewPixels: 1 << 26, openPixels: 1 << 28, metaBytes: 64 << 20, sections: 4096,
};

// -- bytes --------------------------------------------------------------------------------------
const CRC_TABLE = (() => {
  const t = new Uint32Array(256);
  for (let n = 0; n < 256; n++) {
    let c = n;
    for (let k = 0; k < 8; k++) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
    t[n] = c >>> 0;
  }
  return t;
})();

/** CRC-32 (zlib's) of bytes, continuing from `crc` (0 to start). */
export function crc32(bytes, crc = 0) {
  let c = (crc ^ 0xffffffff) >>> 0;
  for (let i = 0; i < bytes.length; i++) c = CRC_TABLE[(c ^ bytes[i]) & 255] ^ (c >>> 8);
  return (c ^ 0xffffffff) >>> 0;
}

/** Bytes from an in-memory Uint8Array / ArrayBuffer. */
export class BufferSource {
  constructor(buf) {
    this.buf = buf instanceof Uint8Array ? buf : new Uint8Array(buf);
    this.bytesFetched = 0;
    this.requests = 0;
  }
  async size() { return this.buf.length; }
  async read(a, b) {
    this.requests += 1;
    this.bytesFetched += b - a;
    return this.buf.subarray(a, b);
  }
}

/** Bytes a file's open reads ahead (LfcFile.open: one request for the header, the section table
 *  and the metadata, ~2.5 KB on the dense grids' files; small, as a light field network's first
 *  renderable prefix is ≤ 8 KB). */
const EARLY_BYTES = 4096;

/** A source whose first bytes were read ahead: reads inside them cost no request. */
class EarlySource {
  constructor(source, early) { this.source = source; this.early = early; }
  async size() { return this.source.size(); }
  async read(a, b) {
    const n = this.early.length;
    if (b <= n) return this.early.subarray(a, b);
    if (a >= n) return this.source.read(a, b);
    const rest = await this.source.read(n, b), out = new Uint8Array(b - a);   // (the rest only)
    out.set(this.early.subarray(a, n), 0);
    out.set(rest, n - a);
    return out;
  }
}

/** Bytes of a URL by HTTP Range requests (one request per read; `fetchImpl` = fetch). */
export class RangeSource {
  constructor(url, fetchImpl = (...a) => globalThis.fetch(...a)) {
    this.url = url;
    this.fetch = fetchImpl;
    this.bytesFetched = 0;
    this.requests = 0;
    this._size = null;
    this._etag = null;
    this._head = null;                      // the first bytes, read with the size
  }
  async size() {
    if (this._size === null) {
      // the size (Content-Range), version (ETag) and the file's first bytes in one range GET,
      // which LfcFile.open reads next; a HEAD where the answer gives no total size (a
      // cross-origin server that does not expose Content-Range)
      const g = await this.fetch(this.url, { headers: { Range: `bytes=0-${EARLY_BYTES - 1}` }, cache: "no-store" });
      if (g.status !== 206 && g.status !== 200 && !g.ok) throw new LfcError(`${this.url}: HTTP ${g.status}`);
      const m = /^bytes 0-(\d+)\/(\d+)$/.exec(g.headers.get("Content-Range") || "");
      if (g.status === 206 && m) {
        const buf = new Uint8Array(await g.arrayBuffer()), n = Number(m[2]);
        if (!Number.isSafeInteger(n) || buf.length !== Math.min(EARLY_BYTES, n) || Number(m[1]) !== buf.length - 1) {
          throw new FormatError(`${this.url}: the server answered range ${g.headers.get("Content-Range")} with ${buf.length} bytes`);
        }
        this.requests += 1;
        this.bytesFetched += buf.length;
        this._size = n;
        this._etag = g.headers.get("ETag");
        this._head = buf;
        return n;
      }
      // the first bytes without the size: kept (read once); a 200 (the whole file): not read
      const part = g.status === 206 && /^bytes 0-\d+\//.test(g.headers.get("Content-Range") || "")
        ? new Uint8Array(await g.arrayBuffer()) : null;
      if (!part && g.body && g.body.cancel) g.body.cancel().catch(() => {});
      if (part) { this.requests += 1; this.bytesFetched += part.length; }
      const r = await this.fetch(this.url, { method: "HEAD", cache: "no-store" });
      if (!r.ok) throw new LfcError(`${this.url}: HTTP ${r.status}`);
      const n = Number(r.headers.get("Content-Length"));
      if (!Number.isSafeInteger(n) || n < 0) throw new LfcError(`${this.url}: the server gave no length`);
      if ((r.headers.get("Accept-Ranges") || "").toLowerCase() !== "bytes") {
        throw new LfcError(`${this.url}: the server does not serve byte ranges`);
      }
      this._size = n;
      this._etag = r.headers.get("ETag");
      if (part && part.length === Math.min(EARLY_BYTES, n) && g.headers.get("ETag") === this._etag) this._head = part;
    }
    return this._size;
  }
  async read(a, b) {
    if (b <= a) return new Uint8Array(0);
    if (this._head && a >= 0 && b <= this._head.length) return this._head.subarray(a, b);   // (size()'s bytes)
    const headers = { Range: `bytes=${a}-${b - 1}` };
    if (this._etag) headers["If-Match"] = this._etag;
    this.requests += 1;
    const r = await this.fetch(this.url, { headers, cache: "no-store" });
    if (r.status === 412) throw new LfcError(`${this.url} changed on the server while it was read`);
    if (r.status !== 206) throw new LfcError(`${this.url}: expected 206 Partial Content, got HTTP ${r.status}`);
    const buf = new Uint8Array(await r.arrayBuffer());
    if (buf.length !== b - a) throw new FormatError(`${this.url}: asked for ${b - a} bytes at ${a}, got ${buf.length}`);
    this.bytesFetched += buf.length;
    return buf;
  }
}

/** Inflate a zlib stream whose output must not exceed `limit` bytes (FormatError otherwise). */
export async function inflate(data, limit, what) {
  if (typeof DecompressionStream === "undefined") throw new UnsupportedError("this browser has no DecompressionStream");
  const ds = new DecompressionStream("deflate");
  const writer = ds.writable.getWriter();
  const done = writer.write(data).then(() => writer.close()).catch(() => {});
  const reader = ds.readable.getReader();
  const parts = [];
  let n = 0;
  try {
    for (;;) {
      const { value, done: end } = await reader.read();
      if (end) break;
      n += value.length;
      if (n > limit) {
        reader.cancel().catch(() => {});
        throw new FormatError(`${what} is larger than its ${limit}-byte bound`);
      }
      parts.push(value);
    }
  } catch (e) {
    if (e instanceof LfcError) throw e;
    throw new FormatError(`${what} is not a valid zlib stream (${e.message || e})`);
  }
  await done;
  const out = new Uint8Array(n);
  let p = 0;
  for (const v of parts) { out.set(v, p); p += v.length; }
  return out;
}

/** Zig-zag LEB128 varints: exactly `count` values filling `bytes` (numbers, exact below 2^53). */
export function unvarints(bytes, count, what) {
  const out = new Array(count);
  let p = 0;
  for (let i = 0; i < count; i++) {
    let u = 0, mul = 1, k = 0;
    for (;;) {
      if (p >= bytes.length) throw new FormatError(`${what}: expected ${count} varints in ${bytes.length} bytes`);
      const b = bytes[p++];
      u += (b & 127) * mul;
      mul *= 128;
      if (++k > 8) throw new FormatError(`${what}: a varint is too long`);
      if (b < 128) break;
    }
    out[i] = u % 2 === 0 ? u / 2 : -(u + 1) / 2;
  }
  if (p !== bytes.length) throw new FormatError(`${what}: expected ${count} varints in ${bytes.length} bytes`);
  return out;
}

function u32(b, o) { return (b[o] | (b[o + 1] << 8) | (b[o + 2] << 16) | (b[o + 3] << 24)) >>> 0; }
function u64(b, o, what) {
  const lo = u32(b, o), hi = u32(b, o + 4);
  if (hi >= 1 << 21) throw new FormatError(`${what}: a 64-bit field is too large`);
  return hi * 4294967296 + lo;
}

// -- container ---------------------------------------------------------------------------------
/** An opened .lfc container: the section table, the meta JSON, and verified section reads. */
export class LfcFile {
  /** `chunkBudget`: bytes of verified section chunks kept in memory (least recently used go
   *  first; a chunk is fetched and verified again when it is needed again). */
  static async open(source, name = "file", chunkBudget = Infinity) {
    const f = new LfcFile();
    f.source = source;
    f.name = name;
    f.chunkBudget = chunkBudget;
    f.lru = new Map();                      // "section/chunk" → bytes, least recently used first
    f.held = 0;
    const size = await source.size();
    if (size < 32) throw new FormatError(`${name}: ${size} bytes is too short for an .lfc header`);
    // the file's first bytes in one request (the header, the section table and the metadata come
    // first), served to the reads below and later ones; each chunk is still verified when first read
    const early = await source.read(0, Math.min(size, EARLY_BYTES));
    f.source = new EarlySource(source, early);
    const head = early.subarray(0, 32);
    for (let i = 0; i < 8; i++) {
      if (head[i] !== MAGIC[i]) throw new FormatError(`${name}: not an .lfc file (bad magic)`);
    }
    const major = head[8] | (head[9] << 8);
    if (major !== 1) throw new UnsupportedError(`${name}: format version ${major}.x is not supported (this reader knows 1.x)`);
    const nSec = u32(head, 12), nCrc = u32(head, 16), hcrc = u32(head, 20);
    if (nSec < 1 || nSec > LIMITS.sections) throw new FormatError(`${name}: ${nSec} sections is out of range`);
    const tableEnd = 32 + 48 * nSec + 4 * nCrc;
    if (tableEnd > size) throw new FormatError(`${name}: the section table does not fit the file (truncated?)`);
    const table = await f.source.read(32, tableEnd);
    let c = crc32(head.subarray(0, 20));
    c = crc32(table, c);
    if (c !== hcrc) throw new FormatError(`${name}: header checksum mismatch (corrupt file)`);
    f.crcs = new Uint32Array(nCrc);
    for (let i = 0; i < nCrc; i++) f.crcs[i] = u32(table, 48 * nSec + 4 * i);
    f.sections = new Map();
    let pos = tableEnd;
    for (let i = 0; i < nSec; i++) {
      const o = 48 * i;
      let sname = "";
      for (let k = 0; k < 16 && table[o + k]; k++) sname += String.fromCharCode(table[o + k]);
      const off = u64(table, o + 16, name), len = u64(table, o + 24, name);
      const chunk = u32(table, o + 32), first = u32(table, o + 36);
      if (chunk < 1) throw new FormatError(`${name}: section '${sname}' has chunk size 0`);
      if (off !== pos) throw new FormatError(`${name}: section '${sname}' does not start where the previous ends`);
      const nChunks = len ? Math.ceil(len / chunk) : 0;
      if (first + nChunks > nCrc) throw new FormatError(`${name}: section '${sname}' has checksums past the table`);
      if (f.sections.has(sname)) throw new FormatError(`${name}: section '${sname}' appears twice`);
      if (off + len > size) throw new FormatError(`${name}: truncated: section '${sname}' is cut off`);
      f.sections.set(sname, { name: sname, offset: off, length: len, chunk, first, nChunks, chunks: new Map() });
      pos = off + len;
    }
    if (pos !== size) throw new FormatError(`${name}: ${size - pos} bytes after the last section`);
    if (!f.sections.has("meta")) throw new FormatError(`${name}: no 'meta' section`);
    const meta = f.sections.get("meta");
    if (meta.length > LIMITS.metaBytes) throw new FormatError(`${name}: the meta section is too large`);
    const text = new TextDecoder("utf-8", { fatal: true });
    try {
      f.meta = JSON.parse(text.decode(await f.read("meta")));
    } catch (e) {
      if (e instanceof LfcError) throw e;
      throw new FormatError(`${name}: the meta section is not UTF-8 JSON (${e.message})`);
    }
    if (!f.meta || typeof f.meta !== "object" || Array.isArray(f.meta)) throw new FormatError(`${name}: meta is not an object`);
    return f;
  }

  /** The metadata with the keys listed in `meta.more` put back from the deflated `meta.more`
   *  section (FORMAT.md "Moved metadata"); read and checked once. */
  async fullMeta() {
    if (this._full) return this._full;
    const meta = this.meta, name = this.name;
    if (meta.more === undefined) return (this._full = meta);
    const keys = meta.more;
    if (!Array.isArray(keys) || keys.length < 1 || keys.length > 64 || !keys.every((k) => typeof k === "string") || new Set(keys).size !== keys.length) {
      throw new FormatError(`${name}: metadata 'more' must be a list of 1..64 distinct key names`);
    }
    const want = {};
    for (const k of keys) {
      const dot = k.indexOf("."), part = dot < 0 ? k : k.slice(0, dot), key = dot < 0 ? "" : k.slice(dot + 1);
      const obj = meta[part];
      if ((part !== "scene" && part !== "config") || !key || !obj || typeof obj !== "object" || Array.isArray(obj) || Object.hasOwn(obj, key)) {
        throw new FormatError(`${name}: metadata 'more' names '${k}', which is not a scene.KEY/config.KEY missing from meta`);
      }
      (want[part] = want[part] || new Set()).add(key);
    }
    if (!this.sections.has("meta.more")) throw new FormatError(`${name}: metadata names moved keys but the file has no 'meta.more' section`);
    const raw = await inflate(await this.read("meta.more"), LIMITS.metaBytes, `${name}: section 'meta.more'`);
    let more;
    try {
      more = JSON.parse(new TextDecoder("utf-8", { fatal: true }).decode(raw));
    } catch (e) {
      throw new FormatError(`${name}: section 'meta.more' is not UTF-8 JSON (${e.message})`);
    }
    const same = (a, b) => a.size === b.size && [...a].every((x) => b.has(x));
    const ok = more && typeof more === "object" && !Array.isArray(more) && same(new Set(Object.keys(more)), new Set(Object.keys(want)))
      && Object.keys(more).every((p) => more[p] && typeof more[p] === "object" && !Array.isArray(more[p]) && same(new Set(Object.keys(more[p])), want[p]));
    if (!ok) throw new FormatError(`${name}: section 'meta.more' does not hold exactly the keys metadata 'more' names`);
    const out = { ...meta };
    for (const p of Object.keys(more)) out[p] = { ...meta[p], ...more[p] };
    return (this._full = out);
  }

  info(sname) {
    const s = this.sections.get(sname);
    if (!s) throw new FormatError(`${this.name}: missing section '${sname}'`);
    return s;
  }

  /** Bytes [a, b) of a section (whole section by default), every chunk verified once; the
   *  missing chunks are fetched in one range request per run of consecutive chunks. */
  async read(sname, a = 0, b = null) {
    const s = this.info(sname);
    if (b === null) b = s.length;
    if (a < 0 || b > s.length || a > b) throw new FormatError(`${this.name}: read past the end of section '${sname}'`);
    if (a === b) return new Uint8Array(0);
    const k0 = Math.floor(a / s.chunk), k1 = Math.floor((b - 1) / s.chunk);
    for (let j = k0; j <= k1; j++) {        // mark the chunks this read uses as recently used
      const key = `${sname}/${j}`, c = this.lru.get(key);
      if (c) { this.lru.delete(key); this.lru.set(key, c); }
    }
    let k = k0;
    while (k <= k1) {
      if (s.chunks.has(k)) { k++; continue; }
      let e = k;
      while (e + 1 <= k1 && !s.chunks.has(e + 1)) e++;
      const lo = k * s.chunk, hi = Math.min((e + 1) * s.chunk, s.length);
      const got = await this.source.read(s.offset + lo, s.offset + hi);
      for (let j = k; j <= e; j++) this._store(s, j, got.slice((j - k) * s.chunk, Math.min((j - k + 1) * s.chunk, got.length)));
      k = e + 1;
    }
    const out = this._assemble(s, a, b, k0, k1);
    for (const [key, c] of this.lru) {         // over budget: drop the least recently used chunks
      if (this.held <= this.chunkBudget) break;
      const cut = key.lastIndexOf("/"), sec = this.sections.get(key.slice(0, cut)), j = Number(key.slice(cut + 1));
      if (sec === s && j >= k0 && j <= k1) continue;
      sec.chunks.delete(j);
      this.lru.delete(key);
      this.held -= c.length;
    }
    return out;
  }

  /** Fetch every missing chunk of the named sections (consecutive in the file, as the LFN
   *  steps are) in one range request per run of missing chunks, verified and cached; later
   *  reads of those sections cost no request while the chunks stay in the budget. */
  async prefetch(snames) {
    const want = [];                          // [file offset, end, section, chunk] of missing chunks
    for (const n of snames) {
      const s = this.info(n);
      for (let j = 0; j < s.nChunks; j++) {
        if (!s.chunks.has(j)) want.push([s.offset + j * s.chunk, s.offset + Math.min((j + 1) * s.chunk, s.length), s, j]);
      }
    }
    want.sort((x, y) => x[0] - y[0]);
    let i = 0;
    while (i < want.length) {
      let e = i;
      while (e + 1 < want.length && want[e + 1][0] === want[e][1]) e++;
      const lo = want[i][0], got = await this.source.read(lo, want[e][1]);
      for (let k = i; k <= e; k++) this._store(want[k][2], want[k][3], got.slice(want[k][0] - lo, want[k][1] - lo));
      i = e + 1;
    }
  }

  /** Verify chunk j of section s against its CRC and keep it (counted in the budget). */
  _store(s, j, part) {
    if (crc32(part) !== this.crcs[s.first + j]) {
      throw new FormatError(`${this.name}: checksum mismatch in section '${s.name}' chunk ${j} (corrupt file)`);
    }
    s.chunks.set(j, part);
    this.lru.set(`${s.name}/${j}`, part);
    this.held += part.length;
  }

  _assemble(s, a, b, k0, k1) {
    if (k0 === k1) {
      const base = k0 * s.chunk;
      return s.chunks.get(k0).subarray(a - base, b - base);
    }
    const out = new Uint8Array(b - a);
    for (let j = k0; j <= k1; j++) {
      const part = s.chunks.get(j), base = j * s.chunk;
      const lo = Math.max(a, base), hi = Math.min(b, base + part.length);
      out.set(part.subarray(lo - base, hi - base), lo - a);
    }
    return out;
  }

  /** Bytes of section chunks held in memory. */
  cachedBytes() { return this.held; }
}

// -- metadata checks ------------------------------------------------------------------------------
function need(obj, key, where) {
  if (!obj || typeof obj !== "object" || !(key in obj)) throw new FormatError(`${where}: missing '${key}'`);
  return obj[key];
}
function int(obj, key, where, lo = -(2 ** 53), hi = 2 ** 53) {
  const v = need(obj, key, where);
  if (!Number.isSafeInteger(v) || v < lo || v > hi) throw new FormatError(`${where}.${key} must be an integer in [${lo}, ${hi}], got ${JSON.stringify(v)}`);
  return v;
}
function intList(obj, key, where, len, lo, hi) {
  const v = need(obj, key, where);
  if (!Array.isArray(v) || (len !== null && v.length !== len)) throw new FormatError(`${where}.${key} must be a list of ${len} integers`);
  for (const x of v) {
    if (!Number.isSafeInteger(x) || x < lo || x > hi) throw new FormatError(`${where}.${key} holds ${JSON.stringify(x)}, out of [${lo}, ${hi}]`);
  }
  return v;
}

// -- rANS ---------------------------------------------------------------------------------------
const PROB_BITS = 12, M = 1 << PROB_BITS, RANS_L = 1 << 15;

// integer weight of each quantized count: round(2^((q−1)/8)) (never a tie), 0 for 0
const COUNT_WEIGHT = (() => {
  const w = new Float64Array(256);
  for (let q = 1; q < 256; q++) w[q] = Math.round(2 ** ((q - 1) / 8));
  return w;
})();

/** Frequencies (A,) summing to 4096 from integer weights (FORMAT.md "rANS tables", version 2). */
export function normalizeInt(w) {
  const A = w.length;
  let T = 0, nUsed = 0;
  for (const x of w) { T += x; if (x > 0) nUsed++; }
  if (T <= 0) { w = new Float64Array(A).fill(1); T = A; nUsed = A; }
  const f = new Float64Array(A), rem = new Float64Array(A);
  let sum = 0;
  for (let s = 0; s < A; s++) {
    if (w[s] > 0) {
      const num = w[s] * M;                        // < 2^44: exact in doubles
      f[s] = Math.max(1, Math.floor(num / T));
      rem[s] = num - Math.floor(num / T) * T;
      sum += f[s];
    } else rem[s] = -1;
  }
  let diff = M - sum;
  if (diff > 0) {
    const order = [...Array(A).keys()].sort((a, b) => (rem[b] - rem[a]) || (a - b));
    for (let i = 0; i < diff; i++) f[order[i % nUsed]] += 1;
  }
  while (diff < 0) {
    let j = 0;
    for (let s = 1; s < A; s++) if (f[s] > f[j]) j = s;
    const take = Math.min(-diff, f[j] - 1);
    f[j] -= take;
    diff += take;
  }
  return f;
}

/** Context tables: freq/cum (C·A) and a slot → symbol look-up (C·4096). */
class Tables {
  constructor(weights, nCtx, A) {
    this.A = A;
    this.freq = new Uint32Array(nCtx * A);
    this.cum = new Uint32Array(nCtx * (A + 1));
    this.slot = new Uint8Array(nCtx * M);
    for (let c = 0; c < nCtx; c++) {
      const f = normalizeInt(weights.subarray(c * A, (c + 1) * A));
      let acc = 0;
      for (let s = 0; s < A; s++) {
        this.freq[c * A + s] = f[s];
        this.cum[c * (A + 1) + s] = acc;
        this.slot.fill(s, c * M + acc, c * M + acc + f[s]);
        acc += f[s];
      }
      this.cum[c * (A + 1) + A] = acc;
    }
  }
}

/** Quantized counts (zlib: context bitmap; per used context a symbol bitmap + one byte per used symbol) → Tables. */
async function readTables(data, nCtx, A, what) {
  const limit = Math.ceil(nCtx / 8) + nCtx * (Math.ceil(A / 8) + A);
  const b = await inflate(data, limit, what);
  const nb = Math.ceil(nCtx / 8), ab = Math.ceil(A / 8);
  if (b.length < nb) throw new FormatError(`${what}: rANS tables are truncated`);
  const w = new Float64Array(nCtx * A);
  let pos = nb;
  for (let c = 0; c < nCtx; c++) {
    if (!((b[c >> 3] >> (c & 7)) & 1)) continue;
    if (pos + ab > b.length) throw new FormatError(`${what}: rANS tables are truncated`);
    const syms = [];
    for (let s = 0; s < A; s++) if ((b[pos + (s >> 3)] >> (s & 7)) & 1) syms.push(s);
    pos += ab;
    if (!syms.length || pos + syms.length > b.length) throw new FormatError(`${what}: rANS tables are truncated or empty`);
    for (const s of syms) {
      const q = b[pos++];
      if (!q) throw new FormatError(`${what}: rANS tables hold a zero count`);
      w[c * A + s] = COUNT_WEIGHT[q];
    }
  }
  if (pos !== b.length) throw new FormatError(`${what}: rANS tables have trailing bytes`);
  return new Tables(w, nCtx, A);
}

/** A rANS stream's and parseBlock's errors (after the stream's name), by the code predict_kernel.wat's parse returns. */
const PARSE_ERRORS = [null, "rANS stream shorter than its 3-byte state", "rANS stream reads past its end",
  "undefined tb mode", "a last position past 64", "undefined magnitude symbol", "undefined escape bucket",
  "malformed stream (its symbols do not end where its raw bits start)"];

/** One rANS stream (FORMAT.md "rANS"). */
class Rans {
  constructor(data, start, end, t, what) {
    if (end - start < 3) throw new FormatError(`${what}: ${PARSE_ERRORS[1]}`);
    this.d = data; this.p = start + 3; this.end = end; this.t = t; this.what = what;
    this.x = data[start] | (data[start + 1] << 8) | (data[start + 2] << 16);
  }
  get(ctx) {
    const t = this.t, A = t.A;
    let x = this.x;
    const sl = x & (M - 1);
    const s = t.slot[ctx * M + sl];
    x = t.freq[ctx * A + s] * (x >>> PROB_BITS) + sl - t.cum[ctx * (A + 1) + s];
    while (x < RANS_L) {
      if (this.p >= this.end) throw new FormatError(`${this.what}: ${PARSE_ERRORS[2]}`);
      x = (x << 8) | this.d[this.p++];
    }
    this.x = x;
    return s;
  }
  done(end, backBits = 0) { return this.x - RANS_L >= 0 && this.x - RANS_L < 2 ** backBits && this.p === end; }
}

// -- the tx block syntax ----------------------------------------------------------------------------
const MODE_SKIP = 0, MODE_INTRA = 2, ESC = 15, N_BUCKETS = 24;
const CTX_MODE = 0, CTX_LAST = 8, CTX_MAG = 20, CTX_ESC = 164, N_CTX = 167, ALPHABET = 65;
const BAND8 = new Int32Array(64);
for (let p = 0; p < 64; p++) BAND8[p] = 8 * (p === 0 ? 0 : p <= 2 ? 1 : p <= 5 ? 2 : p <= 9 ? 3 : p <= 20 ? 4 : 5);
export const ZIGZAG = (() => {
  const k = [...Array(64).keys()];
  k.sort((a, b) => {
    const sa = (a >> 3) + (a & 7), sb = (b >> 3) + (b & 7);
    if (sa !== sb) return sa - sb;
    const ka = sa % 2 === 0 ? a & 7 : a >> 3, kb = sb % 2 === 0 ? b & 7 : b >> 3;
    return ka - kb;
  });
  return Int32Array.from(k);
})();
const T8 = [
  [64, 64, 64, 64, 64, 64, 64, 64], [89, 75, 50, 18, -18, -50, -75, -89],
  [83, 36, -36, -83, -83, -36, 36, 83], [75, -18, -89, -50, 50, 89, 18, -75],
  [64, -64, -64, 64, 64, -64, -64, 64], [50, -89, 18, 75, -75, -18, 89, -50],
  [36, -83, 83, -36, -36, 83, -83, 36], [18, -50, 75, -89, 89, -75, 50, -18],
];
const COEF_MAX = 2 ** 21 - 1;

function planeClasses(P) { return { 1: [0], 2: [0, 2], 3: [0, 1, 1], 4: [0, 1, 1, 2] }[P]; }

/** Parse one block stream of `nt` tbs → {modes (nt), levels (Int32Array nt·P·64, scan order)}
 *  (predict_kernel.wat's parse: the same integers and errors). */
function parseBlock(data, start, end, tables, nt, pcs, kind, key, what) {
  const P = pcs.length;
  const d = new Rans(data, start, end, tables, what);
  const modes = new Int32Array(nt);
  let prev = 3;
  for (let t = 0; t < nt; t++) {
    const s = d.get(CTX_MODE + kind * 4 + prev);
    if (s >= 3) throw new FormatError(`${what}: ${PARSE_ERRORS[3]}`);
    modes[t] = s; prev = s;
  }
  const last = new Int32Array(nt * P);
  for (let t = 0; t < nt; t++) {
    if (modes[t] === MODE_SKIP) continue;
    const ci = modes[t] === MODE_INTRA ? 1 : 0;
    for (let p = 0; p < P; p++) {
      const v = d.get(CTX_LAST + (pcs[p] * 2 + ci) * 2 + key);
      if (v > 64) throw new FormatError(`${what}: ${PARSE_ERRORS[4]}`);
      last[t * P + p] = v;
    }
  }
  const levels = new Int32Array(nt * P * 64);
  const cIdx = [], cFirst = [];                       // nonzero coefficients in magnitude order
  for (let g = 0; g < nt * P; g++) {
    const n = last[g];
    if (!n) continue;
    const base = CTX_MAG + pcs[g % P] * 48 + key * 4;
    let pos = n - 1;
    let s = d.get(base + BAND8[pos]);
    if (s > ESC) throw new FormatError(`${what}: ${PARSE_ERRORS[5]}`);
    levels[g * 64 + pos] = s + 1;
    cIdx.push(g * 64 + pos); cFirst.push(1);
    let h1 = s + 1, h2 = 0;
    for (pos = n - 2; pos >= 0; pos--) {
      s = d.get(base + BAND8[pos] + 1 + (h1 > 0 ? 1 : 0) + (h2 > 0 ? 1 : 0));
      if (s > ESC) throw new FormatError(`${what}: ${PARSE_ERRORS[5]}`);
      h2 = h1; h1 = s;
      if (s) { levels[g * 64 + pos] = s; cIdx.push(g * 64 + pos); cFirst.push(0); }
    }
  }
  const escK = [];
  for (let i = 0; i < cIdx.length; i++) {
    const m = levels[cIdx[i]];
    if (m - cFirst[i] === ESC) {
      const k = d.get(CTX_ESC + pcs[(cIdx[i] >> 6) % P]);
      if (k >= N_BUCKETS) throw new FormatError(`${what}: ${PARSE_ERRORS[6]}`);
      escK.push([i, k]);
    }
  }
  let nbits = cIdx.length;
  for (const [, k] of escK) nbits += k;
  const kb = Math.min(nbits, 15);
  const rawStart = end - Math.ceil((nbits - kb) / 8);
  if (rawStart < d.p || !d.done(rawStart, kb)) throw new FormatError(`${what}: ${PARSE_ERRORS[7]}`);
  const R = d.x - RANS_L;
  let bit = 0;
  const getBit = () => {
    const i = bit++;
    if (i < kb) return (R >> i) & 1;
    const j = i - kb;
    return (data[rawStart + (j >> 3)] >> (j & 7)) & 1;
  };
  const neg = new Uint8Array(cIdx.length);
  for (let i = 0; i < cIdx.length; i++) neg[i] = getBit();
  for (const [i, k] of escK) {
    let r = 0;
    for (let b = 0; b < k; b++) r += getBit() * 2 ** b;
    levels[cIdx[i]] = ESC + cFirst[i] + (2 ** k - 1) + r;
  }
  for (let i = 0; i < cIdx.length; i++) if (neg[i]) levels[cIdx[i]] = -levels[cIdx[i]];
  return { modes, levels };
}

const T8F = Float64Array.from(T8.flat());           // T8 row-major: T8F[k·8 + i] = T8[k][i]
const RES_X = new Float64Array(64), RES_Y = new Float64Array(64), RES_OUT = new Float64Array(64);

/** Residual of one tb and plane: levels (64, scan order) → out (64, raster), exact integers.
 *  Every product and sum is an integer below 2^53, so the terms of zero rows of X (first pass)
 *  and zero columns of X, hence of Y (second pass), are skipped without changing a value. */
function residual(levels, off, step16, bypass, out) {
  const X = RES_X;
  X.fill(0);
  let rowsNz = 0, colsNz = 0;
  for (let i = 0; i < 64; i++) {
    const q = levels[off + i];
    if (!q) continue;
    let v = Math.floor((Math.abs(q) * step16 + 8) / 16);
    if (v > COEF_MAX) v = COEF_MAX;
    const at = bypass ? i : ZIGZAG[i];
    X[at] = q < 0 ? -v : v;
    rowsNz |= 1 << (at >> 3);
    colsNz |= 1 << (at & 7);
  }
  if (!rowsNz) { out.fill(0); return; }
  if (bypass) { out.set(X); return; }
  const Y = RES_Y;
  for (let i = 0; i < 8; i++) {                        // Y = (Tᵀ X + 64) >> 7
    for (let j = 0; j < 8; j++) {
      let s = 0;
      if (colsNz & (1 << j)) {
        for (let k = 0; k < 8; k++) if (rowsNz & (1 << k)) s += T8F[k * 8 + i] * X[k * 8 + j];
      }
      Y[i * 8 + j] = Math.floor((s + 64) / 128);
    }
  }
  for (let i = 0; i < 8; i++) {                        // R = (Y T + 128) >> 8
    for (let j = 0; j < 8; j++) {
      let s = 0;
      for (let k = 0; k < 8; k++) {
        const y = Y[i * 8 + k];
        if (y) s += y * T8F[k * 8 + j];
      }
      out[i * 8 + j] = Math.floor((s + 128) / 256);
    }
  }
}

// -- the tx profile --------------------------------------------------------------------------------
const TB = 8, MAX_REFS = 4;
const WARP_AB_MAX = 1 << 12, WARP_C_MAX = 1 << 15;      // a view warp's ranges (rlfc/txwarp.py)

/** Decoder of an RLFC file of profile "tx" (FORMAT.md "Profile tx"); open with openDecoder(). */
export class TxDecoder {
  async init(file, keyImage) {
    const name = file.name, meta = await file.fullMeta();
    if (meta.codec !== "rlfc") throw new UnsupportedError(`${name}: codec '${meta.codec}' is not supported here (only rlfc)`);
    const cv = meta.codec_version;
    if (!Number.isInteger(cv) || cv < 1) throw new FormatError(`${name}: metadata codec_version must be an integer >= 1, got ${JSON.stringify(cv)}`);
    if (cv > 1) throw new UnsupportedError(`${name}: rlfc codec version ${cv} is newer than this reader (1)`);
    const cfg = need(meta, "config", name);
    if (cfg.profile !== "tx") throw new UnsupportedError(`${name}: RLFC profile '${cfg.profile}' is not supported here (only tx); decode it with the Python library`);
    const scene = need(meta, "scene", name);
    this.file = file;
    this.rows = int(scene, "rows", "scene", 1, LIMITS.views);
    this.cols = int(scene, "cols", "scene", 1, LIMITS.views);
    const N0 = this.n0 = this.rows * this.cols;
    if (N0 > LIMITS.views) throw new FormatError(`${name}: ${N0} views exceed the limit`);
    this.layout = scene.layout === "posed" ? "posed" : "grid";
    const B = this.B = int(cfg, "block_size", "config", 8, 256);
    if (B % TB) throw new FormatError(`${name}: tx blocks must be multiples of 8 pixels, got ${B}`);
    this.H = int(cfg, "height", "config", 1, 1 << 20);
    this.W = int(cfg, "width", "config", 1, 1 << 20);
    const C = this.C = int(cfg, "channels", "config", 1, 4);
    this.P = int(cfg, "planes", "config", C, C);
    if (cfg.dtype !== "uint8" && cfg.dtype !== "uint16") throw new FormatError(`${name}: dtype must be uint8 or uint16`);
    this.dtype = cfg.dtype;
    this.peak = cfg.dtype === "uint8" ? 255 : 65535;
    const [Hp, Wp] = intList(cfg, "padded", "config", 2, 8, 1 << 20);
    const [nby, nbx] = intList(cfg, "blocks", "config", 2, 1, 1 << 20);
    if (Hp !== nby * B || Wp !== nbx * B || Hp < this.H || Wp < this.W || Hp - this.H >= B || Wp - this.W >= B) {
      throw new FormatError(`${name}: padded size ${Hp}x${Wp} does not match the blocks and the image size`);
    }
    if (Hp * Wp > LIMITS.viewPixels) throw new FormatError(`${name}: ${Hp}x${Wp} views exceed the limit`);
    Object.assign(this, { Hp, Wp, nby, nbx, tpb: B / TB, nt: (B / TB) ** 2, nby8: Hp / TB, nbx8: Wp / TB });
    const P = this.P;
    this.pcs = planeClasses(P);
    this.lo = this.pcs.map((c) => (c === 1 ? -this.peak : 0));
    this.hi = this.pcs.map(() => this.peak);
    this.flat = this.pcs.map((c) => (c === 1 ? 0 : (this.peak + 1) / 2));
    const tx = need(cfg, "tx", "config");
    const ver = int(tx, "version", "config.tx", 1, 6);
    if (ver === 1) throw new UnsupportedError(`${name}: tx version 1 files (float rANS tables) are not read here`);
    // version 3: each key-view block row is key_split streams of nbx / key_split blocks; version 4:
    // key_split >= 1, and a weighted prediction (gain, offset) per view and plane in tx.layout;
    // version 5: as 4, with a warp per view (rlfc/txwarp.py); version 6: as 5, with key_alpha (views
    // with alpha: a JPEG 2000 key's entry is its colour codestream, then its alpha plane, zlib)
    this.keySplit = ver >= 3 ? int(tx, "key_split", "config.tx", ver >= 4 ? 1 : 2, 1 << 16) : 1;
    if (nbx % this.keySplit) throw new FormatError(`${name}: config.tx.key_split ${this.keySplit} does not divide the ${nbx} blocks of a row`);
    this.keys = intList(tx, "keys", "config.tx", null, 0, N0 - 1);
    if (!this.keys.length || new Set(this.keys).size !== this.keys.length) throw new FormatError(`${name}: config.tx.keys is empty or repeats a view`);
    if (this.keys.length * Hp * Wp > LIMITS.openPixels) throw new FormatError(`${name}: the key views exceed the open-time limit`);
    this.nMaps = int(tx, "n_maps", "config.tx", 0, N0);
    const steps = need(tx, "step16", "config.tx");
    if (!Array.isArray(steps) || steps.length !== 2) throw new FormatError(`${name}: config.tx.step16 must hold 2 rows`);
    this.step16 = steps.map((r, i) => intList({ r }, "r", `config.tx.step16[${i}]`, P, 16, 1 << 24));
    const bp = need(tx, "bypass", "config.tx");
    if (!Array.isArray(bp) || bp.length !== P || !bp.every((x) => typeof x === "boolean")) throw new FormatError(`${name}: config.tx.bypass must be ${P} booleans`);
    this.bypass = bp;
    this.thumbStep = int(tx, "thumb_step16", "config.tx", 16, 1 << 24);
    const ic = need(tx, "intra_codec", "config.tx");
    if (ic !== "tx" && ic !== "j2k") throw new FormatError(`${name}: config.tx.intra_codec must be tx or j2k`);
    const keyImages = intList(tx, "key_images", "config.tx", null, 0, 1 << 30);
    if (ver >= 6 && P !== 2 && P !== 4) throw new FormatError(`${name}: tx version 6 (alpha streams) needs views with alpha`);
    const keyAlpha = ver >= 6 ? intList(tx, "key_alpha", "config.tx", null, 0, 1 << 30) : [];

    // tx.layout: positions (N0×2), refs (N0×4), weights (N0×4), cell (N0); version 4: then the
    // gains − 64 (N0×P) and the offsets (N0×P) of the weighted predictions; version 5: then each
    // view's warp (a, b, cx, cy)
    const count = N0 * 11 + (ver >= 4 ? 2 * N0 * P : 0) + (ver >= 5 ? 4 * N0 : 0);
    // the sections opening reads, fetched first: one range request per run of them in the file
    // (layout … thumbs, then the index), not one per section in turn
    await file.prefetch(["tx.layout", "tx.tables", "tx.maps", "tx.thumbs", "tx.index"]);
    const v = unvarints(await inflate(await file.read("tx.layout"), count * 10, "tx.layout"), count, "tx.layout");
    this.pos = v.slice(0, 2 * N0);
    this.refs = v.slice(2 * N0, 6 * N0);
    this.weights = v.slice(6 * N0, 10 * N0);
    this.cell = v.slice(10 * N0, 11 * N0);
    this._checkLayout(name);
    this.intra = new Uint8Array(N0);
    for (let i = 0; i < N0; i++) this.intra[i] = this.refs.slice(4 * i, 4 * i + 4).every((r) => r < 0) ? 1 : 0;
    this.wpGain = null;
    this._at = new Int32Array(4);              // _tapAt's result
    this.warp = null;
    if (ver >= 5) {
      const w = v.slice(11 * N0 + 2 * N0 * P, 11 * N0 + 2 * N0 * P + 4 * N0);
      for (let i = 0; i < 4 * N0; i++) {
        if (Math.abs(w[i]) > (i % 4 < 2 ? WARP_AB_MAX : WARP_C_MAX)) throw new FormatError(`${name}: a view's warp is out of range`);
      }
      if (w.some((x) => x !== 0)) this.warp = Float64Array.from(w);
    }
    if (ver >= 4) {
      this.wpGain = Int32Array.from(v.slice(11 * N0, 11 * N0 + N0 * P), (g) => g + 64);
      this.wpOff = Int32Array.from(v.slice(11 * N0 + N0 * P, 11 * N0 + 2 * N0 * P));
      for (let i = 0; i < N0 * P; i++) {
        const g = this.wpGain[i], o = this.wpOff[i];
        if (g < 32 || g > 96) throw new FormatError(`${name}: a weighted prediction's gain is outside 32..96 (1/64)`);
        if (Math.abs(o) > (1 << 18)) throw new FormatError(`${name}: a weighted prediction's offset is out of range`);
        if (this.intra[Math.floor(i / P)] && (g !== 64 || o !== 0)) throw new FormatError(`${name}: an intra view has a weighted prediction`);
      }
    }
    this.keySlot = new Int32Array(N0).fill(-1);
    this.keys.forEach((k, i) => { this.keySlot[k] = i; });
    const intraKeys = this.keys.filter((k) => this.intra[k]);
    const want = ic === "j2k" ? intraKeys.length : 0;
    if (keyImages.length !== want) throw new FormatError(`${name}: key_images lists ${keyImages.length} images, expected ${want}`);
    this.imgOf = new Map();
    this.alphaOf = new Map();
    if (ver >= 6) {
      if (ic !== "j2k" || !keyImages.some((n) => n > 0)) throw new FormatError(`${name}: tx version 6 (alpha streams) needs JPEG 2000 key views`);
      if (keyAlpha.length !== keyImages.length) throw new FormatError(`${name}: key_alpha lists ${keyAlpha.length} streams, expected ${keyImages.length}`);
      keyImages.forEach((n, i) => {
        const a = keyAlpha[i];
        if ((n === 0 && a !== 0) || (n > 0 && !(a > 0 && a < n))) throw new FormatError(`${name}: an alpha stream of ${a} bytes does not fit its image entry of ${n}`);
        if (n > 0) this.alphaOf.set(intraKeys[i], a);
      });
    }
    if (ic === "j2k") intraKeys.forEach((k, i) => { if (keyImages[i] > 0) this.imgOf.set(k, keyImages[i]); });
    this.codedKeys = this.keys.filter((k) => !this.imgOf.has(k));

    this.tables = await readTables(await file.read("tx.tables"), N_CTX, ALPHABET, "tx.tables");
    await this._readMaps(await file.read("tx.maps"));
    const intraCoded = this.codedKeys.filter((k) => this.intra[k]);
    this.thumbOf = new Map(intraCoded.map((k, i) => [k, i]));
    this.thumbs = await this._readThumbs(await file.read("tx.thumbs"), intraCoded.length);
    for (const th of this.thumbs) {                        // a level is a rounded block mean over the step
      for (const t of th) {
        if (Math.abs(t) * this.thumbStep > 16 * (this.peak + 1) + this.thumbStep) {
          throw new FormatError(`${name}: tx.thumbs: a thumbnail level times the thumbnail step exceeds the sample range`);
        }
      }
    }
    await this._readIndex(await file.read("tx.index"));
    let imgOff = 0;
    this.imgRange = new Map();
    for (const k of this.keys) {
      if (this.imgOf.has(k)) { this.imgRange.set(k, [imgOff, imgOff + this.imgOf.get(k)]); imgOff += this.imgOf.get(k); }
    }
    if (file.info("tx.keyimg").length !== imgOff) throw new FormatError(`${name}: section 'tx.keyimg' has ${file.info("tx.keyimg").length} bytes, the header says ${imgOff}`);
    this.keyImage = keyImage;
    // key views are decoded when a view first needs them (_key), as the Python decoder decodes
    // theirs on demand: an open reads no key view, a first frame only the keys in its views' cones
    this.keyPlanes = new Array(this.keys.length).fill(null);
    this._keyPending = new Array(this.keys.length).fill(null);
    return this;
  }

  /** Planes of key view k, decoded on its first use (its references first); concurrent callers
   *  share one decode. A damaged key view's error reaches every caller. */
  _key(k) {
    const s = this.keySlot[k];
    if (this.keyPlanes[s]) return Promise.resolve(this.keyPlanes[s]);
    if (!this._keyPending[s]) {
      this._keyPending[s] = (async () => {
        await this._refsOf(k);
        this.keyPlanes[s] = await this._decodeKey(k);
        return this.keyPlanes[s];
      })();
      this._keyPending[s].catch(() => { this._keyPending[s] = null; });   // (a later call tries again)
    }
    return this._keyPending[s];
  }

  /** Every key view that view v is predicted from, decoded. */
  async _refsOf(v) {
    for (let j = 0; j < MAX_REFS; j++) {
      const r = this.refs[4 * v + j];
      if (r >= 0) await this._key(r);
    }
  }

  /** Key views decoded so far (of this.keys.length). */
  keysDecoded() { return this.keyPlanes.filter((p) => p !== null).length; }

  /** Every key view decoded now (what an open did before stop 85; Python's decode_keys()). */
  async decodeKeys() { for (const k of this.keys) await this._key(k); }

  _checkLayout(name) {
    const N0 = this.n0, order = new Int32Array(N0).fill(-1);
    this.keys.forEach((k, i) => { order[k] = i; });
    for (const [arr, lo, hi, what] of [[this.pos, -(1 << 16), 1 << 16, "positions"], [this.refs, -1, N0 - 1, "refs"],
      [this.weights, 0, 64, "weights"], [this.cell, -1, N0, "cell"]]) {
      for (const x of arr) if (x < lo || x > hi) throw new FormatError(`${name}: tx.layout ${what} out of range`);
    }
    for (let v = 0; v < N0; v++) {
      const r = [], ws = this.weights.slice(4 * v, 4 * v + 4);
      let wsum = 0;
      for (let j = 0; j < 4; j++) {
        const rj = this.refs[4 * v + j];
        if (rj >= 0) r.push(rj); else if (ws[j] > 0) throw new FormatError(`${name}: a weight is given to a missing reference`);
        wsum += ws[j];
      }
      if (new Set(r).size !== r.length) throw new FormatError(`${name}: view ${v} lists a reference twice`);
      if (!r.length) {
        if (order[v] < 0) throw new FormatError(`${name}: view ${v} has no references but is not a key view`);
        if (this.cell[v] !== -1) throw new FormatError(`${name}: intra view ${v} must have cell -1`);
        continue;
      }
      if (wsum !== 64) throw new FormatError(`${name}: blend weights of view ${v} do not sum to 64`);
      if (r.some((x) => order[x] < 0)) throw new FormatError(`${name}: view ${v} references a view that is not a key view`);
      if (order[v] >= 0 && r.some((x) => order[x] >= order[v])) throw new FormatError(`${name}: key view ${v} references a key decoded after it`);
      if (!(this.cell[v] >= 0 && this.cell[v] < this.nMaps)) throw new FormatError(`${name}: view ${v} has map ${this.cell[v]} of ${this.nMaps}`);
    }
  }

  /** The maps section's header and tables; the maps themselves are decoded when a view first
   *  needs one (needMap), as the Python decoder does: an open decodes none of them. */
  async _readMaps(raw) {
    const what = "tx.maps", nMaps = this.nMaps, nloc = this.nby8 * this.nbx8;
    if (!raw.length || raw[0] < 1 || raw[0] > 3) throw new FormatError(`${what}: unknown maps version`);
    if (raw[0] === 1) throw new UnsupportedError(`${what}: version 1 maps (float tables) are not read here`);
    let p = 1, cnt = 0;
    while (cnt < nMaps + 2) {
      if (p >= raw.length) throw new FormatError(`${what}: truncated stream lengths`);
      if (raw[p++] < 128) cnt++;
    }
    const lens = unvarints(raw.subarray(1, p), nMaps + 2, what);
    if (lens.some((x) => x < 0) || p + lens.reduce((a, b) => a + b, 0) !== raw.length) throw new FormatError(`${what}: stream lengths do not add up to the section`);
    const at = [p + lens[0]];                          // where the shared map's and each map's streams start
    for (let i = 1; i < nMaps + 2; i++) at.push(at[i - 1] + lens[i]);
    const tables = await readTables(raw.subarray(p, at[0]), raw[0] >= 3 ? 35 : 33, 64, what);
    this._maps = { raw, ver: raw[0], at, tables, base: null, done: new Uint8Array(nMaps) };
    this.disp = new Int32Array(nMaps * nloc);
    this.modes = new Int32Array(nMaps * nloc);
  }

  /** Decode map m (and the shared map, the first time) where not decoded yet: its disparities
   *  (this.disp) and modes (this.modes), each checked (a mode past a view's references, for
   *  every view that reads the map, is a FormatError). */
  needMap(m) {
    const M = this._maps;
    if (M.done[m]) return;
    const what = "tx.maps", ny = this.nby8, nx = this.nbx8, nloc = ny * nx, R = 31, { raw, at, tables } = M;
    // version 3: each escape digit position has its own context (32 + position); version 2: all in 32
    const digitCtx = (i) => (M.ver >= 3 ? 32 + i : 32);
    const unesc = (d, s) => {
      if (s > 2 * R) throw new FormatError(`${what}: undefined map symbol ${s}`);
      if (s !== 0 && s !== 2 * R) return s - R;
      let x = 0;
      for (let i = 0; i < 3; i++) x = x * 64 + d.get(digitCtx(i));
      return (R + x) * (s === 2 * R ? 1 : -1);
    };
    if (M.base === null) {
      const base = new Float64Array(nloc);
      const d = new Rans(raw, at[0], at[1], tables, what);
      for (let i = 0; i < nloc; i++) {
        const y = Math.floor(i / nx), x = i % nx;
        const a = x ? base[i - 1] : (y ? base[i - nx] : 0);
        const b = y ? base[i - nx] : a;
        const c = x && y ? base[i - nx - 1] : (y ? b : a);
        const act = a === c && b === c ? 0 : (Math.abs(a - c) + Math.abs(b - c) <= 16 ? 1 : 2);
        const e = unesc(d, d.get(act));
        const lo = a < b ? a : b, hi = a < b ? b : a;              // the median of a, b, a + b − c
        base[i] = (i === 0 ? 0 : c >= hi ? lo : c <= lo ? hi : a + b - c) + e;
      }
      if (!d.done(at[1])) throw new FormatError(`${what}: the shared map's stream is malformed`);
      M.base = base;
    }
    const d = new Rans(raw, at[1 + m], at[2 + m], tables, what);
    const corr = new Float64Array(nloc), mo = new Int32Array(nloc);
    for (let i = 0; i < nloc; i++) {
      const y = Math.floor(i / nx), x = i % nx;
      const left = x && corr[i - 1] !== 0 ? 1 : 0, up = y && corr[i - nx] !== 0 ? 1 : 0;
      corr[i] = unesc(d, d.get(3 + left + 2 * up));
    }
    for (let i = 0; i < nloc; i++) {
      const y = Math.floor(i / nx), x = i % nx;
      const ml = x ? Math.min(mo[i - 1], 4) : 0, mu = y ? Math.min(mo[i - nx], 4) : 0;
      const s = d.get(7 + 5 * ml + mu);
      if (s >= 1 + MAX_REFS) throw new FormatError(`${what}: a prediction mode is out of range`);
      mo[i] = s;
    }
    if (!d.done(at[2 + m])) throw new FormatError(`${what}: a map stream is malformed`);
    for (let i = 0; i < nloc; i++) {
      const v = M.base[i] + corr[i];
      if (Math.abs(v) > 1 << 20) throw new FormatError(`${what}: a disparity is out of range`);
    }
    let top = 0;
    for (let i = 0; i < nloc; i++) if (mo[i] > top) top = mo[i];
    for (let v = 0; v < this.n0; v++) {
      if (this.cell[v] !== m) continue;
      const nrefs = this.refs.slice(4 * v, 4 * v + 4).filter((r) => r >= 0).length;
      if (top > nrefs) throw new FormatError(`${this.file.name}: tx.maps selects a reference view ${v} does not have`);
    }
    for (let i = 0; i < nloc; i++) {
      this.disp[m * nloc + i] = M.base[i] + corr[i];
      this.modes[m * nloc + i] = mo[i];
    }
    M.done[m] = 1;
  }

  async _readThumbs(data, n) {
    const ny = this.nby8, nx = this.nbx8, P = this.P, count = n * ny * nx * P;
    const d = unvarints(await inflate(data, count * 10, "tx.thumbs"), count, "tx.thumbs");
    const out = [];
    for (let i = 0; i < n; i++) {
      const t = new Float64Array(ny * nx * P);
      const o = i * ny * nx * P;
      for (let x = 0; x < nx; x++) for (let p = 0; p < P; p++) t[x * P + p] = d[o + x * P + p] + (x ? t[(x - 1) * P + p] : 0);
      for (let y = 1; y < ny; y++) for (let j = 0; j < nx * P; j++) t[y * nx * P + j] = d[o + y * nx * P + j] + t[(y - 1) * nx * P + j];
      for (const v of t) if (Math.abs(v) > 1 << 24) throw new FormatError("tx.thumbs: a thumbnail level is out of range");
      out.push(t);
    }
    return out;
  }

  async _readIndex(data) {
    const ks = this.keySplit, what = "tx.index", nk = this.codedKeys.length * this.nby * ks, N0 = this.n0, nloc = this.nby * this.nbx;
    const nb = Math.ceil(N0 * nloc / 8);
    const raw = await inflate(data, (nk + N0 * nloc) * 10 + nb, what);
    let p = 0, cnt = 0;
    while (cnt < nk) {
      if (p >= raw.length) throw new FormatError(`${what}: too short for ${nk} key row lengths`);
      if (raw[p++] < 128) cnt++;
    }
    const keyLen = unvarints(raw.subarray(0, p), nk, what);
    if (raw.length < p + nb) throw new FormatError(`${what}: too short for the coded-block bitmap`);
    this.coded = new Uint8Array(N0 * nloc);
    let nCoded = 0;
    for (let i = 0; i < N0 * nloc; i++) {
      const bit = (raw[p + (i >> 3)] >> (i & 7)) & 1;
      if (bit && this.keySlot[Math.floor(i / nloc)] >= 0) throw new FormatError(`${what}: the bitmap marks a block of a key view`);
      this.coded[i] = bit;
      nCoded += bit;
    }
    const lens = unvarints(raw.subarray(p + nb), nCoded, what);
    for (const x of keyLen.concat(lens)) if (x < 3 || x > 1 << 28) throw new FormatError(`${what}: a stream length is out of range`);
    // offsets: key rows (coded keys × rows × segments), then block streams location-major, views ascending
    let off = 0;
    this.keyRow = new Map();
    this.codedKeys.forEach((k, i) => {
      const r = [];
      for (let y = 0; y < this.nby * ks; y++) { const n = keyLen[i * this.nby * ks + y]; r.push([off, off + n]); off += n; }
      this.keyRow.set(k, r);
    });
    this.start = new Float64Array(N0 * nloc).fill(-1);
    this.end = new Float64Array(N0 * nloc).fill(-1);
    let j = 0;
    for (let loc = 0; loc < nloc; loc++) {
      for (let v = 0; v < N0; v++) {
        if (!this.coded[v * nloc + loc]) continue;
        this.start[v * nloc + loc] = off; off += lens[j++]; this.end[v * nloc + loc] = off;
      }
    }
    if (this.file.info("tx.blocks").length !== off + 8) throw new FormatError(`tx.blocks has ${this.file.info("tx.blocks").length} bytes, the index says ${off + 8}`);
  }

  /** Whether views are predicted on WebAssembly SIMD here (PredictKernel), not in the loops. */
  predictsOnWasm() {
    if (!PredictKernel.useWasm) return false;
    if (this._kernelP === undefined) this._kernelP = PredictKernel.create(ZIGZAG, T8F, BAND8);
    return this._kernelP !== null;
  }

  /** Where key view k's taps for the tb at pixel (y0, x0) of view v start, at disparity d (1/16
   *  px per view step): this._at = [ry, rx, fy, fx] (the window's top-left pixel, then 1/16 px). */
  _tapAt(v, k, d, y0, x0) {
    let Y = 16 * y0 + d * (this.pos[2 * v] - this.pos[2 * k]);
    let X = 16 * x0 + d * (this.pos[2 * v + 1] - this.pos[2 * k + 1]);
    if (this.warp) {                            // per-view warps: the pair's offset at the tb's centre
      const W = this.warp, X2 = 2 * x0 + 7, Y2 = 2 * y0 + 7;
      const da = W[4 * k] - W[4 * v], db = W[4 * k + 1] - W[4 * v + 1];
      const dcx = W[4 * k + 2] - W[4 * v + 2], dcy = W[4 * k + 3] - W[4 * v + 3];
      X += Math.floor((da * X2 - db * Y2 + 512 * dcx + 4096) / 8192);     // (exact: below 2^31)
      Y += Math.floor((db * X2 + da * Y2 + 512 * dcy + 4096) / 8192);
    }
    const at = this._at;
    at[0] = Y >> 4; at[1] = X >> 4; at[2] = Y & 15; at[3] = X & 15;
  }

  /** Prediction of the 8×8 tb at pixel (y0, x0) of view v, written where it lies in img (Hp·Wp·P).
   *  Each tap ((a(16−fx) + b·fx)(16−fy) + (c(16−fx) + e·fx)·fy + 128) >> 8 is summed as
   *  a·w00 + b·w01 + c·w10 + e·w11 + 128 (the same integer); a window inside the key view reads
   *  its taps without clamping. */
  _predictTb(v, y0, x0, img) {
    const P = this.P, Hp = this.Hp, Wp = this.Wp;
    const loc8 = (y0 >> 3) * this.nbx8 + (x0 >> 3);
    const cell = this.cell[v];
    const d = this.disp[cell * this.nby8 * this.nbx8 + loc8], mode = this.modes[cell * this.nby8 * this.nbx8 + loc8];
    const n = 64 * P;
    if (!this._acc || this._acc.length !== n) this._acc = new Int32Array(n);
    const acc = this._acc, at = this._at;
    acc.fill(0);
    for (let j = 0; j < MAX_REFS; j++) {
      const k = this.refs[4 * v + j];
      if (k < 0) continue;
      const w = mode === 0 ? this.weights[4 * v + j] : (mode - 1 === j ? 64 : 0);
      if (!w) continue;
      const kp = this.keyPlanes[this.keySlot[k]];
      this._tapAt(v, k, d, y0, x0);
      const ry = at[0], rx = at[1], fy = at[2], fx = at[3];
      const w00 = (16 - fx) * (16 - fy), w01 = fx * (16 - fy), w10 = (16 - fx) * fy, w11 = fx * fy;
      const inside = ry >= 0 && ry + 8 <= Hp - 1 && rx >= 0 && rx + 8 <= Wp - 1;
      for (let y = 0; y < 8; y++) {
        const ya = inside ? (ry + y) * Wp : Math.min(Math.max(ry + y, 0), Hp - 1) * Wp;
        const yb = inside ? ya + Wp : Math.min(Math.max(ry + y + 1, 0), Hp - 1) * Wp;
        for (let x = 0; x < 8; x++) {
          const xa = inside ? rx + x : Math.min(Math.max(rx + x, 0), Wp - 1);
          const xb = inside ? xa + 1 : Math.min(Math.max(rx + x + 1, 0), Wp - 1);
          const i00 = (ya + xa) * P, i01 = (ya + xb) * P, i10 = (yb + xa) * P, i11 = (yb + xb) * P, o = (y * 8 + x) * P;
          for (let p = 0; p < P; p++) {
            acc[o + p] += w * ((kp[i00 + p] * w00 + kp[i01 + p] * w01 + kp[i10 + p] * w10 + kp[i11 + p] * w11 + 128) >> 8);
          }
        }
      }
    }
    for (let y = 0; y < 8; y++) {
      const o = ((y0 + y) * Wp + x0) * P, a = y * 8 * P;
      for (let i = 0; i < 8 * P; i++) img[o + i] = (acc[a + i] + 32) >> 6;
    }
    if (this.wpGain) this._weighted(v, img, y0, x0, 8, 8);
  }

  /** Weighted prediction of view v on the h×w pixels at (y0, x0) of img: ((p·g + 32) >> 6) + o,
   *  clipped to the plane's bounds. */
  _weighted(v, img, y0, x0, h, w) {
    const P = this.P, Wp = this.Wp;
    for (let p = 0; p < P; p++) {
      const g = this.wpGain[v * P + p], off = this.wpOff[v * P + p], lo = this.lo[p], hi = this.hi[p];
      if (g === 64 && off === 0) continue;
      for (let y = y0; y < y0 + h; y++) {
        const o = (y * Wp + x0) * P + p;
        for (let x = 0; x < w; x++) {
          const q = ((img[o + x * P] * g + 32) >> 6) + off;
          img[o + x * P] = q < lo ? lo : q > hi ? hi : q;
        }
      }
    }
  }

  /** Add the parsed residual of tb t (mode) to the prediction at (y0, x0) in img, clipped. */
  _addResidual(img, y0, x0, parsed, t, isKey) {
    const P = this.P, Wp = this.Wp, mode = parsed.modes[t];
    const r = RES_OUT;                         // skip tbs: the prediction, clipped
    r.fill(0);
    for (let p = 0; p < P; p++) {
      if (mode !== MODE_SKIP) residual(parsed.levels, (t * P + p) * 64, this.step16[isKey ? 0 : 1][p], this.bypass[p], r);
      const lo = this.lo[p], hi = this.hi[p], flat = this.flat[p];
      for (let y = 0; y < 8; y++) {
        for (let x = 0; x < 8; x++) {
          const i = ((y0 + y) * Wp + x0 + x) * P + p;
          const v = (mode === MODE_INTRA ? flat : img[i]) + r[y * 8 + x];
          img[i] = v < lo ? lo : v > hi ? hi : v;
        }
      }
    }
  }

  async _decodeKey(k) {
    const P = this.P, Hp = this.Hp, Wp = this.Wp;
    if (this.imgOf.has(k)) {
      if (!this.keyImage) throw new UnsupportedError(`${this.file.name}: key view ${k} is JPEG 2000 and no JPEG 2000 decoder is loaded`);
      const [a, b] = this.imgRange.get(k);
      const entry = await this.file.read("tx.keyimg", a, b);
      if (!this.alphaOf.has(k)) return toPlanes(await this.keyImage(entry, Hp, Wp, this.C, this.dtype), Hp * Wp, this.C);
      // version 6: the colour channels' codestream, then the alpha plane (zlib, little-endian samples)
      const cut = entry.length - this.alphaOf.get(k), C = this.C, n = Hp * Wp;
      const col = await this.keyImage(entry.subarray(0, cut), Hp, Wp, C - 1, this.dtype);
      const bytes = this.dtype === "uint8" ? 1 : 2;
      const raw = await inflate(entry.subarray(cut), n * bytes, `${this.file.name}: key view ${k}'s alpha stream`);
      if (raw.length !== n * bytes) throw new FormatError(`${this.file.name}: key view ${k}'s alpha stream holds ${raw.length} bytes, expected ${n * bytes}`);
      const px = bytes === 1 ? new Uint8Array(n * C) : new Uint16Array(n * C);
      for (let i = 0; i < n; i++) {
        for (let c = 0; c < C - 1; c++) px[i * C + c] = col[i * (C - 1) + c];
        px[i * C + C - 1] = bytes === 1 ? raw[i] : raw[2 * i] | (raw[2 * i + 1] << 8);
      }
      return toPlanes(px, n, C);
    }
    const img = new Int32Array(Hp * Wp * P);
    if (this.intra[k]) {                                   // the thumbnail, upsampled
      const th = this.thumbs[this.thumbOf.get(k)], ty = this.nby8, tx = this.nbx8;
      const tv = th.map((t) => Math.floor((t * this.thumbStep + 8) / 16));
      const ax = (n, m) => {
        const i0 = new Int32Array(n), i1 = new Int32Array(n), f = new Int32Array(n);
        for (let y = 0; y < n; y++) {
          const q = 2 * y - 7;
          i0[y] = Math.min(Math.max(q >> 4, 0), m - 1); i1[y] = Math.min(Math.max((q >> 4) + 1, 0), m - 1); f[y] = q & 15;
        }
        return [i0, i1, f];
      };
      const [ya, yb, fy] = ax(Hp, ty), [xa, xb, fx] = ax(Wp, tx);
      for (let y = 0; y < Hp; y++) {
        for (let x = 0; x < Wp; x++) {
          for (let p = 0; p < P; p++) {
            const a = tv[(ya[y] * tx + xa[x]) * P + p], b = tv[(ya[y] * tx + xb[x]) * P + p];
            const c = tv[(yb[y] * tx + xa[x]) * P + p], e = tv[(yb[y] * tx + xb[x]) * P + p];
            img[(y * Wp + x) * P + p] = Math.floor(((a * (16 - fx[x]) + b * fx[x]) * (16 - fy[y]) + (c * (16 - fx[x]) + e * fx[x]) * fy[y] + 128) / 256);
          }
        }
      }
    }
    const rows = this.keyRow.get(k), ks = this.keySplit, sb = this.nbx / ks, jobs = [];
    // the key's rows lie one after another: their missing chunks first, in one request per run
    // of them (then each row's read is served from the cache, instead of a request per row in turn)
    await this.file.read("tx.blocks", rows[0][0], rows[rows.length - 1][1]);
    for (let by = 0; by < this.nby; by++) {
      for (let sg = 0; sg < ks; sg++) {                  // a row's streams: sb blocks each, in order
        const [a, b] = rows[by * ks + sg];
        const blocks = [];
        for (let j = 0; j < sb; j++) blocks.push(by * this.nbx + sg * sb + j);
        jobs.push({ data: await this.file.read("tx.blocks", a, b), blocks, kind: this.intra[k], what: `key view ${k} row ${by}` });
      }
    }
    this._reconstruct(k, img, !this.intra[k], jobs, true);
    return img;
  }

  /** View v's planes in img: its prediction (where `predicted`; else img as it is), then the
   *  residual streams of `jobs` ({data, blocks: their block locations in order, kind, what};
   *  `key`: a key view's streams and steps) added: on WebAssembly SIMD (predict.js) where this
   *  environment has it, else in the loops; the same planes. */
  _reconstruct(v, img, predicted, jobs, key) {
    const B = this.B, tpb = this.tpb, nt = this.nt;
    const pos = (blocks) => {                          // each tb's pixel (y, x), block by block
      const ys = new Int32Array(blocks.length * nt), xs = new Int32Array(blocks.length * nt);
      blocks.forEach((l, j) => {
        const y = Math.floor(l / this.nbx) * B, x = (l % this.nbx) * B;
        for (let t = 0; t < nt; t++) { ys[j * nt + t] = y + Math.floor(t / tpb) * 8; xs[j * nt + t] = x + (t % tpb) * 8; }
      });
      return [ys, xs];
    };
    if (predicted) this.needMap(this.cell[v]);
    const kp = this.predictsOnWasm() ? this._kernelP : null;
    if (kp && kp.begin(this, v, predicted, img, jobs.reduce((m, j) => Math.max(m, j.data.length), 0))) {
      if (predicted && this.wpGain) this._weighted(v, kp.planes, 0, 0, this.Hp, this.Wp);
      for (const { data, blocks, kind, what } of jobs) {
        const [code, modes] = kp.parse(data, blocks.length * nt, kind, key ? 1 : 0);
        if (code) {
          kp.end(null);
          throw new FormatError(`${what}: ${PARSE_ERRORS[code]}`);
        }
        kp.residual(modes, ...pos(blocks), key);
      }
      kp.end(img);
      return;
    }
    if (predicted) for (let y0 = 0; y0 < this.Hp; y0 += 8) for (let x0 = 0; x0 < this.Wp; x0 += 8) this._predictTb(v, y0, x0, img);
    for (const { data, blocks, kind, what } of jobs) {
      const n = blocks.length * nt, parsed = parseBlock(data, 0, data.length, this.tables, n, this.pcs, kind, key ? 1 : 0, what);
      const [ys, xs] = pos(blocks);
      for (let t = 0; t < n; t++) this._addResidual(img, ys[t], xs[t], parsed, t, key);
    }
  }

  /** Planes (Int32Array Hp·Wp·P) of view v (row·cols + col); level 1 = prediction only. */
  async decodeView(v, level = 0) {
    if (!Number.isInteger(v) || v < 0 || v >= this.n0) throw new LfcError(`view ${v} is not in 0..${this.n0 - 1}`);
    if (level !== 0 && level !== 1) throw new LfcError(`level ${level} is not 0 or 1 (0 = full quality, 1 = prediction only)`);
    if (this.keySlot[v] >= 0) return this._key(v);
    await this._refsOf(v);
    const nloc = this.nby * this.nbx, jobs = [];
    if (level === 0) {
      const locs = [];
      for (let l = 0; l < nloc; l++) if (this.coded[v * nloc + l]) locs.push(l);
      if (locs.length) {                        // fetch the view's streams' span once (merged chunks)
        await this.file.read("tx.blocks", this.start[v * nloc + locs[0]], this.end[v * nloc + locs[locs.length - 1]]);
      }
      for (const l of locs) {
        const data = await this.file.read("tx.blocks", this.start[v * nloc + l], this.end[v * nloc + l]);
        jobs.push({ data, blocks: [l], kind: 0, what: `view ${v} block ${l}` });
      }
    }
    const img = new Int32Array(this.Hp * this.Wp * this.P);
    this._reconstruct(v, img, true, jobs, false);
    return img;
  }

  /** Pixels (H·W·C, Uint8Array or Uint16Array) of planes. */
  pixels(planes) { return fromPlanes(planes, this.Hp, this.Wp, this.H, this.W, this.C, this.peak); }
}

/** (n, C) pixels → planes (YCoCg-R for RGB; grey and alpha pass through). */
export function toPlanes(px, n, C) {
  const out = new Int32Array(n * C);
  for (let i = 0; i < n; i++) {
    if (C >= 3) {
      const r = px[i * C], g = px[i * C + 1], b = px[i * C + 2];
      const co = r - b, t = b + (co >> 1), cg = g - t;
      out[i * C] = t + (cg >> 1); out[i * C + 1] = co; out[i * C + 2] = cg;
      if (C === 4) out[i * C + 3] = px[i * C + 3];
    } else for (let c = 0; c < C; c++) out[i * C + c] = px[i * C + c];
  }
  return out;
}

/** Planes (Hp·Wp·C) → pixels (H·W·C) clipped to [0, peak] (inverse YCoCg-R). */
export function fromPlanes(planes, Hp, Wp, H, W, C, peak) {
  const out = peak > 255 ? new Uint16Array(H * W * C) : new Uint8Array(H * W * C);
  const clip = (v) => (v < 0 ? 0 : v > peak ? peak : v);
  for (let y = 0; y < H; y++) {
    for (let x = 0; x < W; x++) {
      const i = (y * Wp + x) * C, o = (y * W + x) * C;
      if (C >= 3) {
        const Y = planes[i], co = planes[i + 1], cg = planes[i + 2];
        const t = Y - (cg >> 1), g = cg + t, b = t - (co >> 1), r = b + co;
        out[o] = clip(r); out[o + 1] = clip(g); out[o + 2] = clip(b);
        if (C === 4) out[o + 3] = clip(planes[i + 3]);
      } else for (let c = 0; c < C; c++) out[o + c] = clip(planes[i + c]);
    }
  }
  return out;
}

/** Open a decoder on a source (RangeSource / BufferSource). `keyImage(bytes, Hp, Wp, C, dtype)`
 *  decodes a JPEG 2000 key view to pixels (optional; see openjpeg.js). */
export async function openDecoder(source, { name = "file", keyImage = null, chunkBudget = Infinity } = {}) {
  const file = await LfcFile.open(source, name, chunkBudget);
  return new TxDecoder().init(file, keyImage);
}
