"""Oracle experiment: the encoder's prediction told each view's true warp (rotation, scale or
shift per view, as tools.unseen made them): every (view, reference) pair's sampling positions
moved by M_r M_v^-1 x - x at each 8x8 block's centre (predictor) / each pixel (map estimation).
Files are not decodable (the decoders do not know the warps); bytes of the sections are counted,
plus 4 numbers a view at 2 bytes each (what a format would store). One thread."""
import sys, json
import numpy as np, cv2
sys.path.insert(0, "/work/main")
from tools import unseen
from formats.scenes import read_scene
from formats.codec_api import EncodeOptions
from rlfc import txencode as te, txsample as ts, txestimate as tse
from rlfc.txsample import TB

variant, target, how = sys.argv[1], float(sys.argv[2]), sys.argv[3]
oracle = how in ("oracle", "estimated")
ant = read_scene("/work/shared/data/hci_antinous")
r, c, h, w, _ = ant.views.shape
cen = (w / 2 - 0.5, h / 2 - 0.5)
if variant == "rotate":
    mats = [cv2.getRotationMatrix2D(cen, a, 1.0) for a in np.random.default_rng(7).uniform(-0.5, 0.5, r * c)]
    views = unseen.rotated(ant.views)
elif variant == "zoom":
    mats = [cv2.getRotationMatrix2D(cen, 0.0, z) for z in np.random.default_rng(8).uniform(1 - 0.006, 1 + 0.006, r * c)]
    views = unseen.zoomed(ant.views)
elif variant == "jitter":
    rng = np.random.default_rng(5)
    sh = [rng.uniform(-0.7, 0.7, 2) for _ in range(r * c)]
    mats = [np.float64([[1, 0, dx], [0, 1, dy]]) for dy, dx in sh]
    views = unseen.jittered(ant.views)
else:
    mats = [np.float64([[1, 0, 0], [0, 1, 0]])] * (r * c)
    views = ant.views
lf = unseen._grid(views, variant)
if how == "estimated":                      # the warps estimated from the views alone (est_warp.py)
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent))
    import est_warp_stop71 as est_warp
    mats = est_warp.estimate(views)[0]
full = [np.vstack([m, [0, 0, 1]]) for m in mats]
inv = [np.linalg.inv(m) for m in full]


def offset_at(v, ref, ys, xs):
    """(dy, dx) px at points (ys, xs): M_r M_v^-1 x - x."""
    T = full[ref] @ inv[v]
    X = T[0, 0] * xs + T[0, 1] * ys + T[0, 2]
    Y = T[1, 0] * xs + T[1, 1] * ys + T[1, 2]
    return Y - ys, X - xs


if oracle:
    orig_pv = ts.predict_view

    def pv_with(v):
        def predict_view(atlas, slots, weights, disp, modes, dpos, n8y, n8x, out=None):
            R = slots.size
            d = np.asarray(disp).reshape(1, n8y, n8x)
            dy, dx = d * dpos[:, 0, None, None], d * dpos[:, 1, None, None]
            yc, xc = np.mgrid[0:n8y, 0:n8x].astype(np.float64) * TB + 3.5
            refs = lf_struct.refs[v].clip(0)
            for j in range(R):
                oy, ox = offset_at(v, int(refs[j]), yc, xc)
                dy[j] = dy[j] + oy * 16
                dx[j] = dx[j] + ox * 16
            if out is None:
                out = np.empty((n8y * TB, n8x * TB, atlas.P), np.int32)
            band = max(1, ts.BAND_TBS // n8x)
            for a in range(0, n8y, band):
                b = min(n8y, a + band)
                ts.predict_rows(atlas, slots, weights, dy[:, a:b], dx[:, a:b], a, out=out[a * TB:b * TB])
            other = np.flatnonzero(np.asarray(modes) != 0)
            if other.size:
                ty, tx = np.divmod(other, n8x)
                wm = ts.mode_weights(weights)[np.asarray(modes)[other]]
                p = ts.predict(atlas, np.broadcast_to(slots, (other.size, R)), wm, dy.reshape(R, -1)[:, other].T,
                               dx.reshape(R, -1)[:, other].T, ty * TB, tx * TB)
                out.reshape(n8y, TB, n8x, TB, atlas.P)[ty, :, tx] = p
            return out
        return predict_view

    orig_enc_pv = te.TxEncoder.predict_view

    def enc_pv(self, v, kp):
        global lf_struct
        lf_struct = self.s
        te.predict_view = pv_with(v)
        try:
            return orig_enc_pv(self, v, kp)
        finally:
            te.predict_view = orig_pv

    te.TxEncoder.predict_view = enc_pv

    def maps_cell(self, m, d16m):
        s = self.s
        views_ = self.cells[m]
        nr = self._nrefs(m)
        acc = np.zeros((1 + nr, self.nby8 * self.nbx8))
        dpix = np.repeat(np.repeat(d16m.reshape(self.nby8, self.nbx8).astype(np.float32) / 16, TB, 0), TB, 1)
        gy, gx = self._grid()
        y, yk, p, e, wp, blend = (np.empty((self.hp, self.wp), np.float32) for _ in range(6))
        for v in views_.tolist():
            rr = s.refs[v, :nr]
            self._y(v, y)
            dpos = (s.positions[v] - s.positions[rr]).astype(np.float32)
            wb = s.weights[v, :nr] / 64.0
            blend.fill(0)
            for j in range(nr):
                oy, ox = offset_at(v, int(rr[j]), gy.astype(np.float64), gx.astype(np.float64))
                mx = (gx + dpix * dpos[j, 1] + ox).astype(np.float32)
                my = (gy + dpix * dpos[j, 0] + oy).astype(np.float32)
                tse.cvremap.remap(self._y(rr[j], yk), mx, my, cv2.INTER_LINEAR, out=p)
                acc[1 + j] += tse._block_sums(np.square(np.subtract(y, p, out=e), out=e), self.nby8, self.nbx8)
                blend += np.multiply(p, np.float32(wb[j]), out=wp)
            acc[0] += tse._block_sums(np.square(np.subtract(y, blend, out=e), out=e), self.nby8, self.nbx8)
        return acc

    tse.Estimator._maps_cell = maps_cell

e = te.encode_tx(lf, EncodeOptions(profile="tx", target_psnr=target))
b = sum(len(x) for _, x in e.sections) + (2 * 4 * r * c if oracle else 0)
print(json.dumps({"variant": variant, "target": target, "warps": how, "bytes": b, "bpp": 8 * b / (r * c * h * w),
                  "psnr": round(e.summary["psnr_rgb"], 3), "coded_blocks": e.config.get("n_blocks")}))
