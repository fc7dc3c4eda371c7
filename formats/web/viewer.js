// viewer.js — the page of `lfcodec view`: opens ?file=URL by HTTP Range requests, decodes on
// the client (lfc.js, JPEG 2000 key views through OpenJPEG/wasm) and renders views with
// render.js onto a canvas. Drag to move the viewpoint; sliders for focus and aperture; a level
// selector; a panel with bytes fetched, cache size and frame time.
//
// Light field networks (codec "lfn") open in the same page: lfn.js renders the network in JS at
// a chosen (fractional) number of neurons, fetching further step sections as the level rises;
// drag moves along the grid, or orbits a posed capture's cameras about their common target.
// A tile set's manifest (?file=NAME.json, tiles.js) opens the same way: each tile's file is
// opened when a camera first blends it, and the frame is the blend of the tiles around the camera.
// Novel views' blends and the networks' passes run on Web Workers (render_pool.js, lfn_pool.js;
// &workers=N, 0 = on the page's thread: the same pixels),
// their dense layers, the novel views' blend and the decoded views' prediction on WebAssembly SIMD
// where the browser has it (&wasm=0: lfn.js's, render.js's and lfc.js's own loops; the same pixels).
// "foveate" (&fovea=1) draws the full network where the pointer is and coarser networks on
// sparser pixels further out (lfn.js renderMip, LfnRenderer.render_pose_lod_mip's frame).
//
// For tests and scripts: window.lfcViewer = {ready (a promise), show(...) → frame info, state};
// RLFC files: show(s, t, {focus, aperture, level, robust}); LFN files: show({s, t} | {view, yaw,
// pitch}, {neurons, scale, native, fovea, gaze}). document.body.dataset.state is "loading", "ready" or "error" (the
// message in #error); state.mode is "rlfc" or "lfn".
import { LfcError, LfcFile, RangeSource, TxDecoder } from "./lfc.js";
import { LfnDecoder } from "./lfn.js";
import { ForwardPool, defaultWorkers } from "./lfn_pool.js";
import { makeKeyImage } from "./openjpeg.js";
import { PredictKernel } from "./predict.js";
import { Renderer, toRGBA } from "./render.js";
import { RenderPool } from "./render_pool.js";
import { TiledLfn } from "./tiles.js";

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const fileUrl = params.get("file");
const cacheMiB = Number(params.get("cache_mib") || 256);     // decoded views
const chunkMiB = Number(params.get("chunk_mib") || 64);      // verified file chunks
const workers = params.has("workers") ? Math.max(0, Math.min(64, Math.floor(Number(params.get("workers")) || 0))) : defaultWorkers();
if (params.get("wasm") === "0") {               // the networks, the blend and the views' prediction in JS loops (the same pixels)
  LfnDecoder.useWasm = false;
  Renderer.useWasm = false;
  PredictKernel.useWasm = false;
}

function fail(e) {
  document.body.dataset.state = "error";
  const msg = e && e.name && e.message ? `${e.name}: ${e.message}` : String(e);
  $("error").textContent = `Cannot show ${fileUrl || "(no file)"}\n${msg}`;
  $("status").textContent = "error";
  console.error(e);
}

const state = { mode: "rlfc", s: 0, t: 0, focus: 0, aperture: 0, level: 0, useMaps: true, robust: true, busy: null, pending: false, last: null };

// one frame at a time; a newer request replaces a waiting one
function scheduler(draw) {
  const request = () => {
    if (state.busy) { state.pending = true; return state.busy; }
    state.busy = draw().catch(fail).finally(() => {
      state.busy = null;
      if (state.pending) { state.pending = false; request(); }
    });
    return state.busy;
  };
  return request;
}

