// viewer.js — the page of `lfcodec view`: opens ?file=URL by HTTP Range requests, decodes on
// the client (lfc.js, JPEG 2000 key views through OpenJPEG/wasm) and renders views with
// render.js onto a canvas. Drag to move the viewpoint; sliders for focus and aperture; a level
// selector; a panel with bytes fetched, cache size and frame time.
//
// For tests and scripts: window.lfcViewer = {ready (a promise), show(s, t, opts) → frame info,
// state}; document.body.dataset.state is "loading", "ready" or "error" (the message in #error).
import { RangeSource, openDecoder } from "./lfc.js";
import { makeKeyImage } from "./openjpeg.js";
import { Renderer, toRGBA } from "./render.js";

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const fileUrl = params.get("file");
const cacheMiB = Number(params.get("cache_mib") || 256);     // decoded views
const chunkMiB = Number(params.get("chunk_mib") || 64);      // verified file chunks

function fail(e) {
  document.body.dataset.state = "error";
  const msg = e && e.name && e.message ? `${e.name}: ${e.message}` : String(e);
  $("error").textContent = `Cannot show ${fileUrl || "(no file)"}\n${msg}`;
  $("status").textContent = "error";
  console.error(e);
}

const state = { s: 0, t: 0, focus: 0, aperture: 0, level: 0, useMaps: true, robust: true, busy: null, pending: false, last: null };

async function main() {
  if (!fileUrl) throw new Error("no file given: open this page as index.html?file=NAME.lfc");
  const source = new RangeSource(new URL(fileUrl, location.href).href);
  let keyImage = null;
  if (typeof globalThis.OpenJPEGWASM === "function") {
    const factory = () => globalThis.OpenJPEGWASM({ locateFile: (p) => new URL(`vendor/${p}`, import.meta.url).href });
    keyImage = await makeKeyImage(factory);
  }
  const t0 = performance.now();
  const dec = await openDecoder(source, { name: fileUrl, keyImage, chunkBudget: chunkMiB * (1 << 20) });
  const openMs = performance.now() - t0;
  const r = new Renderer(dec, { cacheBytes: cacheMiB * (1 << 20) });
  const canvas = $("view");
  canvas.width = dec.W;
  canvas.height = dec.H;
  const ctx = canvas.getContext("2d");
  state.s = (dec.rows - 1) / 2;
  state.t = (dec.cols - 1) / 2;
  $("title").textContent = `${fileUrl} — ${dec.rows}×${dec.cols} views of ${dec.W}×${dec.H}`;

  const stats = () => {
    const f = state.last;
    $("stats").textContent = [
      `bytes fetched  ${source.bytesFetched.toLocaleString()} of ${source._size.toLocaleString()}`,
      `range requests ${source.requests}`,
      `chunk cache    ${(dec.file.cachedBytes() / 1024).toFixed(1)} KiB of ${chunkMiB} MiB`,
      `view cache     ${(r.cachedBytes() / 1048576).toFixed(2)} MiB of ${cacheMiB} MiB (${r.cache.size} views)`,
      `views decoded  ${r.viewsDecoded}`,
      `open           ${openMs.toFixed(0)} ms`,
      `frame          ${f ? f.ms.toFixed(1) : "-"} ms (${f ? f.sources : 0} source views)`,
    ].join("\n");
    $("st").textContent = `${state.s.toFixed(2)}, ${state.t.toFixed(2)}`;
    $("focusv").textContent = state.useMaps && state.aperture === 0 ? "(file's maps)" : state.focus.toFixed(2);
    $("aperturev").textContent = state.aperture.toFixed(1);
  };

  const draw = async () => {
    const focus = state.useMaps && state.aperture === 0 ? null : state.focus;
    const f = await r.render(state.s, state.t, { focus, aperture: state.aperture, level: state.level, robust: state.robust });
    ctx.putImageData(new ImageData(toRGBA(f.pixels, dec.H, dec.W, dec.C, dec.peak), dec.W, dec.H), 0, 0);
    state.last = f;
    stats();
    return { s: state.s, t: state.t, ms: f.ms, sources: f.sources, bytesFetched: source.bytesFetched, requests: source.requests };
  };

  // one frame at a time; a newer request replaces a waiting one
  const request = () => {
    if (state.busy) { state.pending = true; return state.busy; }
    state.busy = draw().catch(fail).finally(() => {
      state.busy = null;
      if (state.pending) { state.pending = false; request(); }
    });
    return state.busy;
  };

  let drag = null;
  canvas.addEventListener("pointerdown", (e) => { drag = { x: e.clientX, y: e.clientY, s: state.s, t: state.t }; canvas.classList.add("dragging"); canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener("pointerup", () => { drag = null; canvas.classList.remove("dragging"); });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    const k = Math.max(dec.rows, dec.cols) / canvas.getBoundingClientRect().width;   // the canvas width = the grid
    state.s = Math.min(Math.max(drag.s - (e.clientY - drag.y) * k, 0), dec.rows - 1);
    state.t = Math.min(Math.max(drag.t - (e.clientX - drag.x) * k, 0), dec.cols - 1);
    request();
  });
  $("focus").addEventListener("input", (e) => { state.focus = Number(e.target.value); state.useMaps = false; $("usemaps").checked = false; request(); });
  $("aperture").addEventListener("input", (e) => { state.aperture = Number(e.target.value); request(); });
  $("usemaps").addEventListener("change", (e) => { state.useMaps = e.target.checked; request(); });
  $("robust").addEventListener("change", (e) => { state.robust = e.target.checked; request(); });
  $("level").addEventListener("change", (e) => { state.level = Number(e.target.value); request(); });

  await request();
  document.body.dataset.state = "ready";
  $("status").textContent = "drag the image to move the viewpoint";
  return {
    decoder: dec, renderer: r, source,
    /** Render (s, t) with opts {focus (null = maps), aperture, level, robust}; resolves with frame info. */
    async show(s, t, opts = {}) {
      if (state.busy) await state.busy;
      Object.assign(state, { s, t, aperture: opts.aperture || 0, level: opts.level || 0, robust: opts.robust !== false });
      state.useMaps = opts.focus === undefined || opts.focus === null;
      if (!state.useMaps) state.focus = opts.focus;
      $("focus").value = state.focus; $("aperture").value = state.aperture;           // the controls follow
      $("usemaps").checked = state.useMaps; $("robust").checked = state.robust; $("level").value = String(state.level);
      return draw();
    },
  };
}

const ready = main().catch((e) => { fail(e); throw e; });
window.lfcViewer = { ready, state };
ready.then((api) => Object.assign(window.lfcViewer, api)).catch(() => {});
