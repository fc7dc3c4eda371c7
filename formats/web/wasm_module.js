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

/** Grow WebAssembly memory `mem` to at least `bytes`; false where it cannot (the caller's loops
 *  then do the work). */
export function growTo(mem, bytes) {
  if (bytes <= mem.buffer.byteLength) return true;
  try {
    mem.grow(Math.ceil((bytes - mem.buffer.byteLength) / 65536));
    return true;
  } catch {
    return false;
  }
}

/** Slots in a kernel's memory for typed arrays `arrays` (by identity): those held already kept,
 *  the others put in a new slot while fewer than `cap` exist, else in the least recently used
 *  one. `slots` ([{a, used}], changed in place) and `tick` (this call's clock) are the caller's.
 *  Returns {slot: each array's slot, fresh: [[slot, array], ...] to copy in}. */
export function assignSlots(slots, arrays, cap, tick) {
  const slot = arrays.map((a) => slots.findIndex((sl) => sl.a === a));
  slot.forEach((i) => { if (i >= 0) slots[i].used = tick; });
  const fresh = [];
  arrays.forEach((a, j) => {
    if (slot[j] >= 0) return;
    let i = slots.findIndex((sl) => sl.a === a);         // (an array named twice in one call)
    if (i < 0 && slots.length < cap) { i = slots.length; slots.push({ a: null, used: 0 }); }
    if (i < 0) {
      i = 0;
      slots.forEach((sl, q) => { if (sl.used < slots[i].used) i = q; });
    }
    if (slots[i].a !== a) fresh.push([i, a]);
    slots[i] = { a, used: tick };
    slot[j] = i;
  });
  return { slot, fresh };
}
