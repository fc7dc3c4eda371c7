// Decode an .lfc file with the browser viewer's JavaScript decoder under Node (the tests' and the
// fuzzer's second reader of the format, tools/fuzz.py).
// node tools/web_decode.mjs FILE OUTDIR [S,T,FOCUS,APERTURE ...]   (env LFC_LEVELS="0,1": levels)
// Writes OUTDIR/view_V.bin (Int32 planes, Hp·Wp·P) for every view (view_V_L1.bin at level 1),
// OUTDIR/render_I.bin (pixels of
// the file's dtype) for every camera (FOCUS "nan" = the file's maps), and prints one JSON line:
// {ok: true, Hp, Wp, P, n, keys, keys_at_open, keys_after_first} (key views: in the file, decoded by
// the open, decoded after the first view) or {ok: false, name, message} for an error the decoder raised.
import fs from "fs";
import path from "path";
import { WEB, openFile, say } from "./web_node.mjs";

const { LfcError } = await import(path.join(WEB, "lfc.js"));
const { Renderer } = await import(path.join(WEB, "render.js"));

const [file, out, ...cams] = process.argv.slice(2);
try {
  const chunkBudget = Number(process.env.LFC_CHUNK_BUDGET || Infinity);      // bytes of file chunks kept
  const dec = await openFile(file, { name: path.basename(file), chunkBudget });
  const keysAtOpen = dec.keysDecoded();
  let keysAfterFirst = null;
  fs.mkdirSync(out, { recursive: true });
  for (const level of (process.env.LFC_LEVELS || "0").split(",").map(Number)) {
    for (let v = 0; v < dec.n0; v++) {
      const p = await dec.decodeView(v, level);
      if (keysAfterFirst === null) keysAfterFirst = dec.keysDecoded();
      const name = level ? `view_${v}_L${level}.bin` : `view_${v}.bin`;
      fs.writeFileSync(path.join(out, name), Buffer.from(p.buffer, p.byteOffset, p.byteLength));
    }
  }
  const r = new Renderer(dec);
  for (let i = 0; i < cams.length; i++) {
    const [s, t, focus, ap] = cams[i].split(",").map(Number);
    const f = await r.render(s, t, { focus: Number.isNaN(focus) ? null : focus, aperture: ap });
    fs.writeFileSync(path.join(out, `render_${i}.bin`), Buffer.from(f.pixels.buffer));
  }
  say(JSON.stringify({ ok: true, Hp: dec.Hp, Wp: dec.Wp, P: dec.P, n: dec.n0, keys: dec.keys.length,
    keys_at_open: keysAtOpen, keys_after_first: keysAfterFirst }));
} catch (e) {
  if (!(e instanceof LfcError)) throw e;        // anything else is a bug: a non-zero exit and a trace
  process.stdout.write(JSON.stringify({ ok: false, name: e.name, message: e.message }) + "\n");
}
