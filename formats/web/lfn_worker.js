// lfn_worker.js — one worker of lfn_pool.js's ForwardPool: holds the weights last sent ({net})
// and answers {id, op, neurons, n, rays} with {id, out}: for op "occ" the occupancy net's answers
// (Uint8Array n), for op "net" the network outputs of the n rays (Float64Array n·4), computed by
// the same code as the page's own thread (LfnDecoder._occupiedAll, _forwardRays).
import { LfnDecoder } from "./lfn.js";

let net = null;
self.onmessage = (e) => {
  const m = e.data;
  if (m.net) {
    const { useWasm, ...fields } = m.net;
    LfnDecoder.useWasm = useWasm;            // as the page's thread
    net = Object.assign(Object.create(LfnDecoder.prototype), fields);
    return;
  }
  try {
    let out;
    if (m.op === "occ") {
      out = net._occupiedAll(m.rays, m.n, net._workspace(1));
    } else {
      out = new Float64Array(m.n * 4);
      net._forwardRays(net._workspace(m.neurons), m.rays, m.n, null, out);
    }
    self.postMessage({ id: m.id, out }, [out.buffer]);
  } catch (err) {
    self.postMessage({ id: m.id, error: String(err && err.message ? err.message : err) });
  }
};
