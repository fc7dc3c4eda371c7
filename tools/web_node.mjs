// The browser viewer's modules under Node, for the tools and benchmarks that run them
// (web_decode.mjs, web_bench.mjs, web_render_ab.mjs, web_blend_kernel.mjs, ...): where they are,
// the JPEG 2000 key-view decoder the page uses (OpenJPEG/wasm) and a decoder opened on a file.
// Importing this module silences console.log (OpenJPEG prints progress lines while it decodes):
// print results with `say`.
import fs from "fs";
import path from "path";
import { createRequire } from "module";
import { fileURLToPath } from "url";

/** formats/web of this checkout. */
export const WEB = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "../formats/web");
/** console.log as it was before this module silenced it. */
export const say = console.log.bind(console);
console.log = () => {};
const { makeKeyImage } = await import(path.join(WEB, "openjpeg.js"));
const factory = createRequire(import.meta.url)(path.join(WEB, "vendor/openjpegwasm_decode.js"));
/** OpenJPEG/wasm's key-view decoder, for openDecoder's `keyImage`. */
export const keyImage = await makeKeyImage(() => factory({ print: () => {}, printErr: () => {} }));
const LFC = await import(path.join(WEB, "lfc.js"));

/** A TxDecoder of `file` (a path, or its bytes) through lfc.js: this checkout's, or `lfc` (another
 *  checkout's module); `name` and `chunkBudget` as openDecoder's. */
export function openFile(file, { lfc = LFC, name = "file", chunkBudget = Infinity } = {}) {
  const bytes = typeof file === "string" ? fs.readFileSync(file) : file;
  return lfc.openDecoder(new lfc.BufferSource(bytes), { name, keyImage, chunkBudget });
}
