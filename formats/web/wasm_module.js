// wasm_module.js — the loader of the viewer's generated WebAssembly kernels (lfn_kernel.js,
// render_kernel.js: their modules' bytes in base64, made by tools/build_kernels.mjs from the .wat
// text beside them).

/** A function returning the WebAssembly.Module of base64 bytes `b64`, compiled on its first call
 *  (synchronously: the kernels are small), or null where the environment cannot compile it (no
 *  WebAssembly SIMD). */
export function lazyModule(b64) {
  let compiled;
  return () => {
    if (compiled === undefined) {
      try {
        compiled = new WebAssembly.Module(Uint8Array.from(atob(b64), (c) => c.charCodeAt(0)));
      } catch {
        compiled = null;
      }
    }
    return compiled;
  };
}