async function main() {
  if (!fileUrl) throw new Error("no file given: open this page as index.html?file=NAME.lfc");
  const url = new URL(fileUrl, location.href);
  const source = new RangeSource(url.href);
  const t0 = performance.now();
  if (/\.json$/i.test(url.pathname)) {              // an LFN tile set's manifest
    const dec = await TiledLfn.open(source, fileUrl, (name) => new RangeSource(new URL(name, url).href),
      { chunkBytes: chunkMiB * (1 << 20) });
    return mainLfn(dec, dec.source, t0);
  }
  const file = await LfcFile.open(source, fileUrl, chunkMiB * (1 << 20));
  if (file.meta.codec === "lfn") return mainLfn(await LfnDecoder.open(file, { maxNeurons: 0 }), source, t0);   // the base network first
  let keyImage = null;
  if (typeof globalThis.OpenJPEGWASM === "function") {
    const factory = () => globalThis.OpenJPEGWASM({ locateFile: (p) => new URL(`vendor/${p}`, import.meta.url).href });
    keyImage = await makeKeyImage(factory);
  }
  const dec = await new TxDecoder().init(file, keyImage);
  const openMs = performance.now() - t0;
  // the frames' blends on the page's thread and N − 1 Web Workers (&workers=N, at least one
  // worker; 0: the page's thread alone). By default only where the browser reports 3 or more
  // cores: on 2 cores one worker beside the page gave 0.77–1.13× the frame (BENCHMARKS.md)
  const renderWorkers = params.has("workers") || defaultWorkers() >= 3 ? workers : 0;
  const pool = renderWorkers > 0 && typeof Worker !== "undefined" ? new RenderPool(Math.max(1, renderWorkers - 1)) : null;
  const r = new Renderer(dec, { cacheBytes: cacheMiB * (1 << 20), pool });
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
      `views decoded  ${r.viewsDecoded} (predicted ${dec.predictsOnWasm() ? "on WebAssembly SIMD" : "in JS loops"})`,
      `open           ${openMs.toFixed(0)} ms`,
      `frame          ${f ? f.ms.toFixed(1) : "-"} ms (${f ? f.sources : 0} source views${f && !f.cubic ? ", bilinear preview" : ""}`
        + `${f ? (f.wasm ? ", WebAssembly SIMD" : ", JS loops") : ""}`
        + `${r.pool ? `, blended on ${r.pool.size} worker${r.pool.size > 1 ? "s" : ""} and the page's thread` : ""})`,
    ].join("\n");
    $("st").textContent = `${state.s.toFixed(2)}, ${state.t.toFixed(2)}`;
    $("focusv").textContent = state.useMaps && state.aperture === 0 ? "(file's maps)" : state.focus.toFixed(2);
    $("aperturev").textContent = state.aperture.toFixed(1);
  };

  const draw = async () => {
    const focus = state.useMaps && state.aperture === 0 ? null : state.focus;
    // a bilinear preview while a drag moves the camera; the frame at rest is the Python renderer's (bicubic)
    const f = await r.render(state.s, state.t, { focus, aperture: state.aperture, level: state.level, robust: state.robust,
      cubic: !drag });
    ctx.putImageData(new ImageData(toRGBA(f.pixels, dec.H, dec.W, dec.C, dec.peak), dec.W, dec.H), 0, 0);
    state.last = f;
    stats();
    return { s: state.s, t: state.t, ms: f.ms, sources: f.sources, bytesFetched: source.bytesFetched, requests: source.requests,
      workers: r.pool ? r.pool.size : 0 };
  };

  const request = scheduler(draw);

  let drag = null;
  canvas.addEventListener("pointerdown", (e) => { drag = { x: e.clientX, y: e.clientY, s: state.s, t: state.t }; canvas.classList.add("dragging"); canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener("pointerup", () => {
    const moved = drag && (drag.s !== state.s || drag.t !== state.t);
    drag = null;
    canvas.classList.remove("dragging");
    if (moved) request();                          // the full-quality frame once the camera rests
  });
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
      return draw().catch((e) => { fail(e); throw e; });        // (on the page too, as a drag's error is)
    },
  };
}

