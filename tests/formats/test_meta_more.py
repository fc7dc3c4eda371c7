"""Metadata moved to the end of a file (``meta.more``): what the writer moves, how a reader
puts it back, and hostile variants (each a typed error, no unbounded inflate)."""
import json
import zlib

import pytest

from formats.container import build_container
from formats.errors import FormatError, TruncatedError
from formats.lfcfile import encode_meta, lfc_bytes, open_lfc

SCENE = {"rows": 1, "cols": 2, "height": 4, "width": 4, "channels": 3, "dtype": "uint8", "layout": "posed",
         "positions": [[[0, 0, 0], [1, 0, 0]]]}


def test_moved_keys_come_back_and_leave_meta():
    blob = lfc_bytes("x", 1, {"a": 1, "train": [1, 2]}, SCENE, [("s", b"abc")],
                     more=("scene.positions", "config.train", "scene.c2w"))    # absent keys are not moved
    f = open_lfc(blob)
    assert list(f.container.sections) == ["meta", "s", "meta.more"]
    assert "positions" not in f.meta["scene"] and f.meta["more"] == ["scene.positions", "config.train"]
    full = f.full_meta()
    assert full["scene"]["positions"] == SCENE["positions"] and full["config"] == {"a": 1, "train": [1, 2]}
    assert f.scene is full["scene"] and f.full_meta() is full            # read once
    # without moved keys the file is as before: no section, no "more"
    plain = open_lfc(lfc_bytes("x", 1, {}, SCENE, [("s", b"abc")]))
    assert "more" not in plain.meta and plain.full_meta() is plain.meta
    # a prefix without the section: the first bytes open, the moved keys are a typed error
    pre = open_lfc(blob[:f.container.info("meta.more").offset + 3], partial=True)
    with pytest.raises(TruncatedError, match="meta.more"):
        pre.full_meta()


def _file(more_names, payload: bytes, scene=None, with_section=True):
    meta = json.loads(encode_meta("x", 1, {}, scene or {k: v for k, v in SCENE.items() if k != "positions"}))
    meta["more"] = more_names
    secs = [("meta.more", payload)] if with_section else []
    return b"".join(bytes(p) for p in build_container(json.dumps(meta).encode(), secs))


GOOD = zlib.compress(json.dumps({"scene": {"positions": SCENE["positions"]}}).encode())


@pytest.mark.parametrize("names,payload,kw,needle", [
    (["scene.positions"], GOOD, {"with_section": False}, "no 'meta.more' section"),
    ("scene.positions", GOOD, {}, "must be a list"),
    ([], GOOD, {}, "must be a list"),
    (["scene.positions", "scene.positions"], GOOD, {}, "must be a list"),
    (["views.positions"], GOOD, {}, "not a scene.KEY"),
    (["scene.rows"], GOOD, {}, "not a scene.KEY"),                     # already in meta: no override
    (["scene.positions"], b"not zlib", {}, "not a zlib stream"),
    (["scene.positions"], GOOD[:-6], {}, "cut short"),
    (["scene.positions"], GOOD + b"xx", {}, "trailing"),
    (["scene.positions"], zlib.compress(b"[1, 2"), {}, "not valid JSON"),
    (["scene.positions"], zlib.compress(b'{"scene": {"positions": NaN}}'), {}, "not valid JSON"),
    (["scene.positions"], zlib.compress(b'{"scene": {"c2w": 1}}'), {}, "exactly the keys"),
    (["scene.positions"], zlib.compress(b'{"scene": {"positions": 1}, "config": {}}'), {}, "exactly the keys"),
    (["scene.positions"], zlib.compress(b'{"scene": [1]}'), {}, "exactly the keys"),
])
def test_hostile_moved_metadata_is_a_format_error(names, payload, kw, needle):
    f = open_lfc(_file(names, payload, **kw))
    with pytest.raises(FormatError, match=needle):
        f.full_meta()


def test_inflate_is_bounded_by_the_metadata_limit():
    from formats.limits import DEFAULT, Limits

    bomb = zlib.compress(b'{"scene": {"positions": "' + b"a" * (3 << 20) + b'"}}', 9)
    assert len(bomb) < 8000
    small = Limits(**{**DEFAULT.__dict__, "max_meta_bytes": 1 << 20})
    f = open_lfc(_file(["scene.positions"], bomb), limits=small)
    with pytest.raises(FormatError, match="inflates past"):
        f.full_meta()
