"""Every model kind on the Cortex-M4F (needs arm-none-eabi-gcc and qemu-system-arm; returns {}
without them): `cdam firmware check` on one model of each kind, built here from the test
builders (tests/firmware/_kinds.py) and, where the shared data are there, from the EMPS record
(an ARX(2, 2, 1) and the grey-box model the residual loop finds on DATA_EMPS) and a nano-drone
flight (quad_physics).

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
    from cdam_core.record.realdata.emps import emps_path, load_emps
    from cdam_core.residual.analyse import analyse
    from cdam_core.residual.benchmark import greybox_of
    if not emps_path("DATA_EMPS").is_file():
        return {}
    d = load_emps("DATA_EMPS")
    U, Y = d["force"][:, None], d["qm"][:, None]
    save_model(tmp / "emps_arx.json", ArxModel((2, 2, 1)).fit(U, Y), inputs=["force"],
               outputs=["qm"])
    sel = analyse("rigid_axis", d["t"], {"tau": d["force"], "q": d["qm"]}, free_run=False)
    save_model(tmp / "emps_gb.json", greybox_of(sel.final, float(np.mean(np.diff(d["t"])))),
               inputs=["force"], outputs=["qm"])
    return {"arx_emps": tmp / "emps_arx.json", "greybox_emps": tmp / "emps_gb.json"}


def _nanodrone_model(tmp: Path) -> dict:
    """quad_physics (the documented defaults) fitted on the longest clean stretch of the
    nano-drone flight random1 run 1 ({} without the flights)."""
    import numpy as np
    from cdam_core.models import save_model
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
    return {"quad_physics_nanodrone": tmp / "nano.json"}


def bench_kinds() -> dict:
    if fw.toolchain_available():
        return {}
    k = _builders()
    t0 = time.perf_counter()
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        models = {"bp_network_demo": fw.FIRMWARE_DIR / "generated" / "demo_model.json",
                  **_emps_models(tmp),
                  "arx_physics": k.arx_file(tmp / "arxp.json", physics=True),
                  "hybrid": k.hybrid_file(tmp / "hybrid.json")[0],
                  "greybox_rigid_4_effects": k.greybox_file(tmp / "rigid.json"),
                  "greybox_flexible_6_effects": k.flexible_file(tmp / "flex.json"),
                  "greybox_quadrotor_4_effects": k.quadrotor_file(tmp / "quad.json"),
                  "greybox_aerial_manipulator_6_effects": k.aerial_file(tmp / "aerial.json"),
                  "quad_physics_lag_damping_reaction":
                      k.quad_physics_file(tmp / "quad_physics.json")[0],
                  **_nanodrone_model(tmp)}
        for name, path in models.items():
            rep = fw.check(path, build_dir=tmp / f"b_{name}")
            ips = rep.get("instructions_per_step", rep.get("instructions_per_prediction"))
            out[name] = {"instructions": ips, "us_168mhz": rep["microseconds_168mhz"],
                         "flash": rep["flash_bytes"], "static_ram": rep["static_ram_bytes"],
                         "error_one_step": rep.get("max_rel_error", rep["max_abs_error"]),
                         "error_k_step": rep.get("max_rel_error_k_step"),
                         "error_free_run": rep.get("max_rel_error_free_run"),
                         "heap_free": rep["heap_free"]}
    secs = time.perf_counter() - t0
    for name, r in out.items():
        print(f"firmware {name}: " + ", ".join(f"{a}={b}" for a, b in r.items()))
    worst = max(r["instructions"] for r in out.values())
    return {"ratio": BUDGET_CYCLES / worst, "seconds": secs, "worst_instructions": worst,
            **{f"{n}_instructions": r["instructions"] for n, r in out.items()}}


BENCHMARKS = {"firmware_kinds": bench_kinds}
