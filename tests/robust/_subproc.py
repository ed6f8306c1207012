"""Run a snippet against ``cdam_core._core`` in a child interpreter, so that a segfault or a hang
is a test failure instead of the end of pytest. The child inherits the environment (so
``CDAM_CORE_EXT_DIR`` / ``PYTHONPATH`` select the same build as the tests) and reports one JSON
line: the exception type and message, or ``"ok"`` with a repr of the result."""
import json
import os
import signal
import subprocess
import sys
import textwrap
import time

PRELUDE = textwrap.dedent("""
    import json, sys
    import numpy as np
    from cdam_core import _core
    def report(f):
        try:
            r = f()
        except BaseException as e:  # noqa: BLE001 - the parent judges the type
            print(json.dumps({"type": type(e).__name__, "message": str(e)}), flush=True)
        else:
            print(json.dumps({"type": "ok", "message": repr(r)[:200]}), flush=True)
""")


def run_call(expr: str, setup: str = "", timeout: float = 60.0) -> dict:
    """Evaluates ``expr`` (an expression using ``_core`` and ``np``) in a child; returns the
    report dict plus ``returncode``. A crash shows as a negative return code and no report."""
    code = PRELUDE + textwrap.dedent(setup) + f"\nreport(lambda: {expr})\n"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=timeout, env=os.environ.copy())
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("{")]
    out = json.loads(lines[-1]) if lines else {"type": None, "message": r.stderr[-2000:]}
    out["returncode"] = r.returncode
    return out


def interrupt_call(expr: str, setup: str = "", delay: float = 1.0, grace: float = 5.0) -> dict:
    """Starts ``expr`` in a child, sends SIGINT ``delay`` seconds after the child says it is
    about to call it, and waits at most ``grace`` seconds for the child to end. Returns the
    report, ``returncode`` and ``seconds`` (from SIGINT to exit; None if it had to be killed)."""
    code = (PRELUDE + textwrap.dedent(setup) +
            f"\nprint('ready', flush=True)\nreport(lambda: {expr})\n")
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=os.environ.copy())
    try:
        first = p.stdout.readline()
        if first.strip() != "ready":
            p.kill()
            _, err = p.communicate()
            raise RuntimeError(f"child did not start: {first!r} {err[-2000:]}")
        time.sleep(delay)
        t0 = time.monotonic()
        p.send_signal(signal.SIGINT)
        try:
            out, err = p.communicate(timeout=grace)
            seconds = time.monotonic() - t0
        except subprocess.TimeoutExpired:
            p.kill()
            out, err = p.communicate()
            seconds = None
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    lines = [ln for ln in out.splitlines() if ln.startswith("{")]
    res = json.loads(lines[-1]) if lines else {"type": None, "message": err[-2000:]}
    res.update(returncode=p.returncode, seconds=seconds)
    return res
