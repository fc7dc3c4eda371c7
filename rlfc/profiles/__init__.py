"""RLFC profiles, found by the id stored in a file (``config.profile``).

Built-in profiles are listed here by module; others join through the ``lfcodec.rlfc_profiles``
entry-point group (``id = "package.module:PROFILE"``). Nothing is imported until asked for.
"""
from __future__ import annotations

from formats.errors import UnsupportedError
from formats.registry import load_ref

from .base import Profile, ProfileDecoder

BUILTIN = {
    "bise": "rlfc.profiles.bise:PROFILE",      # the paper's: Gaussian key-view tree, BISE blocks
    "dcp": "rlfc.profiles.dcp:PROFILE",        # disparity-compensated prediction, BISE blocks
    "tx": "rlfc.profiles.tx:PROFILE",          # multi-key prediction, transform + rANS residuals
}
GROUP = "lfcodec.rlfc_profiles"
_cache: dict[str, Profile] = {}


def _entry_points() -> dict:
    from importlib import metadata       # (only for profiles not built in: its import costs ~50 ms)

    return {ep.name: ep for ep in metadata.entry_points(group=GROUP)}


def available_profiles() -> list[str]:
    return sorted(set(BUILTIN) | set(_entry_points()))


def get_profile(pid: str) -> Profile:
    """The profile registered under on-wire id ``pid``."""
    if pid not in _cache:
        ref = BUILTIN.get(pid)
        if ref is None:
            eps = _entry_points()
            if pid not in eps:
                raise UnsupportedError(f"RLFC profile {pid!r} is not supported by this lfcodec "
                                       f"(known: {', '.join(available_profiles())})")
            prof = eps[pid].load()
        else:
            prof = load_ref(ref)
        _cache[pid] = prof
    return _cache[pid]


__all__ = ["Profile", "ProfileDecoder", "get_profile", "available_profiles"]
