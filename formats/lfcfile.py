"""An .lfc file as the codecs see it: metadata JSON (codec id, codec config, scene geometry)
plus the codec's named sections, on top of :mod:`formats.container`."""
from __future__ import annotations

import json
import os
import zlib
from dataclasses import dataclass, field

from .container import DEFAULT_CHUNK, Container, write_container
from .errors import FormatError, TruncatedError, UnsupportedError
from .limits import DEFAULT, Limits

FORMAT_NAME = "lfc"
#: the section holding metadata moved out of ``meta`` (docs/FORMAT.md, "Moved metadata")
MORE_SECTION = "meta.more"
MORE_PARTS = ("scene", "config")
MAX_MORE_KEYS = 64


def encode_meta(codec: str, codec_version: int, config: dict, scene: dict, extra: dict | None = None) -> bytes:
    """UTF-8 JSON of the file's metadata section."""
    from . import __version__

    meta = {"format": FORMAT_NAME, "codec": codec, "codec_version": codec_version, "config": config,
            "scene": scene, "encoder": f"lfcodec {__version__}"}
    if extra:
        meta.update(extra)
    try:
        return json.dumps(meta, separators=(",", ":"), sort_keys=True, allow_nan=False).encode()
    except ValueError as e:     # NaN/Infinity somewhere (e.g. a camera matrix): not JSON
        raise FormatError(f"metadata holds a value JSON cannot represent ({e}); check the scene's cameras") from None


def split_meta(codec: str, codec_version: int, config: dict, scene: dict, sections: list,
               extra: dict | None = None, more: tuple[str, ...] = ()) -> tuple[bytes, list]:
    """(meta JSON, sections) of a file whose metadata keys named in ``more`` ("scene.KEY" or
    "config.KEY", those present) move out of ``meta`` into a deflated ``meta.more`` section
    appended after ``sections``: data a reader of the first bytes does not need (camera poses,
    file names, evaluation lists) then no longer delays what it does need."""
    parts = {"scene": dict(scene), "config": dict(config)}
    moved: dict = {}
    names = []
    for key in more:
        part, _, k = key.partition(".")
        if part not in MORE_PARTS or not k:
            raise ValueError(f"cannot move metadata key {key!r} (only scene.KEY / config.KEY)")
        if k in parts[part]:
            moved.setdefault(part, {})[k] = parts[part].pop(k)
            names.append(key)
    if not names:
        return encode_meta(codec, codec_version, config, scene, extra), list(sections)
    meta = encode_meta(codec, codec_version, parts["config"], parts["scene"], {**(extra or {}), "more": names})
    try:
        blob = json.dumps(moved, separators=(",", ":"), sort_keys=True, allow_nan=False).encode()
    except ValueError as e:
        raise FormatError(f"metadata holds a value JSON cannot represent ({e}); check the scene's cameras") from None
    return meta, list(sections) + [(MORE_SECTION, zlib.compress(blob, 9))]


def write_lfc(path: str | os.PathLike, codec: str, codec_version: int, config: dict, scene: dict,
              sections: list, *, extra: dict | None = None, more: tuple[str, ...] = (),
              chunk_size: int = DEFAULT_CHUNK) -> int:
    """Write an .lfc file atomically (``more``: metadata keys moved to the end of the file,
    :func:`split_meta`). Returns its size in bytes."""
    meta, secs = split_meta(codec, codec_version, config, scene, sections, extra, more)
    return write_container(path, meta, secs, chunk_size)


def lfc_bytes(codec: str, codec_version: int, config: dict, scene: dict, sections: list, *,
              extra: dict | None = None, more: tuple[str, ...] = ()) -> bytes:
    """The bytes :func:`write_lfc` would write (in memory)."""
    from .container import build_container

    meta, secs = split_meta(codec, codec_version, config, scene, sections, extra, more)
    return b"".join(bytes(p) for p in build_container(meta, secs))


@dataclass
class LfcFile:
    """An opened .lfc file: ``container`` for sections, ``meta`` for the parsed metadata."""

    container: Container
    meta: dict
    limits: Limits = DEFAULT
    _full: dict | None = field(default=None, repr=False)

    @property
    def codec(self) -> str:
        return self.meta["codec"]

    @property
    def moved(self) -> list[str]:
        """Metadata keys ("scene.KEY", "config.KEY") stored in the ``meta.more`` section."""
        return list(self.meta.get("more") or [])

    def full_meta(self) -> dict:
        """The metadata with the keys moved to ``meta.more`` put back (read, verified and
        inflated on first use; a byte prefix without that section raises TruncatedError)."""
        if self._full is None:
            self._full = self.meta if "more" not in self.meta else _merge_more(self)
        return self._full

    @property
    def scene(self) -> dict:
        """The complete scene geometry object (:meth:`full_meta`)."""
        return self.full_meta().get("scene")

    def close(self) -> None:
        self.container.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _merge_more(f: "LfcFile") -> dict:
    c, meta, name = f.container, f.meta, f.container.name
    keys = meta["more"]
    if not (isinstance(keys, list) and 1 <= len(keys) <= MAX_MORE_KEYS and all(isinstance(k, str) for k in keys)
            and len(set(keys)) == len(keys)):
        raise FormatError(f"{name}: metadata 'more' must be a list of 1..{MAX_MORE_KEYS} distinct key names")
    want: dict[str, set] = {}
    for k in keys:
        part, _, sub = k.partition(".")
        if part not in MORE_PARTS or not sub or not isinstance(meta.get(part), dict) or sub in meta[part]:
            raise FormatError(f"{name}: metadata 'more' names {k!r}, which is not a scene.KEY/config.KEY missing "
                              f"from meta")
        want.setdefault(part, set()).add(sub)
    if not c.has(MORE_SECTION):
        raise FormatError(f"{name}: metadata names moved keys but the file has no {MORE_SECTION!r} section")
    if not c.available(MORE_SECTION):
        raise TruncatedError(f"{name}: section {MORE_SECTION!r} ({', '.join(keys)}) is past the available prefix "
                             f"of the file")
    lim = f.limits.max_meta_bytes
    d = zlib.decompressobj()
    try:
        raw = d.decompress(bytes(c.read(MORE_SECTION)), lim + 1)
    except zlib.error as e:
        raise FormatError(f"{name}: section {MORE_SECTION!r} is not a zlib stream ({e})") from None
    if len(raw) > lim or d.unconsumed_tail or not d.eof or d.unused_data:
        raise FormatError(f"{name}: section {MORE_SECTION!r} inflates past {lim} bytes, is cut short or has "
                          f"trailing data")
    more = parse_json(raw, f"{name}: {MORE_SECTION}", f.limits)
    if not isinstance(more, dict) or set(more) != set(want) or any(
            not isinstance(more[p], dict) or set(more[p]) != want[p] for p in more):
        raise FormatError(f"{name}: section {MORE_SECTION!r} does not hold exactly the keys metadata 'more' names")
    out = dict(meta)
    for p, v in more.items():
        out[p] = {**meta[p], **v}
    return out


