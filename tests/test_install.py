"""`pip install .` without Debian's Eigen (issue 22 item 1): CMake takes Eigen 3.4 from the PyPI
package cmeel-eigen (a build requirement) when the system has none. Here the system's Eigen is
skipped (CDAM_EIGEN=python, what a machine without libeigen3-dev sees), the project configured,
and the core's headers compiled against the headers CMake found."""
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _tool(name):
    p = Path(sys.prefix) / "bin" / name
    return str(p) if p.is_file() else shutil.which(name)


def test_eigen_comes_from_the_python_package_when_the_system_has_none(tmp_path):
    if not (ROOT / "CMakeLists.txt").is_file():
        pytest.fail("needs the source checkout (CMakeLists.txt)")
    cmake = _tool("cmake")
    assert cmake, "cmake not found (pip install cmake)"
    assert "cmeel-eigen" in (ROOT / "pyproject.toml").read_text().split("[project]")[0]
    r = subprocess.run([cmake, "-S", str(ROOT), "-B", str(tmp_path / "b"),
                        "-DCDAM_PYTHON=OFF", "-DCDAM_TESTS=OFF", "-DCDAM_EIGEN=python",
                        f"-DPython_EXECUTABLE={sys.executable}"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    m = re.search(r"Eigen (3\.4\.\d+) from (\S+)", r.stdout)
    assert m, r.stdout
    cmake_dir = Path(m.group(2))
    assert "cmeel.prefix" in cmake_dir.parts and not str(cmake_dir).startswith("/usr/")
    include = cmake_dir.parents[2] / "include" / "eigen3"
    assert (include / "Eigen" / "Core").is_file()
    cxx = shutil.which("c++") or shutil.which("g++")
    src = tmp_path / "probe.cpp"
    src.write_text("#include <cdam/mlp.hpp>\n#include <cdam/levenberg_marquardt.hpp>\n"
                   "#include <Eigen/Core>\n"
                   "static_assert(EIGEN_WORLD_VERSION == 3 && EIGEN_MAJOR_VERSION == 4, \"3.4\");\n"
                   "int main() { return 0; }\n")
    r = subprocess.run([cxx, "-std=c++17", "-fsyntax-only", "-w",
                        f"-I{ROOT / 'cpp' / 'include'}", f"-isystem{include}", str(src)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]


def test_a_missing_eigen_is_named_with_the_fix(tmp_path):
    """A Python without cmeel-eigen and the system's Eigen skipped: the configure step stops
    with one message naming both remedies."""
    py = tmp_path / "py"
    py.mkdir()
    fake = py / "python3"           # an interpreter whose sys.path holds no cmeel.prefix
    fake.write_text(f"#!/bin/sh\nexec {sys.executable} -I -S \"$@\"\n")
    fake.chmod(0o755)
    r = subprocess.run([_tool("cmake"), "-S", str(ROOT), "-B", str(tmp_path / "b"),
                        "-DCDAM_PYTHON=OFF", "-DCDAM_EIGEN=python", f"-DPython_EXECUTABLE={fake}"],
                       capture_output=True, text=True, timeout=300)
    out = " ".join((r.stdout + r.stderr).split())
    assert r.returncode != 0
    assert "Eigen 3.4 not found" in out and "pip install cmeel-eigen" in out
    assert "libeigen3-dev" in out


def test_setup_builds_a_committed_tree_once(tmp_path):
    """scripts/setup.sh records the commit's tree it built into .venv and skips the build when
    asked again for the same tree; an uncommitted change (or another commit) builds again and
    an uncommitted build records nothing. Run on a scratch repository with a stand-in
    .venv/bin/python that logs its calls (pip succeeds without doing anything)."""
    for pkg in ("g++", "python3-venv", "python3-dev"):      # else setup.sh would call apt-get
        r = subprocess.run(["dpkg-query", "-W", "-f=${Status}", pkg], capture_output=True,
                           text=True)
        if "install ok installed" not in r.stdout:
            pytest.skip(f"{pkg} is not installed: setup.sh would install it with apt-get")
    repo = tmp_path / "repo"
    (repo / "scripts").mkdir(parents=True)
    shutil.copy(ROOT / "scripts" / "setup.sh", repo / "scripts" / "setup.sh")
    (repo / ".gitignore").write_text("build/\n")
    (repo / "a.txt").write_text("1\n")
    venv_bin = repo / ".venv" / "bin"
    venv_bin.mkdir(parents=True)
    calls = tmp_path / "calls"
    py = venv_bin / "python"
    py.write_text(f'#!/bin/sh\necho "$*" >> {calls}\n'
                  'case "$*" in *"print(\'setup: cdam_core\'"*) echo "setup: cdam_core 0 ready";; '
                  'esac\nexit 0\n')
    py.chmod(0o755)
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@example.org"]

    def setup():
        calls.write_text("")
        r = subprocess.run(["bash", "scripts/setup.sh"], cwd=repo, capture_output=True,
                           text=True, timeout=120)
        assert r.returncode == 0, r.stdout + r.stderr
        return r.stdout, "-m pip install --no-build-isolation" in calls.read_text()

    def tree():
        return subprocess.run(["git", "rev-parse", "HEAD^{tree}"], cwd=repo, text=True,
                              capture_output=True, check=True).stdout.strip()
    stamp = repo / ".venv" / "cdam-setup.stamp"
    subprocess.run(["git", "init", "-q"], cwd=repo, check=True)
    subprocess.run(git + ["add", "a.txt", ".gitignore", "scripts"], cwd=repo, check=True)
    subprocess.run(git + ["commit", "-qm", "one"], cwd=repo, check=True)
    # .venv untracked and not ignored, as the fresh-clone test's link: excluded by name
    assert "?? .venv/" in subprocess.run(["git", "status", "--porcelain"], cwd=repo,
                                         capture_output=True, text=True).stdout
    out, built = setup()
    assert built and stamp.read_text().split() == [tree()]
    out, built = setup()
    assert not built and out.startswith("setup: cdam_core already built from this commit's tree")
    (repo / "a.txt").write_text("2\n")                       # uncommitted: built, not recorded
    out, built = setup()
    assert built and not stamp.exists()
    out, built = setup()
    assert built and not stamp.exists()
    subprocess.run(git + ["commit", "-qam", "two"], cwd=repo, check=True)
    out, built = setup()
    assert built and stamp.read_text().split() == [tree()]
    out, built = setup()
    assert not built
