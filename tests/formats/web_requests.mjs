// Test helper: the range reads (requests, over HTTP) the browser viewer's decoder makes to open a
// tx .lfc file and then to decode each key view in coding order (its references decoded before),
// through a BufferSource that counts them: one JSON line {open, keys: [{key, transform, requests}]}.
// node web_requests.mjs FILE
import fs from "fs";
import path from "path";
import { WEB, keyImage, say } from "../../tools/web_node.mjs";

const lfc = await import(path.join(WEB, "lfc.js"));
const [file] = process.argv.slice(2);
const src = new lfc.BufferSource(new Uint8Array(fs.readFileSync(file)));
const dec = await lfc.openDecoder(src, { name: path.basename(file), keyImage, chunkBudget: Infinity });
const open = src.requests;
const keys = [];
for (const k of dec.keys) {
  const before = src.requests;
  await dec._key(k);
  keys.push({ key: k, transform: !dec.imgOf.has(k), requests: src.requests - before });
}
say(JSON.stringify({ open, keys }));
