import numpy as np
from pathlib import Path
from tools.unseen import layers_rgba, _grid
from rlfc import encode
from formats.codec_api import EncodeOptions
lf = layers_rgba(Path("../shared/data"))
v = lf.views
for name, views in [("rgba", v), ("rgb only", np.ascontiguousarray(v[..., :3])), ("rgba, alpha 255", np.concatenate([v[..., :3], np.full(v.shape[:-1] + (1,), 255, np.uint8)], -1))]:
    for t in (36.0, 40.0):
        e = encode(_grid(views, name), EncodeOptions(profile="tx", target_psnr=t))
        secs = {n: len(x) for n, x in e.sections}
        print(name, t, sum(secs.values()), secs, e.config["n_blocks"], e.config["params"].get("step"))
