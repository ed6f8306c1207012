"""Firmware side, split by job: the model as the firmware runs it (:mod:`.model`), generated
headers (:mod:`.export`), the cross build (:mod:`.build`), QEMU runs (:mod:`.qemu`),
``cdam firmware check`` (:mod:`.check`), processor in the loop (:mod:`.pil`: the joint loop;
:mod:`.monitor_pil`: the residual monitor over SLCAN).

The firmware (``firmware_stubs/``) runs the core's own ``cdam::Mlp`` (cpp/include/cdam/mlp.hpp)
with the fast activation of cdam/fast_math.hpp on the weights of ``generated/model.hpp``.
NARX models: the firmware works in the network's input space (the regressor). The exporter
writes one pair of scaling constants per regressor element (the output scaler's for past
outputs, the input scaler's for past inputs), so the firmware scales a raw regressor exactly as
``BPNetwork`` does. The dynamic kinds (arx, hybrid, greybox) run one sample at a time in
``fw::StepModel`` (firmware_stubs/include/fw/step_model.hpp), from :mod:`.step`. Only numbers
from a model file reach generated code.
"""
from cdam_core.firmware.build import IMAGES, STEP_IMAGES, build, heap_guard_works
from cdam_core.firmware.check import check, default_inputs, default_record
from cdam_core.firmware.export import (OPTIM_DATA_SEED, OPTIM_SAMPLES, OPTIM_SHAPE, export_header,
                                       export_optim_data, optim_data)
from cdam_core.firmware.model import (FirmwareModel, StepFirmwareModel, load_firmware_model,
                                      theta_fnv1a)
from cdam_core.firmware.paths import (ARM_GCC, FIRMWARE_DIR, QEMU, firmware_sources,
                                     missing_tools, toolchain_available)
from cdam_core.firmware.monitor_pil import monitor_pil
from cdam_core.firmware.pil import (JointPlant, closed_loop_pil, closed_loop_python,
                                    default_reference, pid_config)
from cdam_core.firmware.qemu import (run_equivalence, run_kernels, run_optim_host,
                                     run_optim_target, run_qemu, run_step_equivalence)

__all__ = [
    "ARM_GCC", "FIRMWARE_DIR", "FirmwareModel", "IMAGES", "JointPlant", "OPTIM_DATA_SEED",
    "OPTIM_SAMPLES", "OPTIM_SHAPE", "QEMU", "STEP_IMAGES", "StepFirmwareModel", "build", "check",
    "closed_loop_pil", "closed_loop_python", "default_inputs", "default_record",
    "default_reference", "export_header", "export_optim_data", "firmware_sources",
    "heap_guard_works", "load_firmware_model", "missing_tools", "monitor_pil", "optim_data", "pid_config",
    "run_equivalence", "run_kernels", "run_optim_host", "run_optim_target", "run_qemu",
    "run_step_equivalence", "theta_fnv1a", "toolchain_available",
]
