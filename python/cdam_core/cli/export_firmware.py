"""`cdam export-firmware MODEL -o firmware_stubs/generated/model.hpp`."""
from __future__ import annotations


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "export-firmware", help="write a model file as a C++ header for the STM32 firmware",
        description="Export a model file (cdam_core.save_model) to a header with constexpr "
                    "float32 weights, sizes, scaling constants and the model's sha256, for "
                    "firmware_stubs/ (cdam::Mlp with the fast activation).")
    p.add_argument("model", metavar="MODEL", help="model file (.json)")
    p.add_argument("-o", "--output", required=True, help="header to write (model.hpp)")
    p.set_defaults(func=run)


def run(args) -> int:
    from cdam_core.cli.common import check_io
    from cdam_core.firmware import export_header, load_firmware_model

    check_io(inputs=[("MODEL", args.model)], files=[("-o", args.output)])

    fm = load_firmware_model(args.model)
    out = export_header(fm, args.output)
    print(f"{fm.n_inputs}-{fm.hidden}-{fm.n_outputs} {fm.activation} network "
          f"(sha256 {fm.sha256[:12]}...) -> {out}")
    return 0