async function mainLfn(dec, source, t0) {
  const tiled = dec instanceof TiledLfn;
  let pool = workers > 0 && typeof Worker !== "undefined" ? new ForwardPool(workers) : null;   // the networks' passes
  const openMs = performance.now() - t0;
  const posed = dec.layout === "posed";
  Object.assign(state, { mode: "lfn", posed, view: 0, yaw: 0, pitch: 0, s: (dec.rows - 1) / 2, t: (dec.cols - 1) / 2,
    neurons: dec.maxN, scale: "auto", native: true, fovea: params.get("fovea") === "1", gaze: null });
  const want = Number(params.get("neurons"));
  if (want >= dec.minN && want <= dec.maxN) state.neurons = want;
  $("rlfc-controls").hidden = true;
  $("lfn-controls").hidden = false;
  $("fovea").checked = state.fovea;
  $("viewidx").max = String(dec.rows * dec.cols - 1);
  $("neurons").min = String(dec.minN); $("neurons").max = String(dec.maxN); $("neurons").value = String(state.neurons);
  $("title").textContent = `${fileUrl} — ${tiled ? `tile set of ${dec.files.length} light field networks` : "light field network"}, ${dec.depth} layers of ${dec.minN}..${dec.maxN} neurons; ${dec.rows}×${dec.cols} views of ${dec.W}×${dec.H}`;
  const canvas = $("view"), ctx = canvas.getContext("2d");
  canvas.style.width = `${dec.W}px`;

  let drag = null;
  const pose = () => (posed ? dec.orbitPose(state.view, state.yaw, state.pitch) : dec.gridPose(state.s, state.t));
  const stats = () => {
    const f = state.last;
    const held = dec.weightBytes();
    $("stats").textContent = [
      `bytes fetched  ${source.bytesFetched.toLocaleString()} of ${source._size.toLocaleString()}`,
      `range requests ${source.requests}`,
      `network        ${dec.neurons} of ${dec.maxN} neurons fetched (${(held / 1024).toFixed(1)} KiB of weights)`,
      ...(tiled ? [`tiles          ${f ? f.tiles.join(", ") : "-"} blended; ${dec.tiles.size} of ${dec.files.length} opened`] : []),
      `open           ${openMs.toFixed(0)} ms`,
      `frame          ${f ? f.ms.toFixed(1) : "-"} ms, ${f ? `${f.w}×${f.h}` : "-"} at ${f ? f.neurons.toFixed(2) : "-"} neurons${f && f.stride > 1 ? `, the network every ${f.stride} pixels` : ""}`,
      ...(f && f.gaze ? [`foveated       around (${f.gaze.map((v) => v.toFixed(0)).join(", ")}): ${f.levels} levels, the full network at the gaze`] : []),
      `rays evaluated ${f ? f.evaluated.toLocaleString() : "-"}${dec.occ ? " (the occupancy net skips the others)" : ""}`
        + (pool ? ` on ${pool.size} worker${pool.size > 1 ? "s" : ""}` : " on the page's thread"),
    ].join("\n");
    $("st").textContent = posed ? `view ${state.view}, yaw ${state.yaw.toFixed(1)}°, pitch ${state.pitch.toFixed(1)}°`
      : `${state.s.toFixed(2)}, ${state.t.toFixed(2)}`;
    $("viewv").textContent = String(state.view);
    $("neuronsv").textContent = `${state.neurons} (scale ${dec.scaleOf(state.neurons).toFixed(3)})`;
  };

  const draw = async (neurons = state.neurons) => {
    const p = pose();
    await dec.grow(neurons, p);              // fetches the step sections this level needs (a tile set: of the camera's tiles)
    // beyond what the file holds: the best size of its display ladder (at the chosen scale) that the held steps reach
    const n = neurons <= dec.neurons ? neurons : dec.displayNeurons(state.scale === "auto" ? null : Number(state.scale));
    const t = performance.now();
    const sc = state.scale === "auto" ? dec.scaleOf(n) : Number(state.scale);
    const s = drag ? Math.min(sc, 0.25) : sc;   // a quarter-scale preview while dragging
    const h = Math.max(1, Math.round(dec.H * s)), w = Math.max(1, Math.round(dec.W * s));
    // foveated: sizes falling from the held network at the gaze (default: the centre) to the base one
    const gaze = state.fovea && !drag ? (state.gaze ? state.gaze.map((v, i) => v * (i ? h : w)) : [w / 2, h / 2]) : null;
    const frame = (pl) => (gaze ? dec.renderMipAsync(p, dec.foveationMap(gaze, h, w), s, { native: state.native, pool: pl })
      : dec.renderAsync(p, n, s, { native: state.native, pool: pl }));
    let r;
    try {
      r = await frame(pool);
    } catch (e) {
      if (!pool || e instanceof LfcError) throw e;
      console.warn(`network workers failed (${e.message}); rendering on the page's thread`);
      pool.terminate();
      pool = null;
      r = await frame(null);
    }
    const px = dec.toPixels(r.rgba, r.h, r.w);
    const ms = performance.now() - t;
    canvas.width = r.w;
    canvas.height = r.h;
    ctx.putImageData(new ImageData(toRGBA(px, r.h, r.w, dec.C, dec.peak), r.w, r.h), 0, 0);
    state.last = { ms, w: r.w, h: r.h, neurons: gaze ? dec.neurons : n, evaluated: r.evaluated, stride: r.stride,
      tiles: r.tiles || [0], gaze, levels: r.levels };
    stats();
    return { ...state.last, pose: p, bytesFetched: source.bytesFetched, requests: source.requests, neuronsFetched: dec.neurons,
      workers: pool ? pool.size : 0, wasm: Boolean(dec._kernel && dec._kernel()) };
  };
  const request = scheduler(() => draw());

  canvas.addEventListener("pointerdown", (e) => { drag = { x: e.clientX, y: e.clientY, s: state.s, t: state.t, yaw: state.yaw, pitch: state.pitch }; canvas.classList.add("dragging"); canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener("pointerup", () => { drag = null; canvas.classList.remove("dragging"); request(); });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) {                               // foveated: the gaze follows the pointer (as a fraction of the frame)
      if (!state.fovea) return;
      const b = canvas.getBoundingClientRect();
      state.gaze = [(e.clientX - b.left) / b.width, (e.clientY - b.top) / b.height];
      request();
      return;
    }
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    if (posed) {                               // half a degree per pixel
      state.yaw = drag.yaw - dx * 0.5;
      state.pitch = Math.min(Math.max(drag.pitch - dy * 0.5, -80), 80);
    } else {
      const k = Math.max(dec.rows, dec.cols) / canvas.getBoundingClientRect().width;
      state.s = Math.min(Math.max(drag.s - dy * k, 0), dec.rows - 1);
      state.t = Math.min(Math.max(drag.t - dx * k, 0), dec.cols - 1);
    }
    request();
  });
  $("viewidx").addEventListener("input", (e) => {
    state.view = Number(e.target.value);
    if (!posed) { state.s = Math.floor(state.view / dec.cols); state.t = state.view % dec.cols; }
    state.yaw = state.pitch = 0;
    request();
  });
  $("neurons").addEventListener("input", (e) => { state.neurons = Number(e.target.value); request(); });
  $("scale").addEventListener("change", (e) => { state.scale = e.target.value; request(); });
  $("native").addEventListener("change", (e) => { state.native = e.target.checked; request(); });
  $("fovea").addEventListener("change", (e) => { state.fovea = e.target.checked; request(); });

  await draw(dec.minN);                        // the base network at its own scale: the first useful bytes
  await request();                             // then the chosen level, its steps streamed in
  document.body.dataset.state = "ready";
  $("status").textContent = posed ? "drag the image to orbit the scene" : "drag the image to move the viewpoint";
  return {
    decoder: dec, source,
    /** Render a camera ({s, t} on a grid, or {view, yaw, pitch}) with opts {neurons, scale
     *  ("auto" or a number), native (the network on its own pixel grid; default true), fovea
     *  (foveated around gaze: [x, y] as fractions of the frame, default the centre)}; resolves
     *  with frame info. */
    async show(cam, opts = {}) {
      if (state.busy) await state.busy;
      if (cam.view !== undefined) {
        state.view = cam.view;
        if (!posed) { state.s = Math.floor(cam.view / dec.cols); state.t = cam.view % dec.cols; }
      }
      if (cam.s !== undefined) { state.s = cam.s; state.t = cam.t; }
      state.yaw = cam.yaw || 0; state.pitch = cam.pitch || 0;
      if (opts.neurons !== undefined) state.neurons = opts.neurons;
      if (opts.scale !== undefined) state.scale = String(opts.scale);
      if (opts.native !== undefined) state.native = Boolean(opts.native);
      if (opts.fovea !== undefined) state.fovea = Boolean(opts.fovea);
      if (opts.gaze !== undefined) state.gaze = opts.gaze;
      $("native").checked = state.native;
      $("fovea").checked = state.fovea;
      $("neurons").value = String(state.neurons); $("scale").value = state.scale === "auto" ? "auto" : "1";
      return draw();
    },
  };
}

const ready = main().catch((e) => { fail(e); throw e; });
window.lfcViewer = { ready, state };
ready.then((api) => Object.assign(window.lfcViewer, api)).catch(() => {});
