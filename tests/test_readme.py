"""The README's examples, run as written, so they cannot drift: the main job's lfcodec commands
(after its set-up part) and every ```python block, in a scratch folder holding the sample."""
import os
import re
import shlex
import subprocess
import sys

from formats.cli import main
from tests.conftest import ROOT

README = (ROOT / "README.md").read_text()


def _blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", README, flags=re.S)


def test_readme_main_job_and_python_examples(tmp_path, monkeypatch, capsys):
    (tmp_path / "samples").symlink_to(ROOT / "samples")
    monkeypatch.chdir(tmp_path)
    main_job = _blocks("bash")[0].strip()
    assert main_job.startswith("python3 -m venv .venv") and "lfcodec encode samples/dino_crop" in main_job
    steps = [s.strip() for s in main_job.split("&&")]
    run = [s for s in steps if s.startswith(("mkdir", "lfcodec"))]
    assert [s.split()[1] for s in run if s.startswith("lfcodec")] == ["encode", "decode", "info"]
    for step in run:
        argv = shlex.split(step)
        if argv[0] == "mkdir":
            os.makedirs(argv[-1], exist_ok=True)
        else:
            assert main(argv[1:]) == 0, step
    capsys.readouterr()
    for code in _blocks("python"):
        out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                             env={**os.environ, "PYTHONPATH": str(ROOT)})
        assert out.returncode == 0, out.stderr[-2000:]


def test_readme_test_command_is_the_ci_command():
    tests = _blocks("bash")[1].strip()
    ci = (ROOT / ".ci" / "run").read_text()
    assert tests.split("&&")[-1].strip() in ci
