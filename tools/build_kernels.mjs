// Assemble the browser viewer's WebAssembly text (SIMD) with wabt and write each kernel's loader:
// formats/web/lfn_kernel.wat → lfn_kernel.js (the network renderer's dense layers),
// formats/web/render_kernel.wat → render_kernel.js (the novel-view blend) and
// formats/web/predict_kernel.wat → predict_kernel.js (a view's prediction): the module's bytes as
// base64, compiled by formats/web/wasm_module.js. Run by tools/build_web.sh; `node
// tools/build_kernels.mjs --check` exits 1 where a committed file differs from its build.
import fs from "fs";
import path from "path";
import { fileURLToPath } from "url";

const web = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "../formats/web");
const { default: wabtInit } = await import(path.join(web, "node_modules/wabt/index.js"));
const wabt = await wabtInit();
const KERNELS = [
  ["lfn_kernel", "The WebAssembly module of the network renderer's dense layers"],
  ["render_kernel", "The WebAssembly module of the novel-view renderer's blend"],
  ["predict_kernel", "The WebAssembly module of the decoder's view prediction"],
];
let stale = 0;
for (const [name, what] of KERNELS) {
  const wat = fs.readFileSync(path.join(web, `${name}.wat`), "utf8");
  const mod = wabt.parseWat(`${name}.wat`, wat, { simd: true });
  mod.validate();
  const { buffer } = mod.toBinary({});
  if (buffer.length > 4096) {     // browsers refuse to compile larger modules synchronously on a page's thread
    console.error(`${name}.wat builds to ${buffer.length} bytes: over 4 KB, ${name}.js would need an asynchronous compile`);
    process.exit(1);
  }
  const b64 = Buffer.from(buffer).toString("base64");
  const js = `// ${name}.js — generated from ${name}.wat by tools/build_kernels.mjs (wabt); do not edit.
// ${what} (${buffer.length} bytes): kernelModule() compiles it once
// (wasm_module.js); null where the environment has no WebAssembly SIMD.
import { lazyModule } from "./wasm_module.js";

export const kernelModule = lazyModule("${b64}");
`;
  const out = path.join(web, `${name}.js`);
  if (process.argv.includes("--check")) {
    const same = fs.existsSync(out) && fs.readFileSync(out, "utf8") === js;
    console.log(same ? `${name}.js is up to date` : `${name}.js differs from ${name}.wat's build`);
    stale += same ? 0 : 1;
    continue;
  }
  fs.writeFileSync(out, js);
  console.log(`wrote ${out} (${buffer.length} bytes of WebAssembly)`);
}
process.exit(stale ? 1 : 0);
