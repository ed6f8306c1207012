"""Same result whatever the thread count (issue 24 item 7): every binding that takes ``threads``
(``train_lm``, ``train_gd``, ``mlp_jtj``, ``bp_fitness``, ``optimise``) gives byte-identical
weights, histories and values at 1, 2 and 3 threads, for records just below and above the size
where the core starts to use threads (1,023 / 1,024 samples) and longer, uneven ones; and the
same bytes as a separate interpreter that computes at 1 thread. Before the fix, ``train_lm``,
``train_gd`` and ``mlp_jtj`` differed in the last bits from 1,024 samples on (the record was
split into one part per thread).

The values themselves are checked against the numpy twin (``cdam_core.reference``) within a
tolerance, so identical-but-wrong output fails too.
"""
import hashlib
import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from cdam_core import _core, reference

SIZES = [1023, 1024, 5000, 10007]
THREADS = [1, 2, 3]
I, H, M = 4, 8, 3  # a small network keeps the runs short; the paper's 6-20-8 below


def _problem(n, dtype=np.float64, i=I, h=H, m=M, seed=0):
    rng = np.random.default_rng(seed + n)
    X = rng.uniform(-1, 1, (n, i))
    T = np.tanh(X @ rng.uniform(-1, 1, (i, m))) + 0.1 * rng.standard_normal((n, m))
    theta = rng.uniform(-0.5, 0.5, _core.mlp_num_params(i, h, m))
    return X.astype(dtype), T.astype(dtype), theta.astype(dtype)


