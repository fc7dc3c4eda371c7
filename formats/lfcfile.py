"""An .lfc file as the codecs see it: metadata JSON (codec id, codec config, scene geometry)
plus the codec's named sections, on top of :mod:`formats.container`."""
from __future__ import annotations

import json
import os
from dataclasses import dataclass

from .container import DEFAULT_CHUNK, Container, write_container
from .errors import FormatError, UnsupportedError
from .limits import DEFAULT, Limits

FORMAT_NAME = "lfc"


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


def write_lfc(path: str | os.PathLike, codec: str, codec_version: int, config: dict, scene: dict,
              sections: list[tuple[str, bytes]], *, extra: dict | None = None,
              chunk_size: int = DEFAULT_CHUNK) -> int:
    """Write an .lfc file atomically. Returns its size in bytes."""
    return write_container(path, encode_meta(codec, codec_version, config, scene, extra), sections, chunk_size)


@dataclass
class LfcFile:
    """An opened .lfc file: ``container`` for sections, ``meta`` for the parsed metadata."""

    container: Container
    meta: dict

    @property
    def codec(self) -> str:
        return self.meta["codec"]

    def close(self) -> None:
        self.container.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


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


def parse_meta(data, name: str, limits: Limits = DEFAULT) -> dict:
    """Strict, bounded parse of a metadata section: UTF-8 JSON (no NaN/Infinity), at most
    ``limits.max_meta_bytes`` bytes and ``limits.max_json_depth`` levels deep."""
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
    return LfcFile(c, meta)


def check_codec_version(f: LfcFile, codec: str, supported: int) -> None:
    if f.meta.get("codec") != codec:
        raise UnsupportedError(f"{f.container.name}: codec {f.meta.get('codec')!r} is not {codec!r}")
    v = f.meta.get("codec_version")
    if type(v) is not int or v < 1:              # FORMAT.md: every codec's versions start at 1
        raise FormatError(f"{f.container.name}: metadata codec_version must be an integer >= 1, got {v!r}")
    if v > supported:
        raise UnsupportedError(f"{f.container.name}: {codec} version {v} is newer than this decoder ({supported})")
