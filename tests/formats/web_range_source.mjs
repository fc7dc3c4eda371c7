// Test helper: lfc.js's RangeSource over a fake fetch that serves FILE's bytes (206 with
// Content-Range and ETag; with "nototal", a Content-Range without the size, as a cross-origin
// server that does not expose it looks to a page): opens a decoder, decodes view 0, and prints one
// JSON line {calls: [method Range...], same (view 0's planes those of a BufferSource), size, n}.
// node web_range_source.mjs FILE [nototal]
import fs from "fs";
import path from "path";
import { WEB, keyImage, say } from "../../tools/web_node.mjs";

const lfc = await import(path.join(WEB, "lfc.js"));
const [file, mode] = process.argv.slice(2);
const bytes = new Uint8Array(fs.readFileSync(file));
const calls = [];
async function fakeFetch(url, opts = {}) {
  const method = opts.method || "GET", range = (opts.headers || {}).Range;
  calls.push(`${method} ${range || ""}`.trim());
  const headers = new Headers({ ETag: '"v1"', "Accept-Ranges": "bytes" });
  if (method === "HEAD") {
    headers.set("Content-Length", String(bytes.length));
    return new Response(null, { status: 200, headers });
  }
  const [a, b] = range.slice(6).split("-").map(Number), end = Math.min(b, bytes.length - 1);
  headers.set("Content-Range", mode === "nototal" ? `bytes ${a}-${end}/*` : `bytes ${a}-${end}/${bytes.length}`);
  return new Response(bytes.slice(a, end + 1), { status: 206, headers });
}
const src = new lfc.RangeSource("http://x/f.lfc", fakeFetch);
const dec = await lfc.openDecoder(src, { name: "f", keyImage });
const hash = (p) => p.reduce((h, x) => (h * 31 + x) >>> 0, 7);
const planes = await dec.decodeView(0);
const local = await (await lfc.openDecoder(new lfc.BufferSource(bytes), { name: "f", keyImage })).decodeView(0);
say(JSON.stringify({ calls, same: hash(planes) === hash(local), size: await src.size(), n: bytes.length }));
