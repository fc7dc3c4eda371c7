"""Resource caps a decoder checks before it allocates anything a file's fields drive.

Defaults fit any light field this project has met with a wide margin; a caller with a
legitimately huge file passes its own :class:`Limits` (``open_decoder(f, limits=...)``).
The caps are listed in docs/FORMAT.md.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Limits:
    """Attributes:
        max_views: views in a light field (rows × cols).
        max_view_pixels: pixels in one view (H × W).
        max_open_pixels: pixels a decoder may hold decoded for the life of a file (key views,
            summed over all of them).
        max_tree_height: levels of a key-view hierarchy.
        max_scene_pixels: pixels of all views of a scene read from files (views × H × W).
        max_meta_bytes: size of the metadata JSON section.
        max_json_depth: nesting depth of the metadata JSON.
    """

    max_views: int = 1 << 16
    max_view_pixels: int = 1 << 26
    max_open_pixels: int = 1 << 28
    max_tree_height: int = 16
    max_scene_pixels: int = 1 << 32
    max_meta_bytes: int = 1 << 26
    max_json_depth: int = 32


DEFAULT = Limits()
