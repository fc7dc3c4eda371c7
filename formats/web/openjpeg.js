// openjpeg.js — JPEG 2000 key views through OpenJPEG compiled to WebAssembly
// (@cornerstonejs/codec-openjpeg, vendor/openjpegwasm_decode.js + .wasm; see vendor/LICENSES.md).
//
// makeKeyImage(factory) returns the `keyImage(bytes, Hp, Wp, C, dtype)` callback of
// lfc.openDecoder: it decodes one codestream and checks that its size, components and depth are
// what the file's header says (FormatError otherwise), returning H·W·C interleaved pixels.
import { FormatError } from "./lfc.js";

export async function makeKeyImage(factory) {
  const mod = await factory();
  return async (bytes, Hp, Wp, C, dtype) => {
    const dec = new mod.J2KDecoder();
    try {
      const buf = dec.getEncodedBuffer(bytes.length);
      buf.set(bytes);
      try {
        dec.decode();
      } catch (e) {
        throw new FormatError(`a JPEG 2000 key view does not decode (${typeof e === "number" ? "OpenJPEG error" : e.message || e})`);
      }
      const fi = dec.getFrameInfo();
      const bits = dtype === "uint8" ? 8 : 16;
      if (fi.width !== Wp || fi.height !== Hp || fi.componentCount !== C || fi.bitsPerSample > bits || fi.isSigned) {
        throw new FormatError(`a JPEG 2000 key view is ${fi.width}x${fi.height}x${fi.componentCount} at ${fi.bitsPerSample} bits; the header says ${Wp}x${Hp}x${C} ${dtype}`);
      }
      const out = dec.getDecodedBuffer();                  // interleaved, 1 or 2 bytes per sample (LE)
      return bits === 8 ? Uint8Array.from(out) : new Uint16Array(out.buffer.slice(out.byteOffset, out.byteOffset + out.byteLength));
    } finally {
      dec.delete();
    }
  };
}
