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
