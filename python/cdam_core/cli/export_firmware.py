"""`cdam export-firmware MODEL -o firmware_stubs/generated/model.hpp`."""
from __future__ import annotations


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "export-firmware", help="write a model file as a C++ header for the STM32 firmware",
        description="Export a model file (cdam_core.save_model) of any kind to a header of "
                    "constexpr numbers for firmware_stubs/: bp_network (float32 weights, "
                    "sizes, scaling constants; cdam::Mlp with the fast activation), arx and "
                    "hybrid (ARX coefficients, the residual network), greybox (the declared "
                    "model's parameters and the effects found, as codes and numbers; "
                    "fw/step_model.hpp), quad_physics (the flight model's parameters, lag "
                    "kernel and delays; fw/quad_physics_step.hpp), quad_hybrid (the "
                    "physics with its rate network's weights and scales; "
                    "fw/quad_hybrid_step.hpp). Only numbers reach the header, never a name or "
                    "text from the file.")
    p.add_argument("model", metavar="MODEL", help="model file (.json)")
    p.add_argument("-o", "--output", required=True, help="header to write (model.hpp)")
    p.set_defaults(func=run)


def run(args) -> int:
    from cdam_core.cli.common import check_io
    from cdam_core.firmware import StepFirmwareModel, export_header, load_firmware_model

    check_io(inputs=[("MODEL", args.model)], files=[("-o", args.output)])

    fm = load_firmware_model(args.model)
    out = export_header(fm, args.output)
    what = (fm.describe() if isinstance(fm, StepFirmwareModel)
            else f"{fm.n_inputs}-{fm.hidden}-{fm.n_outputs} {fm.activation} network")
    print(f"{what} (sha256 {fm.sha256[:12]}...) -> {out}")
    return 0
