"""Every model kind on the Cortex-M4F (needs arm-none-eabi-gcc and qemu-system-arm; returns {}
without them): `cdam firmware check` on one model of each kind, built here from the test
builders (tests/firmware/_kinds.py) and, where the shared data are there, from the EMPS record
(an ARX(2, 2, 1) and the grey-box model the residual loop finds on DATA_EMPS) and a nano-drone
flight (quad_physics and quad_hybrid).

"ratio": the 1 kHz loop's budget on a 168 MHz STM32F405 (168,000 cycles) over the instructions
per step of the costliest kind measured in this run (one instruction a cycle, a lower bound on
the cycles): the headroom at 1 kHz. Per kind: instructions per step (mean), microseconds at
168 MHz, flash (text + data) and static RAM (data + bss) of the smallest image with the model,
and the largest error of an output over its span against the Python model (one-step, k-step
with k = 10, free run).
"""
from __future__ import annotations

import importlib.util
import tempfile
import time
from pathlib import Path

from cdam_core import firmware as fw

BUDGET_CYCLES = 168_000   # 1 ms at 168 MHz


def _builders():
    path = Path(__file__).resolve().parents[1] / "tests" / "firmware" / "_kinds.py"
    spec = importlib.util.spec_from_file_location("_kinds", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _emps_models(tmp: Path) -> dict:
    """ARX(2, 2, 1) and the residual loop's grey-box model on DATA_EMPS ({} without the data)."""
    import numpy as np
    from cdam_core.models import ArxModel, save_model
    from cdam_core.record.realdata.emps import EMPS_UNITS, emps_path, load_emps
    from cdam_core.residual.analyse import analyse
    from cdam_core.residual.benchmark import greybox_of
    if not emps_path("DATA_EMPS").is_file():
        return {}
    d = load_emps("DATA_EMPS")
    U, Y = d["force"][:, None], d["qm"][:, None]
    save_model(tmp / "emps_arx.json", ArxModel((2, 2, 1)).fit(U, Y), inputs=["force"],
               outputs=["qm"])
    sel = analyse("rigid_axis", d["t"], {"tau": d["force"], "q": d["qm"]}, free_run=False,
                  units=EMPS_UNITS)
    save_model(tmp / "emps_gb.json", greybox_of(sel.final, float(np.mean(np.diff(d["t"])))),
               inputs=["force"], outputs=["qm"])
    return {"arx_emps": tmp / "emps_arx.json", "greybox_emps": tmp / "emps_gb.json"}


def _nanodrone_model(tmp: Path) -> dict:
    """quad_physics and quad_hybrid (the documented defaults: 8 units, 6 lags, K = 50)
    fitted on the longest clean stretch of the nano-drone flight random1 run 1 ({} without
    the flights)."""
    import numpy as np
    from cdam_core.models import save_model
    from cdam_core.models.flight.hybrid import QuadHybrid
    from cdam_core.models.flight.physics import QuadPhysics
    from cdam_core.record.realdata import shared_data_dir
    from cdam_core.record.realdata.nanodrone import INPUTS, STATES, load_nanodrone
    path = shared_data_dir() / "nanodrone" / "random1_20251017_run1.parquet"
    if not path.is_file():
        return {}
    ds = load_nanodrone(path)
    a, b = max(ds.segments, key=lambda s: s[1] - s[0])
    U = np.column_stack([ds.column(c) for c in INPUTS])[a:b]
    Y = np.column_stack([ds.column(c) for c in STATES])[a:b]
    save_model(tmp / "nano.json", QuadPhysics(dt=0.01).fit(U, Y))
    save_model(tmp / "nano_hybrid.json", QuadHybrid(dt=0.01, threads=1).fit(U, Y))
    return {"quad_physics_nanodrone": tmp / "nano.json",
            "quad_hybrid_nanodrone": tmp / "nano_hybrid.json"}


def _models(tmp: Path, network: dict) -> dict:
    """One model file of each kind (``network``: the bp_network entry), written into tmp."""
    k = _builders()
    return {**network, **_emps_models(tmp),
            "arx_physics": k.arx_file(tmp / "arxp.json", physics=True),
            "hybrid": k.hybrid_file(tmp / "hybrid.json")[0],
            "greybox_rigid_4_effects": k.greybox_file(tmp / "rigid.json"),
            "greybox_flexible_6_effects": k.flexible_file(tmp / "flex.json"),
            "greybox_quadrotor_4_effects": k.quadrotor_file(tmp / "quad.json"),
            "greybox_aerial_manipulator_6_effects": k.aerial_file(tmp / "aerial.json"),
            "greybox_aerial_manipulator_arm_coupling": k.arm_coupling_file(tmp / "arm.json")[0],
            "quad_physics_lag_damping_reaction": k.quad_physics_file(tmp / "quad_physics.json")[0],
            "quad_hybrid_4_units_3_lags": k.quad_hybrid_file(tmp / "quad_hybrid.json")[0],
            **_nanodrone_model(tmp)}


def _each_kind(network, measure, total: str, label: str) -> dict:
    """``measure(tmp, name, path)`` on one model of each kind (``network(tmp)``: the bp_network
    entry); prints each and returns the headroom at 1 kHz over the largest ``total``."""
    if fw.toolchain_available():
        return {}
    t0 = time.perf_counter()
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for name, path in _models(tmp, network(tmp)).items():
            out[name] = measure(tmp, name, path)
    secs = time.perf_counter() - t0
    for name, r in out.items():
        print(f"{label} {name}: " + ", ".join(f"{a}={b}" for a, b in r.items()))
    worst = max(r[total] for r in out.values())
    return {"ratio": BUDGET_CYCLES / worst, "seconds": secs, "worst_instructions": worst,
            **{f"{n}_instructions": r[total] for n, r in out.items()}}


def _check_figures(tmp, name, path) -> dict:
    rep = fw.check(path, build_dir=tmp / f"b_{name}")
    ips = rep.get("instructions_per_step", rep.get("instructions_per_prediction"))
    return {"instructions": ips, "us_168mhz": rep["microseconds_168mhz"],
            "flash": rep["flash_bytes"], "static_ram": rep["static_ram_bytes"],
            "error_one_step": rep.get("max_rel_error", rep["max_abs_error"]),
            "error_k_step": rep.get("max_rel_error_k_step"),
            "error_free_run": rep.get("max_rel_error_free_run"),
            "heap_free": rep["heap_free"]}


def bench_kinds() -> dict:
    return _each_kind(lambda tmp: {"bp_network_demo":
                                   fw.FIRMWARE_DIR / "generated" / "demo_model.json"},
                      _check_figures, "instructions", "firmware")


def _with_monitor(path, out, seed: int = 0):
    """The model file of ``path`` with a monitor section calibrated on its default record (the
    free run of cdam firmware check's synthetic input) plus white noise of 1e-3 of each
    output's span (seeded), so that the residual has a spread to normalise by."""
    import numpy as np
    from cdam_core.evaluate.monitor import calibrate
    from cdam_core.models.file import read_model_file, save_model
    from cdam_core.firmware.step import step_model
    mf = read_model_file(path)
    fm = step_model(mf)            # a network too: one sample at a time, as with a monitor
    U, Y = fw.default_record(fm)   # 1,000 rows, as the check (longer: an unstable mode grows)
    Y = Y + 1e-3 * np.ptp(Y, axis=0) * np.random.default_rng(seed).standard_normal(Y.shape)
    dt = float(getattr(mf.model, "dt", None) or 1e-3)
    save_model(out, mf.model, inputs=mf.inputs, outputs=mf.outputs,
               smoothing_passes=mf.smoothing_passes, meta=mf.meta,
               monitor=calibrate(mf.model, U, Y, dt, paths=100, seed=seed))
    return out


def _narx_network(path):
    """A NARX bp_network (2, 2, 1), 2 inputs, 2 outputs, 8 hidden units, on a damped linear
    plant driven by held random levels (seeded)."""
    import numpy as np
    from cdam_core.models import BPNetwork, save_model
    rng = np.random.default_rng(1)
    U = np.repeat(rng.uniform(-1, 1, (20, 2)), 100, axis=0)
    Y = np.zeros((2000, 2))
    for t in range(2, 2000):
        Y[t, 0] = 1.6 * Y[t - 1, 0] - 0.64 * Y[t - 2, 0] + 0.04 * U[t - 1, 0]
        Y[t, 1] = 0.9 * Y[t - 1, 1] + 0.05 * Y[t - 1, 0] + 0.1 * U[t - 1, 1]
    save_model(path, BPNetwork(hidden=8, narx=(2, 2, 1), epochs=50).fit(U, Y),
               inputs=["u0", "u1"], outputs=["y0", "y1"])
    return path


def _monitor_figures(tmp, name, path) -> dict:
    rep = fw.check(_with_monitor(path, tmp / f"{name}_monitor.json"),
                   build_dir=tmp / f"b_{name}", k=2)
    step, upd = rep["instructions_per_step"], rep["instructions_per_monitor"]
    return {"step": step, "monitor": upd, "total": round(step + upd, 1),
            "us_168mhz": round((step + upd) / 168, 2),
            "flash": rep["flash_bytes"], "static_ram": rep["static_ram_bytes"],
            "monitor_mismatches": rep["monitor_mismatches"],
            "error_one_step": rep["max_rel_error"]}


def bench_kinds_monitor() -> dict:
    """Every kind that reaches the board with its residual monitor: the model's step plus the
    monitor's update per sample (instructions, microseconds at 168 MHz), fw_step's flash and
    static RAM with the monitor, and the monitor's decisions against Python's (mismatches)."""
    return _each_kind(lambda tmp: {"bp_network_narx_8_hidden": _narx_network(tmp / "net.json")},
                      _monitor_figures, "total", "firmware+monitor")


BENCHMARKS = {"firmware_kinds": bench_kinds, "firmware_kinds_monitor": bench_kinds_monitor}
