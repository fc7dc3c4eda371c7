"""An .lfc file as the codecs see it: metadata JSON (codec id, codec config, scene geometry)
plus the codec's named sections, on top of :mod:`formats.container`."""
from __future__ import annotations

import json
import os
from dataclasses import dataclass

from .container import DEFAULT_CHUNK, Container, write_container
from .errors import FormatError, UnsupportedError

FORMAT_NAME = "lfc"


def encode_meta(codec: str, codec_version: int, config: dict, scene: dict, extra: dict | None = None) -> bytes:
    """UTF-8 JSON of the file's metadata section."""
    from . import __version__

    meta = {"format": FORMAT_NAME, "codec": codec, "codec_version": codec_version, "config": config,
            "scene": scene, "encoder": f"lfcodec {__version__}"}
    if extra:
        meta.update(extra)
    return json.dumps(meta, separators=(",", ":"), sort_keys=True).encode()


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


def open_lfc(source, *, name: str | None = None, partial: bool = False) -> LfcFile:
    """Open an .lfc file (path, bytes or ByteRangeSource) and parse its metadata.

    ``partial=True`` accepts a byte prefix of a file (progressive streams): sections past the
    prefix are reported unavailable instead of the file being rejected as truncated.
    """
    c = Container(source, name=name, partial=partial)
    try:
        meta = json.loads(bytes(c.read("meta")).decode("utf-8"))
        if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME or "codec" not in meta:
            raise FormatError(f"{c.name}: metadata is not lfcodec metadata")
    except (ValueError, UnicodeDecodeError) as e:
        c.close()
        raise FormatError(f"{c.name}: metadata section is not valid JSON ({e})") from None
    except Exception:
        c.close()
        raise
    return LfcFile(c, meta)


def check_codec_version(f: LfcFile, codec: str, supported: int) -> None:
    if f.meta.get("codec") != codec:
        raise UnsupportedError(f"{f.container.name}: codec {f.meta.get('codec')!r} is not {codec!r}")
    if int(f.meta.get("codec_version", 0)) > supported:
        raise UnsupportedError(f"{f.container.name}: {codec} version {f.meta['codec_version']} is newer than "
                               f"this decoder ({supported})")
