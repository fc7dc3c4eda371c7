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


def test_cli_start_imports_no_torch():
    """Every ``lfcodec`` command builds a parser that loads each codec to list its options; an
    RLFC command must not pay torch's import (about 1.3 s on the 2-core box): the LFN plug-in
    and ``lfn_stream`` load torch only when a network is built, trained or rendered."""
    import subprocess
    import sys

    code = ("import sys, lfn_stream, lfn_stream.codec\n"
            "from formats.cli import build_parser\n"
            "build_parser().parse_args(['info', 'x.lfc'])\n"
            "assert 'torch' not in sys.modules, 'torch imported'\n"
            "assert lfn_stream.LfnConfig().max_neurons > 0 and 'torch' not in sys.modules\n"
            "lfn_stream.NestedLFN\n"
            "assert 'torch' in sys.modules\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
