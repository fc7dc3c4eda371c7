"""Cross-grid tables from several ``python -m tools.bench`` runs: for each target PSNR, the file
the CLI's rate control wrote (whole file, PSNR reached ≥ target) against each peer's
rate-distortion curve interpolated at the same target, and the worst grid.

Usage:
    python -m tools.bench_table DIR [DIR ...] [--profile tx] [--extra POINTS.jsonl]

``--extra``: JSON lines {"scene", "codec", "points": [[setting, psnr, bpp], ...]} adding peer
points (e.g. JPEG 2000 at higher qualities than the bench swept).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from tools.bench import bpp_at

PEERS = ("JPEG 2000 (per view)", "JPEG XL (per view)", "HEVC x265 (pseudo-sequence)")
SHORT = {"JPEG 2000 (per view)": "J2K", "JPEG XL (per view)": "JXL", "HEVC x265 (pseudo-sequence)": "HEVC"}


def load(dirs, extra=None) -> dict:
    scenes = {}
    for d in dirs:
        r = json.loads((Path(d) / "results.json").read_text())
        scenes.update(r["scenes"])
    if extra:
        for line in Path(extra).read_text().splitlines():
            if line.strip():
                e = json.loads(line)
                scenes.setdefault(e["scene"], []).extend(
                    {"codec": e["codec"], "setting": str(s), "psnr_rgb": p, "bpp": b} for s, p, b in e["points"])
    return scenes


def ours_at(rows, profile: str, target: float):
    """(bpp, psnr) of the file written for ``target`` by the profile's rate control."""
    for r in rows:
        if r.get("codec") == f"lfcodec RLFC ({profile})" and r.get("setting") == f"target {target:g} dB" and "bpp" in r:
            return r["bpp"], r["psnr_rgb"]
    return None


def table(scenes: dict, profile: str, targets) -> list[str]:
    lines = []
    for t in targets:
        lines += [f"**{t:g} dB**", "", "| grid | " + profile + " bpp (PSNR reached) | " +
                  " | ".join(f"{SHORT[p]} bpp | ×{SHORT[p]}" for p in PEERS) + " |",
                  "|---|---|" + "---|---|" * len(PEERS)]
        worst = {p: (0, None) for p in PEERS}
        for name, rows in sorted(scenes.items()):
            got = ours_at(rows, profile, t)
            if got is None:
                continue
            cells = [name, f"{got[0]:.4f} ({got[1]:.2f})"]
            for p in PEERS:
                pb = bpp_at(rows, p, t)
                if pb:
                    r = got[0] / pb
                    cells += [f"{pb:.4f}", f"{r:.2f}×"]
                    if r > worst[p][0]:
                        worst[p] = (r, name)
                else:
                    cells += ["–", "–"]
            lines.append("| " + " | ".join(cells) + " |")
        cells = ["**worst grid**", ""]
        for p in PEERS:
            cells += ["", f"**{worst[p][0]:.2f}×** ({worst[p][1]})" if worst[p][1] else "–"]
        lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    return lines


def budget(scenes: dict, profile: str, target: float) -> list[str]:
    names = ["tx.layout", "tx.tables", "tx.maps", "tx.thumbs", "tx.keyimg", "tx.index", "tx.blocks"]
    lines = [f"| grid ({target:g} dB) | bytes | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    for name, rows in sorted(scenes.items()):
        for r in rows:
            if r.get("codec") == f"lfcodec RLFC ({profile})" and r.get("setting") == f"target {target:g} dB" \
                    and "sections" in r:
                tot = sum(r["sections"].values())
                lines.append(f"| {name} | {r['bytes']} | " + " | ".join(
                    f"{100 * r['sections'].get(n, 0) / tot:.0f}%" for n in names) + " |")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.bench_table", description=__doc__.split("\n\n")[0])
    ap.add_argument("dirs", nargs="+")
    ap.add_argument("--profile", default="tx")
    ap.add_argument("--targets", default="36,40,45,48")
    ap.add_argument("--extra", default=None)
    a = ap.parse_args(argv)
    scenes = load(a.dirs, a.extra)
    targets = [float(x) for x in a.targets.split(",")]
    print("\n".join(table(scenes, a.profile, targets) + ["Bit budget:", ""] + budget(scenes, a.profile, 40.0)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
