"""Codec registry: on-wire codec id → codec plug-in.

Codecs join through the ``lfcodec.codecs`` entry-point group (pyproject.toml: ``[project.
entry-points."lfcodec.codecs"]``, ``id = "package.module:CodecClass"``), as numcodecs does, or
at run time with :func:`register_codec`. Nothing here imports a codec until it is asked for.
The codecs this package ships (:data:`BUILTIN`) are found without scanning the installed
distributions' entry points (``importlib.metadata``'s import and scan cost every command ~60 ms
on the 2-core box); a codec registered at run time takes precedence over both.
"""
from __future__ import annotations

from importlib import import_module

from .codec_api import Codec
from .errors import UnsupportedError

GROUP = "lfcodec.codecs"
_registered: dict[str, type] = {}
#: the codecs this package ships, id → "module:Class": their entry points in pyproject.toml (a
#: test keeps the two the same)
BUILTIN = {"rlfc": "rlfc.codec:RlfcCodec", "lfn": "lfn_stream.codec:LfnCodec"}
_instances: dict[str, Codec] = {}


def register_codec(cls: type, codec_id: str | None = None) -> type:
    """Register a :class:`~formats.codec_api.Codec` subclass under its id (usable as a decorator)."""
    _registered[codec_id or cls.codec_id] = cls
    _instances.pop(codec_id or cls.codec_id, None)
    return cls


def _entry_points() -> dict:
    from importlib import metadata

    return {ep.name: ep for ep in metadata.entry_points(group=GROUP)}


def load_ref(ref: str):
    """The object an entry-point style reference ``"package.module:name"`` names (imported now)."""
    module, name = ref.split(":")
    return getattr(import_module(module), name)


def available_codecs() -> list[str]:
    """Ids of every codec that can be loaded."""
    return sorted(set(_registered) | set(BUILTIN) | set(_entry_points()))


def get_codec(codec_id: str) -> Codec:
    """The codec registered under ``codec_id`` (one shared instance)."""
    if codec_id in _instances:
        return _instances[codec_id]
    cls = _registered.get(codec_id)
    if cls is None and codec_id in BUILTIN:
        cls = load_ref(BUILTIN[codec_id])
    if cls is None:
        ep = _entry_points().get(codec_id)
        if ep is None:
            raise UnsupportedError(f"codec {codec_id!r} is not supported by this lfcodec "
                                   f"(known: {', '.join(available_codecs()) or 'none'})")
        cls = ep.load()
    inst = cls()
    if not isinstance(inst, Codec):
        raise UnsupportedError(f"codec {codec_id!r} does not implement formats.codec_api.Codec")
    _instances[codec_id] = inst
    return inst


def open_decoder(f, **kw):
    """A decoder for an opened :class:`~formats.lfcfile.LfcFile`, chosen by its codec id."""
    return get_codec(f.codec).open(f, **kw)


def describe(f) -> dict:
    """What ``lfcodec info`` says of an opened :class:`~formats.lfcfile.LfcFile`: its codec's
    :meth:`~formats.codec_api.Codec.describe`."""
    return get_codec(f.codec).describe(f)


def set_codec(source) -> Codec | None:
    """The codec whose sets of files (:attr:`Codec.set_suffix`) ``source`` (a path or URL) names,
    or None: such a source is opened with :func:`open_set`, not as an .lfc file. A name ending in
    ``.lfc`` is a file of the container itself (no set's manifest: no plug-in is loaded to ask)."""
    name = str(source).lower()
    if name.endswith(".lfc"):
        return None
    for cid in available_codecs():
        suffix = get_codec(cid).set_suffix
        if suffix and name.endswith(suffix):
            return get_codec(cid)
    return None


def open_set(source, **kw):
    """Open a set of files by its manifest (path or URL), through the codec that writes such sets."""
    codec = set_codec(source)
    if codec is None:
        raise UnsupportedError(f"{source}: no codec opens sets of files named like this")
    return codec.open_set(source, **kw)
