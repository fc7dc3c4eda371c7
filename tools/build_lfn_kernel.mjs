// Assemble formats/web/lfn_kernel.wat (WebAssembly text, SIMD) with wabt and write
// formats/web/lfn_kernel.js: the module's bytes as base64 and a loader (run by tools/build_web.sh;
// `node tools/build_lfn_kernel.mjs --check` exits 1 where the committed file differs).
import fs from "fs";
import path from "path";
import { fileURLToPath } from "url";

const web = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "../formats/web");
const { default: wabtInit } = await import(path.join(web, "node_modules/wabt/index.js"));
const wabt = await wabtInit();
const wat = fs.readFileSync(path.join(web, "lfn_kernel.wat"), "utf8");
const mod = wabt.parseWat("lfn_kernel.wat", wat, { simd: true });
mod.validate();
const { buffer } = mod.toBinary({});
if (buffer.length > 4096) {       // browsers refuse to compile larger modules synchronously on a page's thread
  console.error(`lfn_kernel.wat builds to ${buffer.length} bytes: over 4 KB, lfn_kernel.js would need an asynchronous compile`);
  process.exit(1);
}
const b64 = Buffer.from(buffer).toString("base64");
const js = `// lfn_kernel.js — generated from lfn_kernel.wat by tools/build_lfn_kernel.mjs (wabt); do not edit.
// The WebAssembly module of the network renderer's dense layers (${buffer.length} bytes), compiled once
// (synchronously: it is small); null where the environment has no WebAssembly SIMD.
const WASM = "${b64}";

let compiled;
export function kernelModule() {
  if (compiled === undefined) {
    try {
      compiled = new WebAssembly.Module(Uint8Array.from(atob(WASM), (c) => c.charCodeAt(0)));
    } catch {
      compiled = null;
    }
  }
  return compiled;
}
`;
const out = path.join(web, "lfn_kernel.js");
if (process.argv.includes("--check")) {
  const same = fs.existsSync(out) && fs.readFileSync(out, "utf8") === js;
  console.log(same ? "lfn_kernel.js is up to date" : "lfn_kernel.js differs from lfn_kernel.wat's build");
  process.exit(same ? 0 : 1);
}
fs.writeFileSync(out, js);
console.log(`wrote ${out} (${buffer.length} bytes of WebAssembly)`);
