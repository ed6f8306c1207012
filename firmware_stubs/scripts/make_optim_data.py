"""Write firmware_stubs/generated/optim_data.hpp: the 200 training samples of the on-board
IBOA-BP run (check 3), held in flash. Run from the repository root:
    PYTHONPATH=python python3 firmware_stubs/scripts/make_optim_data.py
tests/test_firmware_export.py checks that the checked-in header equals a fresh export.
"""
from __future__ import annotations

from cdam_core import firmware


def main() -> int:
    out = firmware.FIRMWARE_DIR / "generated" / "optim_data.hpp"
    firmware.export_optim_data(out)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
