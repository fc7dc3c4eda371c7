#!/usr/bin/env bash
# Rebuild the browser viewer's vendored files from the npm registry, reproducibly: `npm ci`
# installs exactly what formats/web/package-lock.json pins (@cornerstonejs/codec-openjpeg 1.3.6,
# checked against its sha512), then the OpenJPEG decoder (JS loader + WebAssembly) is copied into
# formats/web/vendor/; the WebAssembly text of the network renderer's dense layers
# (lfn_kernel.wat) and of the novel-view blend (render_kernel.wat) is assembled by wabt into
# lfn_kernel.js and render_kernel.js. The viewer's other files need no build.
# Run from anywhere; needs node and npm.
set -euo pipefail
cd "$(dirname "$0")/../formats/web"
npm ci --no-audit --no-fund
src=node_modules/@cornerstonejs/codec-openjpeg/dist
cp "$src/openjpegwasm_decode.js" "$src/openjpegwasm_decode.wasm" vendor/
sha256sum vendor/openjpegwasm_decode.js vendor/openjpegwasm_decode.wasm
# the WebAssembly kernels: lfn_kernel.wat and render_kernel.wat assembled by wabt (a devDependency)
node ../../tools/build_kernels.mjs