def _run(kind, n, dtype, threads):
    """The result of one threaded binding as a list of (name, bytes)."""
    X, T, theta = _problem(n, dtype)
    if kind == "train_lm":
        Xv, Tv, _ = _problem(n // 3 + 1, dtype, seed=1)
        th, hist = _core.train_lm(theta, X, T, H, epochs=5, min_grad=0.0, X_val=Xv, T_val=Tv,
                                  threads=threads)
        return [("theta", th.tobytes())] + [
            (k, np.asarray(hist[k]).tobytes()) for k in ("mse", "mu", "grad_norm", "val_mse")
        ] + [("stop", hist["stop"].encode()), ("best_epoch", str(hist["best_epoch"]).encode())]
    if kind == "train_gd":
        th, hist = _core.train_gd(theta, X, T, H, lr=1e-3, epochs=5, threads=threads)
        return [("theta", th.tobytes()), ("mse", np.asarray(hist["mse"]).tobytes())]
    if kind == "mlp_jtj":
        A, b, sse = _core.mlp_jtj(theta, X, T, H, "tansig", threads)
        return [("JtJ", A.tobytes()), ("Jte", b.tobytes()), ("sse", np.float64(sse).tobytes())]
    if kind == "bp_fitness":
        thetas = np.stack([theta, -theta, 0.5 * theta]).astype(np.float64)
        return [("mse", _core.bp_fitness(thetas, X.astype(np.float64), T.astype(np.float64), H,
                                         threads=threads).tobytes())]
    if kind == "optimise":
        r = _core.optimise("iboa", "bp", X=X.astype(np.float64), T=T.astype(np.float64),
                           hidden=H, seed=3, options={"iterations": 3, "n": 8},
                           threads=threads)
        return [(k, np.asarray(r[k]).tobytes()) for k in ("best", "curve", "fitness")]
    raise ValueError(kind)


def _digest(parts):
    return hashlib.sha256(b"".join(hashlib.sha256(v).digest() for _, v in parts)).hexdigest()


CASES = ([("train_lm", n, np.float64) for n in SIZES] +
         [("train_lm", n, np.float32) for n in (1024, 5000)] +
         [("train_gd", n, np.float64) for n in SIZES] +
         [("mlp_jtj", n, np.float64) for n in SIZES] +
         [("mlp_jtj", n, np.float32) for n in (1024, 10007)] +
         [("bp_fitness", n, np.float64) for n in SIZES] +
         [("optimise", n, np.float64) for n in (1023, 5000)])


@pytest.fixture(scope="module")
def child_digests():
    """Every case computed at 1 thread by a separate interpreter (fresh process, nothing shared
    with this one), as sha256 digests."""
    here = os.path.dirname(os.path.abspath(__file__))
    code = textwrap.dedent(f"""
        import json, sys
        import numpy as np
        sys.path.insert(0, {here!r})
        import test_threads as t
        out = {{}}
        for kind, n, dtype in t.CASES:
            out[f"{{kind}}-{{n}}-{{np.dtype(dtype).name}}"] = t._digest(t._run(kind, n, dtype, 1))
        print(json.dumps(out))
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=600, env=os.environ.copy())
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("kind, n, dtype", CASES,
                         ids=[f"{k}-{n}-{np.dtype(d).name}" for k, n, d in CASES])
def test_same_bytes_at_1_2_3_threads_and_in_a_child(kind, n, dtype, child_digests):
    one = _run(kind, n, dtype, 1)
    for threads in THREADS[1:]:
        other = _run(kind, n, dtype, threads)
        for (name, a), (_, b) in zip(one, other):
            assert a == b, f"{kind} N={n} {np.dtype(dtype).name}: {name} differs at {threads} threads"
    assert _digest(one) == child_digests[f"{kind}-{n}-{np.dtype(dtype).name}"], \
        "differs from the 1-thread result of a separate interpreter"


@pytest.mark.parametrize("n", [1024, 10007])
def test_paper_network_jtj_same_bytes_and_equal_to_the_numpy_twin(n):
    X, T, theta = _problem(n, i=6, h=20, m=8)
    A1, b1, s1 = _core.mlp_jtj(theta, X, T, 20, "tansig", 1)
    for threads in (2, 3):
        A, b, s = _core.mlp_jtj(theta, X, T, 20, "tansig", threads)
        assert A.tobytes() == A1.tobytes() and b.tobytes() == b1.tobytes()
        assert np.float64(s).tobytes() == np.float64(s1).tobytes()
    Ar, br, sr = reference.mlp_jtj(theta, X, T, 20, "tansig")
    np.testing.assert_allclose(A1, Ar, rtol=0, atol=1e-10 * np.abs(Ar).max())
    np.testing.assert_allclose(b1, br, rtol=0, atol=1e-10 * np.abs(br).max())
    assert s1 == pytest.approx(sr, rel=1e-12)


@pytest.mark.parametrize("n", SIZES)
def test_threaded_values_match_the_numpy_twin(n):
    """The identical bytes are also the right values: J'J, J'e, SSE, the BP fitness and the LM
    run against cdam_core.reference within rounding."""
    X, T, theta = _problem(n)
    A, b, sse = _core.mlp_jtj(theta, X, T, H, "tansig", 3)
    Ar, br, sr = reference.mlp_jtj(theta, X, T, H, "tansig")
    np.testing.assert_allclose(A, Ar, rtol=0, atol=1e-10 * np.abs(Ar).max())
    np.testing.assert_allclose(b, br, rtol=0, atol=1e-10 * np.abs(br).max())
    assert sse == pytest.approx(sr, rel=1e-12)
    Y = reference.mlp_forward(theta, X, H, M, "tansig")
    f = _core.bp_fitness(theta, X, T, H, threads=3)
    assert f[0] == pytest.approx(np.mean((T - Y) ** 2), rel=1e-12)
    th, hist = _core.train_lm(theta, X, T, H, epochs=3, min_grad=0.0, threads=3)
    thr, histr = reference.train_lm(theta, X, T, H, epochs=3, min_grad=0.0)
    np.testing.assert_allclose(hist["mse"], histr["mse"], rtol=1e-9)
    np.testing.assert_allclose(th, thr, rtol=0, atol=1e-6)
