// A view's reconstruction on WebAssembly (formats/web/predict_kernel.wat, predict.js PredictKernel:
// its prediction, its residual blocks) against lfc.js's loops, in one Node process:
//   node tools/web_predict_kernel.mjs FILE.lfc [ROUNDS]
// First every view of the file (key views included: predicted keys are predicted too) is decoded
// by a decoder predicting on the kernel and by one predicting in the loops, and their planes are
// compared integer for integer (a damaged file: both must throw the same errors; then only same,
// differ, errors and first_error are printed). Then (ROUNDS > 0) every predicted view is timed, its prediction
// alone (level 1 of decodeView) and whole (level 0: the residual blocks added), the two
// alternated per round on decoders whose key views are decoded. Prints one JSON line: same (every
// view equal), differ (integers that differ), kernel (whether this Node has WebAssembly SIMD), P,
// warps, weighted, the median ms per view of each (kernel_ms, loops_ms; view_kernel_ms,
// view_loops_ms) and their ratios, the key views copied into the kernel's memory, and (fallback_*)
// the same with a key-view budget of one byte: every view in the loops, none copied.
import path from "path";
import { WEB, openFile, say } from "./web_node.mjs";

const [file, rounds = "5"] = process.argv.slice(2);
const { PredictKernel } = await import(path.join(WEB, "predict.js"));
const med = (a) => a.slice().sort((x, y) => x - y)[a.length >> 1];
const dk = await openFile(file), dl = await openFile(file);

async function withKernel(on, fn) {
  PredictKernel.useWasm = on;
  try {
    return await fn();
  } finally {
    PredictKernel.useWasm = true;
  }
}

const attempt = async (fn) => {
  try {
    return [await fn(), null];
  } catch (e) {
    return [null, `${e.name}: ${e.message}`];
  }
};
let same = true, differ = 0, errors = 0, firstError = null;
for (let v = 0; v < dk.n0; v++) {
  for (const level of [0, 1]) {
    const [a, ea] = await attempt(() => withKernel(true, () => dk.decodeView(v, level)));
    const [b, eb] = await attempt(() => withKernel(false, () => dl.decodeView(v, level)));
    if (ea || eb) {                            // (a damaged file: the same error from both)
      errors++;
      firstError = firstError || ea || eb;
      same = same && ea === eb;
      continue;
    }
    for (let i = 0; i < a.length; i++) if (a[i] !== b[i]) differ++;
    same = same && a.length === b.length;
  }
}
same = same && differ === 0;
if (errors) {
  say(JSON.stringify({ same, differ, errors, first_error: firstError, kernel: dk.predictsOnWasm() }));
  process.exit(0);
}
// views whose key views do not fit the kernel's budget go to the loops (the same planes, none copied)
const df = await openFile(file), budget = PredictKernel.SLOT_BYTES;
PredictKernel.SLOT_BYTES = 1;
let fallbackSame = true;
try {
  for (let v = 0; v < df.n0; v++) {
    const a = await df.decodeView(v, 0), b = await dl.decodeView(v, 0);
    fallbackSame = fallbackSame && a.length === b.length && a.every((x, i) => x === b[i]);
  }
} finally {
  PredictKernel.SLOT_BYTES = budget;
}
const predicted = [];
for (let v = 0; v < dk.n0; v++) if (dk.keySlot[v] < 0) predicted.push(v);
const times = { kernel: [], loops: [], kernel0: [], loops0: [] };
for (let r = 0; r < Number(rounds); r++) {
  for (const [name, d, on] of r % 2 ? [["loops", dl, false], ["kernel", dk, true]] : [["kernel", dk, true], ["loops", dl, false]]) {
    for (const level of [1, 0]) {
      for (const v of predicted) {
        const t = performance.now();
        await withKernel(on, () => d.decodeView(v, level));
        times[level ? name : name + "0"].push(performance.now() - t);
      }
    }
  }
}
const out = { same, differ, kernel: dk.predictsOnWasm(), P: dk.P, warps: dk.warp !== null, weighted: dk.wpGain !== null,
  views: dk.n0, predicted: predicted.length, copies: dk._kernelP ? dk._kernelP.copies : 0,
  fallback_same: fallbackSame, fallback_copies: df._kernelP ? df._kernelP.copies : 0 };
if (times.kernel.length) {
  out.kernel_ms = med(times.kernel);
  out.loops_ms = med(times.loops);
  out.ratio = out.kernel_ms / out.loops_ms;
  out.view_kernel_ms = med(times.kernel0);
  out.view_loops_ms = med(times.loops0);
  out.view_ratio = out.view_kernel_ms / out.view_loops_ms;
}
say(JSON.stringify(out));
