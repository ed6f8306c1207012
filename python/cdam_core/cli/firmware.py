"""`cdam firmware check MODEL [--json OUT] [--report DIR] [--quiet]`: build the STM32F405
firmware for a model and check it under QEMU (equivalence with the Python model, instructions per
inference or step, sizes, no heap)."""
from __future__ import annotations

import json

from cdam_core.base.jsonio import write_text_atomic
from cdam_core.cli.common import CliError, CliIOError, add_outputs, check_io, note


def register(subparsers) -> None:
    p = subparsers.add_parser("firmware", help="build and check the STM32 firmware under QEMU")
    sub = p.add_subparsers(dest="firmware_command", metavar="ACTION")
    c = sub.add_parser("check", help="build for MODEL, run the equivalence and cost checks",
                       description="Cross-builds firmware_stubs/ for MODEL (any kind: "
                                   "bp_network, arx, hybrid, greybox, quad_physics, "
                                   "quad_hybrid) with arm-none-eabi-gcc, "
                                   "runs it on qemu-system-arm -M netduinoplus2 and prints the "
                                   "kind, flash_bytes, static_ram_bytes, heap_free, "
                                   "instructions per inference (network: 1,000 input vectors) "
                                   "or per step (dynamic kinds: a 1,000-row synthetic record in "
                                   "one-step, k-step and free run), microseconds_168mhz and "
                                   "max_abs_error against the Python model. Needs "
                                   "gcc-arm-none-eabi, libnewlib-arm-none-eabi, "
                                   "libstdc++-arm-none-eabi-newlib, qemu-system-arm, cmake and "
                                   "libeigen3-dev (`bash scripts/setup.sh --firmware` installs them); a missing "
                                   "one is named, with exit code 3.")
    c.add_argument("model", metavar="MODEL", help="model file (.json)")
    c.add_argument("--data", default=None, metavar="RECORD",
                   help="arx, hybrid, greybox, quad_physics, quad_hybrid: check on this record "
                        "(dataset CSV with the "
                        "model's input and output columns) instead of the synthetic one")
    c.add_argument("--horizon", type=int, default=10, metavar="K",
                   help="the dynamic kinds: k-step horizon compared besides one-step and free "
                        "run (1..64, default 10)")
    c.add_argument("--json", dest="json_out", default=None, metavar="FILE",
                   help="also write the results as JSON to FILE")
    add_outputs(c, json=False)
    c.add_argument("--build-dir", default=None, help="keep the build here (default: temporary)")
    c.add_argument("--timeout", type=float, default=60.0, help="seconds per QEMU run")
    c.set_defaults(func=run_check)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])


def run_check(args) -> int:
    from cdam_core.firmware import (check, firmware_sources, load_firmware_model,
                                    toolchain_available)

    check_io(inputs=[("MODEL", args.model), ("--data", args.data)],
             files=[("--json", args.json_out)],
             folders=[("--build-dir", args.build_dir), ("--report", args.report)])
    if not 1 <= args.horizon <= 64:
        raise CliError(f"--horizon: expected 1..64, got {args.horizon}")
    fm = load_firmware_model(args.model)     # a bad or unsupported model: exit 2, before tools
    record = _record(args.data, fm) if args.data else None
    why = toolchain_available() or firmware_sources()
    if why:
        raise CliIOError(f"cannot build the firmware: {why}")
    note(args, f"building the {fm.kind} firmware and running it under QEMU (about a minute)")
    try:
        report = check(args.model, build_dir=args.build_dir, timeout=args.timeout,
                       record=record, k=args.horizon)
    except RuntimeError as exc:
        raise CliError(str(exc)) from None
    text = json.dumps(report, indent=1)
    print(text)
    if args.json_out:
        write_text_atomic(args.json_out, text + "\n")
    if args.report:
        note(args, f"report: {_write_report(args.report, args.model, report)}")
    return 0


# the fields of the report's table, in order, with their meaning
_FIELDS = [("kind", "model kind"), ("network", "network size (inputs-hidden-outputs)"),
           ("flash_bytes", "flash: text + data of the smallest image holding the model [bytes]"),
           ("static_ram_bytes", "static RAM: data + bss [bytes]"),
           ("heap_free", "no heap use (a heap call fails the link)"),
           ("instructions_per_inference", "instructions per network inference"),
           ("instructions_per_step", "instructions per model step"),
           ("microseconds_168mhz", "at 168 MHz, one instruction a cycle (a lower bound) [us]"),
           ("max_abs_error", "largest difference from the Python model (one step) [output units]"),
           ("max_abs_error_free_run", "the same in free run [output units]"),
           ("sandbox", "how QEMU was confined")]


def _write_report(folder, model, report: dict):
    from cdam_core.report.summary import write_summary_report
    lines = [f"{key:<28} {report[key]}   ({what})" for key, what in _FIELDS if key in report]
    return write_summary_report(
        folder, "Firmware check", lines, report, source=f"model file {model}",
        notes="Built for the STM32F405 (Cortex-M4F, -fno-exceptions -fno-rtti) and run under "
              "qemu-system-arm -M netduinoplus2; instruction counts are QEMU's, not cycles "
              "measured on a board. Every field is in results.json.")


def _record(path, fm):
    """(U, Y) of the model's input and output columns in the record at ``path``."""
    import numpy as np
    from cdam_core.firmware import StepFirmwareModel
    from cdam_core.record.dataset import read_dataset
    if not isinstance(fm, StepFirmwareModel):
        raise CliError("--data: a bp_network model is checked on input vectors; --data is for "
                       "the dynamic kinds")
    ds = read_dataset(path, inputs=fm.inputs, outputs=fm.outputs)
    if len(ds) <= fm.history:
        raise CliError(f"--data: {len(ds)} rows; the model needs more than {fm.history}")
    if fm.kind in ("greybox", "quad_physics", "quad_hybrid"):
        dt = float(np.median(np.diff(ds.t)))
        if not np.isclose(dt, fm.floats["kDt"], rtol=1e-6, atol=0.0):
            raise CliError(f"--data: sampled every {dt:g} s; the model integrates at "
                           f"{fm.floats['kDt']:g} s")
    return (np.column_stack([ds.column(c) for c in fm.inputs]),
            np.column_stack([ds.column(c) for c in fm.outputs]))
