"""Ctrl-C stops the long native loops (issue 24 item 5): SIGINT sent to a child running a call
that would take minutes to hours ends it with KeyboardInterrupt within a few seconds (the
bindings poll Python's signal handlers from the loop; before, the signal waited for the loop
to finish). Each call runs in its own child interpreter (tests/robust/_subproc.py)."""
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _subproc import interrupt_call  # noqa: E402

GRACE = 5.0  # seconds from SIGINT to exit

NET = ("rng = np.random.default_rng(0)\n"
       "X = rng.uniform(-1, 1, (20000, 6)); T = np.tanh(X @ rng.uniform(-1, 1, (6, 8)))\n"
       "T += 0.1 * rng.standard_normal(T.shape)\n"
       "th = rng.uniform(-0.5, 0.5, _core.mlp_num_params(6, 20, 8))\n")


SIM = ("from cdam_core.sim.parameters import control_vector, plant_vector\n"
       "from cdam_core.sim.state import hover_state\n"
       "P, C = plant_vector(), control_vector()\n")


@pytest.mark.parametrize("expr, setup", [
    # 2**31 - 1 passes over 10 samples: about a minute of work
    ("_core.five_point_cubic_smooth(np.ones(10), 2**31 - 1)", ""),
    ("_core.five_point_cubic_smooth(np.ones((100, 3)), 2**31 - 1)", ""),
    # LM with no stop criterion reachable soon (goal 0, min_grad 0) on a noisy 20,000-sample
    # record: an epoch costs tens of ms, 10**7 epochs would take days
    ("_core.train_lm(th, X, T, 20, epochs=10**7, min_grad=0.0, threads=1)", NET),
    ("_core.train_gd(th, X, T, 20, lr=1e-4, epochs=2**31 - 1, threads=1)", NET),
    # 2 * 10**7 BOA iterations of 20 sphere evaluations
    ("_core.optimise('boa', 'sphere', dim=4, options={'iterations': 2 * 10**7})", ""),
    ("_core.optimise('cabc', 'sphere', dim=4, options={'iterations': 2 * 10**7})", ""),
    # the simulator at its largest sub-step count: 10**9 RK4 steps in the open loop, 2.5 10**8
    # in the closed loop (minutes); a wide NARX network run over 10**7 samples (tens of seconds)
    ("_core.sim_open_loop(P, hover_state(), np.zeros((10**6, 6)), 1e-3, 1000)", SIM),
    ("_core.sim_closed_loop(P, C, hover_state(), np.tile(hover_state()[[0, 1, 2, 3, 4, 5, 6, 7]],"
     " (2 * 10**5, 1)), 1e-3, 1000)", SIM),
    ("_core.narx_simulate(np.full(_core.mlp_num_params(2, 2000, 1), 0.01), np.zeros((10**7, 1)), "
     "np.zeros((1, 1)), 2000, 'tansig', 1, 1, 1)", ""),
])
def test_sigint_stops_a_long_native_loop(expr, setup):
    res = interrupt_call(expr, setup=setup, delay=1.0, grace=GRACE)
    assert res["seconds"] is not None, f"still running {GRACE} s after SIGINT: {res}"
    assert res["type"] == "KeyboardInterrupt", res
    assert res["returncode"] == 0, res


START = ("import sys\nprint('ready', flush=True)\n"
         "from cdam_core.cli.main import main\nsys.exit(main())\n")   # what the `cdam` script does


@pytest.mark.parametrize("delay", [0.05, 0.3, 1.5])
def test_sigint_at_start_up_is_one_line_and_130(tmp_path, delay):
    """Ctrl-C while `cdam` imports its modules (0.05 s and 0.3 s after the interpreter is up:
    the imports take about 0.6 s here) or once the command runs: exit 130, one line on stderr,
    no traceback (before, an interrupt during the imports printed a KeyboardInterrupt
    traceback and exited 1)."""
    import os
    import signal
    import subprocess
    import time
    lines = ["t,u,y"] + [f"{k / 100},{(k * 7 % 13) / 13},{(k * 5 % 11) / 11}" for k in range(300)]
    (tmp_path / "d.csv").write_text("\n".join(lines) + "\n")
    argv = ["identify", str(tmp_path / "d.csv"), "--inputs", "u", "--outputs", "y", "--algo",
            "iboa", "--iterations", "1000000", "--quiet"]
    p = subprocess.Popen([sys.executable, "-c", START, *argv], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=os.environ.copy())
    try:
        assert p.stdout.readline().strip() == "ready"
        time.sleep(delay)
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert "Traceback" not in out + err, err
    assert p.returncode == 130, err
    assert err.strip().splitlines() in (["cdam: error: interrupted"],
                                        ["cdam identify: error: interrupted"]), err
    if delay < 0.1:         # still importing: the command is not known yet
        assert err.strip() == "cdam: error: interrupted"


def test_a_loop_in_a_worker_thread_stops_when_cancelled():
    """A native loop in a thread other than the main one never sees Ctrl-C; the main thread's
    request (_core.cancel_native_loops, what `cdam batch` does on Ctrl-C before shutting its
    workers down) ends it within a poll period with an ordinary exception (a worker's task
    fails like any other), and a later loop runs normally once the request is withdrawn."""
    import threading
    import time

    import numpy as np

    from cdam_core import _core
    out = {}

    def run():
        t0 = time.perf_counter()
        try:
            _core.five_point_cubic_smooth(np.ones(10), 2**31 - 1)   # about a minute of work
            out["result"] = "finished"
        except BaseException as exc:   # noqa: BLE001 - the type is what is tested
            out["result"] = type(exc).__name__
        out["seconds"] = time.perf_counter() - t0

    th = threading.Thread(target=run)
    th.start()
    time.sleep(0.5)
    try:
        _core.cancel_native_loops()
        th.join(timeout=GRACE)
    finally:
        _core.cancel_native_loops(False)
    assert not th.is_alive(), "the loop did not stop"
    assert out["result"] == "RuntimeError" and out["seconds"] < 0.5 + GRACE, out
    np.testing.assert_allclose(_core.five_point_cubic_smooth(np.arange(10.0), 1), np.arange(10.0))
