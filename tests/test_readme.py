"""The README works when pasted (issue 22 item 2): its commands call the project's venv
(`.venv/bin/...`), write only into `out/` (ignored by git), never over tracked files. The
first-use snippet and the fenced shell examples run as written in a plain clone in
tests/test_fresh_clone.py."""
import re
import shlex
import subprocess
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
FENCES = re.findall(r"^ *```(\w+)\n(.*?)^ *```", README, re.M | re.S)
OUTPUT_OPTIONS = ("-o", "--output", "--out", "--report", "--json", "--save", "--simulated")


def _bash_lines():
    lines = []
    for lang, body in FENCES:
        if lang == "bash":
            lines += [ln.split("#", 1)[0].strip() for ln in body.splitlines()]
    return [ln for ln in lines if ln]


def _venv_commands():
    """Every command line the README gives with .venv/bin/ (fenced or inline)."""
    inline = re.findall(r"`(\.venv/bin/[^`]+)`", README)
    return inline + [ln for ln in _bash_lines() if ln.startswith(".venv/bin/")]


def test_fenced_commands_use_the_venv_or_the_scripts():
    allowed = ("bash scripts/", ".venv/bin/", "mkdir ", "source .venv/bin/activate", "export ",
               "EXAMPLES=")
    for ln in _bash_lines():
        assert ln.startswith(allowed), f"README: {ln!r} does not run as pasted"


def test_commands_write_only_into_out():
    tracked = set(subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True,
                                 text=True).stdout.split())
    cmds = _venv_commands()
    assert len(cmds) >= 8
    for cmd in cmds:
        words = shlex.split(cmd)
        outs = [words[i + 1] for i, w in enumerate(words[:-1]) if w in OUTPUT_OPTIONS]
        if "cdam_core.cli.example" in words:
            outs.append(words[-1])
        for path in outs:
            if path.isupper() or path.startswith("/tmp/"):      # a placeholder, a scratch file
                continue
            assert path.startswith("out/"), f"README: {cmd!r} writes {path} outside out/"
            assert path not in tracked
    assert "/out/" in (ROOT / ".gitignore").read_text().split()
