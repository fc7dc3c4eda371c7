"""The one-way architecture, checked statically (docs/ARCHITECTURE.md):

- ``formats`` imports nothing from ``rlfc``, ``lfn_stream`` or ``tools``;
- the codecs import ``formats`` and never each other; the library never imports ``tools``;
- no ``profile ==`` branch outside the RLFC profile modules.
"""
import ast
import re
from pathlib import Path

import pytest

from tests.conftest import ROOT

FORBIDDEN = {"formats": {"rlfc", "lfn_stream", "tools"}, "rlfc": {"lfn_stream", "tools"},
             "lfn_stream": {"rlfc", "tools"}}


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), str(path))
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module.split(".")[0])
    return out


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_dependency_direction(package):
    bad = []
    for f in sorted((ROOT / package).rglob("*.py")):
        hit = _imports(f) & FORBIDDEN[package]
        if hit:
            bad.append(f"{f.relative_to(ROOT)} imports {', '.join(sorted(hit))}")
    assert not bad, "imports against the dependency direction:\n" + "\n".join(bad)


#: the fuzzer's reference decoder: one self-contained reader written from FORMAT.md on purpose
#: (it must not share the plug-in structure it checks)
INDEPENDENT_READERS = {"refdecode.py", "reflfn.py"}


def test_no_profile_branches_outside_profile_modules():
    pat = re.compile(r"\bprofile\s*(==|!=)|==\s*profile\b|\bprofile\s+in\s*\(")
    bad = []
    for package in ("formats", "rlfc", "lfn_stream", "tools"):
        for f in sorted((ROOT / package).rglob("*.py")):
            if "profiles" in f.parts or f.name in INDEPENDENT_READERS:
                continue
            for i, line in enumerate(f.read_text().splitlines(), 1):
                if pat.search(line.split("#")[0]):
                    bad.append(f"{f.relative_to(ROOT)}:{i}: {line.strip()}")
    assert not bad, "profile branches outside rlfc/profiles:\n" + "\n".join(bad)


def test_the_checks_would_fail(tmp_path):
    """The checks above can fail: they catch a planted violation."""
    f = tmp_path / "x.py"
    f.write_text("import rlfc.decoder\nfrom tools.common import log\nfrom .y import z\n")
    assert _imports(f) == {"rlfc", "tools"}
