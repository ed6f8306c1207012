"""Child process of the file fuzz: runs `cdam` commands in-process, one per line of a JSON case
file, and prints one JSON line per case (exit code, traceback seen). Before each case it prints
``start I`` so that the parent can name the case that killed it."""
import contextlib
import io
import json
import sys

from cdam_core.cli.main import main

cases = json.loads(open(sys.argv[1]).read())
first = int(sys.argv[2]) if len(sys.argv) > 2 else 0
for i in range(first, len(cases)):
    print(f"start {i}", flush=True)
    out, err = io.StringIO(), io.StringIO()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            rc = main(cases[i])
    except SystemExit as exc:          # argparse usage errors
        rc = exc.code if isinstance(exc.code, int) else 2
    except BaseException as exc:       # noqa: BLE001 - an escape from main is a finding
        rc, err = -1, io.StringIO(f"escaped main: {type(exc).__name__}: {exc}")
    text = out.getvalue() + err.getvalue()
    print(json.dumps({"i": i, "rc": rc, "traceback": "Traceback" in text,
                      "stderr": err.getvalue()[-300:]}), flush=True)