def _reject_constant(name):
    raise ValueError(f"non-standard JSON constant {name}")


def _depth(obj, limit: int, d: int = 0) -> int:
    """Nesting depth of parsed JSON, stopping past ``limit``."""
    if d > limit:
        return d
    if isinstance(obj, dict):
        return max([_depth(v, limit, d + 1) for v in obj.values()], default=d + 1)
    if isinstance(obj, list):
        return max([_depth(v, limit, d + 1) for v in obj], default=d + 1)
    return d


def parse_json(data, name: str, limits: Limits = DEFAULT):
    """Strict, bounded JSON: UTF-8 (no NaN/Infinity), at most ``limits.max_meta_bytes`` bytes
    and ``limits.max_json_depth`` levels deep."""
    if len(data) > limits.max_meta_bytes:
        raise FormatError(f"{name}: metadata section of {len(data)} bytes exceeds the limit of {limits.max_meta_bytes}")
    try:
        meta = json.loads(bytes(data).decode("utf-8"), parse_constant=_reject_constant)
    except RecursionError:
        raise FormatError(f"{name}: metadata JSON is nested too deeply") from None
    except (ValueError, UnicodeDecodeError) as e:
        raise FormatError(f"{name}: metadata section is not valid JSON ({e})") from None
    if _depth(meta, limits.max_json_depth) > limits.max_json_depth:
        raise FormatError(f"{name}: metadata JSON is nested deeper than {limits.max_json_depth} levels")
    return meta


def parse_meta(data, name: str, limits: Limits = DEFAULT) -> dict:
    """Strict, bounded parse of a metadata section (:func:`parse_json`), checked to be lfcodec
    metadata."""
    meta = parse_json(data, name, limits)
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME or not isinstance(meta.get("codec"), str):
        raise FormatError(f"{name}: metadata is not lfcodec metadata")
    v = meta.get("codec_version", 1)
    if isinstance(v, bool) or not isinstance(v, int) or v < 0:
        raise FormatError(f"{name}: metadata codec_version must be a non-negative integer, got {v!r}")
    return meta


def open_lfc(source, *, name: str | None = None, partial: bool = False, limits: Limits = DEFAULT,
             cache_bytes: int | None = None) -> LfcFile:
    """Open an .lfc file (path, URL, bytes or ByteRangeSource) and parse its metadata.

    A URL (``http(s)://``, or any scheme fsspec serves: ``file://``, ``s3://``, ``gs://``) is
    read by byte ranges through a page cache of at most ``cache_bytes`` bytes (default 64 MiB;
    :mod:`formats.remote`). ``partial=True`` accepts a byte prefix of a file (progressive
    streams): sections past the prefix are reported unavailable instead of the file being
    rejected as truncated.
    """
    if isinstance(source, str) and "://" in source:       # (formats.remote, and urllib, for URLs only)
        from .remote import DEFAULT_CACHE, is_url, open_remote

        if is_url(source):
            name = name or source
            source = open_remote(source, cache_bytes=cache_bytes or DEFAULT_CACHE)
    c = Container(source, name=name, partial=partial)
    try:
        if c.info("meta").length > limits.max_meta_bytes:
            raise FormatError(f"{c.name}: metadata section of {c.info('meta').length} bytes exceeds the limit of "
                              f"{limits.max_meta_bytes}")
        meta = parse_meta(c.read("meta"), c.name, limits)
    except Exception:
        c.close()
        raise
    return LfcFile(c, meta, limits)


def check_codec_version(f: LfcFile, codec: str, supported: int) -> None:
    if f.meta.get("codec") != codec:
        raise UnsupportedError(f"{f.container.name}: codec {f.meta.get('codec')!r} is not {codec!r}")
    v = f.meta.get("codec_version")
    if type(v) is not int or v < 1:              # FORMAT.md: every codec's versions start at 1
        raise FormatError(f"{f.container.name}: metadata codec_version must be an integer >= 1, got {v!r}")
    if v > supported:
        raise UnsupportedError(f"{f.container.name}: {codec} version {v} is newer than this decoder ({supported})")
