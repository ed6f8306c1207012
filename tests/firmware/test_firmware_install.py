"""Installed, not only cloned: the firmware sources ship as package data, and a missing
toolchain is named with the packages that provide it (exit code 3), no toolchain needed."""
import os
import sys
from pathlib import Path

import numpy as np
import pytest

import cdam_core
from cdam_core import firmware as fw
from cdam_core.cli.main import main

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _kinds import arx_file  # noqa: E402


def test_installed_package_ships_the_firmware_sources():
    pkg = Path(cdam_core.__file__).resolve().parent
    if os.environ.get("CDAM_FIRMWARE_DIR"):
        pytest.skip("CDAM_FIRMWARE_DIR is set: the package data is not used")
    if (pkg.parents[1] / "firmware_stubs" / "CMakeLists.txt").is_file():
        pytest.skip("cdam_core is imported from a source checkout; scripts/test.sh runs this "
                    "test on the installed package")
    assert fw.FIRMWARE_DIR == pkg / "firmware_src" / "firmware_stubs"
    assert fw.firmware_sources() is None
    # what the cross build reads: the project, the toolchain file, the linker script, the
    # sources of every image, the headers, the checked-in header and the core's headers
    for rel in ("CMakeLists.txt", "cmake/arm-none-eabi.cmake", "netduinoplus2.ld",
                "src/startup.cpp", "src/main_step_check.cpp", "include/fw/step_model.hpp",
                "src/main_monitor_pil.cpp", "include/fw/monitor_pil.hpp",
                "include/fw/slcan_port.hpp", "include/fw/quad_body.hpp",
                "include/fw/quad_physics_step.hpp", "include/fw/quad_hybrid_step.hpp",
                "generated/model.hpp", "generated/optim_data.hpp"):
        assert (fw.FIRMWARE_DIR / rel).is_file(), rel
    assert (fw.FIRMWARE_DIR.parent / "cpp" / "include" / "cdam" / "mlp.hpp").is_file()


def _empty_path(monkeypatch, tmp_path):
    bare = tmp_path / "bin"
    bare.mkdir()
    monkeypatch.setenv("PATH", str(bare))


def test_missing_toolchain_is_named_with_the_packages(monkeypatch, tmp_path):
    _empty_path(monkeypatch, tmp_path)
    why = fw.toolchain_available()
    for tool in ("arm-none-eabi-gcc", "qemu-system-arm", "cmake"):
        assert tool in why
    assert ("apt-get install gcc-arm-none-eabi libnewlib-arm-none-eabi "
            "libstdc++-arm-none-eabi-newlib") in why
    assert "qemu-system-arm" in why.split("apt-get install", 1)[1]
    assert [w for w, _ in fw.missing_tools()][:2] == ["arm-none-eabi-gcc", "arm-none-eabi-g++"]


def test_cli_check_without_toolchain_exits_3_naming_it(monkeypatch, tmp_path, capsys):
    model = arx_file(tmp_path / "arx.json")
    _empty_path(monkeypatch, tmp_path)
    out = tmp_path / "rep.json"
    assert main(["firmware", "check", str(model), "--json", str(out)]) == 3
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("cdam firmware: error:")
    assert "arm-none-eabi-gcc" in err and "apt-get install gcc-arm-none-eabi" in err
    assert "bash scripts/setup.sh --firmware" in err       # the set-up step that installs them
    assert "--firmware" in (Path(__file__).resolve().parents[2] / "scripts" / "setup.sh").read_text()
    assert not out.exists()


def test_cli_check_bad_model_is_2_before_the_toolchain(monkeypatch, tmp_path, capsys):
    _empty_path(monkeypatch, tmp_path)
    bad = tmp_path / "bad.json"
    bad.write_text("{")
    assert main(["firmware", "check", str(bad)]) == 2
    assert "arm-none-eabi" not in capsys.readouterr().err


def test_missing_eigen_is_named(monkeypatch, tmp_path):
    from cdam_core.firmware import paths
    monkeypatch.setattr(paths, "EIGEN_DIRS", (str(tmp_path / "none"),))
    monkeypatch.setenv("EIGEN3_ROOT", str(tmp_path / "none"))
    paths._missing_tools.cache_clear()
    try:
        assert ("Eigen 3 headers", "libeigen3-dev") in paths.missing_tools()
    finally:
        paths._missing_tools.cache_clear()


def test_cli_check_data_is_checked_before_building(monkeypatch, tmp_path, capsys):
    from _kinds import greybox_file
    from cdam_core.record.dataset import Dataset, write_dataset
    model = greybox_file(tmp_path / "gb.json", inputs=("tau", "load"))
    _empty_path(monkeypatch, tmp_path)           # no toolchain: the record is refused first
    rec = tmp_path / "rec.csv"
    t = np.arange(50) * 0.002                    # the model integrates at 1 ms
    write_dataset(rec, Dataset(t, ["tau", "load", "q"], np.zeros((50, 3))))
    assert main(["firmware", "check", str(model), "--data", str(rec)]) == 2
    assert "0.002 s" in capsys.readouterr().err
    write_dataset(rec, Dataset(t / 2, ["tau", "q"], np.zeros((50, 2))))
    assert main(["firmware", "check", str(model), "--data", str(rec)]) == 2
    assert "load" in capsys.readouterr().err      # the missing column, named
    net = fw.FIRMWARE_DIR / "generated" / "demo_model.json"
    assert main(["firmware", "check", str(net), "--data", str(rec)]) == 2
    assert "bp_network" in capsys.readouterr().err
