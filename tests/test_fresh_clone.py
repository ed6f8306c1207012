"""A newcomer's first run, in CI (issue 22, "done when"): a plain ``git clone`` of this
repository into an empty folder, no ``../shared`` beside it and ``CDAM_SHARED_DATA`` pointing
nowhere, then the README's commands run exactly as written (``bash scripts/main.sh``,
``.venv/bin/cdam ...``, from the clone's root) must end successfully, print what the README
says they print, write only into ``out/`` and ``reports/`` (nothing tracked changes), and the
examples and tests that need the nano-drone flights must say that they are absent.

What is not rebuilt: the clone's ``.venv`` is a link to the venv running these tests. Under
``scripts/test.sh`` (CI) that is the venv ``scripts/setup.sh`` just built from this same
commit (its stamp, ``.venv/cdam-setup.stamp``, names the commit's tree), so ``.venv/bin/cdam``
is the installed package, as after ``bash scripts/setup.sh`` in the clone, and the main job's
own set-up finds the clone's tree already built instead of building it again (minutes for the
same pip install). In a source-tree run (PYTHONPATH set, the dev extension) PYTHONPATH points
at the clone's ``python/``, and the main job is skipped: its set-up would install into the
venv running the tests. The slow tests (the main job, the EMPS example, the first-use snippet
with the firmware commands on its model) run once in CI (scripts/test.sh runs ``-m "not
fuzz"``). Left out: the two batch runs over 10 seeds (minutes: tests/fleet runs every batch
command on small grids; here their set-up lines run, their specs give the task counts the
README states, and the shared-data one must name what is missing), the batch against a
hand-started Dask scheduler, and the PX4 import, which needs a shared log.
"""
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


@pytest.fixture(scope="module")
def clone(tmp_path_factory):
    if not (ROOT / ".git").exists() or shutil.which("git") is None:
        pytest.fail(f"{ROOT} is not a git checkout: the fresh-clone test needs one")
    top = tmp_path_factory.mktemp("fresh")
    repo = top / "cdam_core"
    r = subprocess.run(["git", "clone", "-q", str(ROOT), str(repo)], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert not (top / "shared").exists()
    (repo / ".venv").symlink_to(Path(sys.prefix))
    assert (repo / ".venv" / "bin" / "cdam").is_file(), "the venv has no cdam command"
    env = {k: v for k, v in os.environ.items()
           if k not in ("CDAM_FIRMWARE_DIR", "MPLBACKEND", "VIRTUAL_ENV")}
    env["CDAM_SHARED_DATA"] = str(top / "no-shared-data")          # set, and pointing nowhere
    if "PYTHONPATH" in env:                                          # a source-tree run
        env["PYTHONPATH"] = str(repo / "python")
    return repo, env


def _bash(repo, env, script: str, timeout=900):
    return subprocess.run(["bash", "-ec", script], cwd=repo, env=env, capture_output=True,
                          text=True, timeout=timeout)


def _inline(prefix: str) -> str:
    """The README's inline command starting with ``prefix`` (exactly one)."""
    found = [c for c in re.findall(r"`(\.venv/bin/[^`]+)`", README) if c.startswith(prefix)]
    assert len(found) == 1, (prefix, found)
    return found[0]


def _fenced(must: str) -> str:
    blocks = [b for lang, b in re.findall(r"^ *```(\w+)\n(.*?)^ *```", README, re.M | re.S)
              if lang == "bash" and must in b]
    assert len(blocks) == 1, must
    return "\n".join(ln.strip() for ln in blocks[0].splitlines())


def test_commands_run_as_written_in_a_plain_clone(clone):
    repo, env = clone
    r = _bash(repo, env, ".venv/bin/cdam --version && .venv/bin/cdam --help")
    assert r.returncode == 0, r.stderr
    init = (repo / "python" / "cdam_core" / "__init__.py").read_text()
    assert r.stdout.splitlines()[0] == "cdam " + re.search(r'__version__ = "([^"]+)"',
                                                           init).group(1)
    # the AR.Drone example: the record from the clone's data/, its numbers as the README says
    r = _bash(repo, env, _fenced("load_ardrone2"))
    assert r.returncode == 0, r.stderr[-2000:]
    out, text = r.stdout, " ".join(README.split())
    assert out.splitlines()[0] == "test record, free run, mean over 6 output(s):"
    model = re.search(r"IBOA-BP +r (\S+) +NRMSE (\S+)", out).groups()
    arx = re.search(r"ARX\(4, 4, 0\) +r (\S+) +NRMSE (\S+)", out).groups()
    naive = re.search(r"naive +r +n/a +NRMSE (\S+)", out).group(1)
    assert f"mean r {model[0]} and NRMSE {model[1]}" in text
    assert f"NRMSE {float(naive):.2f}" in text
    assert arx == model                       # "the same for the least-squares ARX" 
    # a hidden effect in a simulated flight: simulate, then the residual loop names it
    sim = _inline(".venv/bin/cdam simulate --experiment both")
    res = _inline(".venv/bin/cdam residual out/f.csv")
    r = _bash(repo, env, f"mkdir -p out\n{sim}\n{res}")
    assert r.returncode == 0, r.stderr[-2000:]
    js = json.loads((repo / "out" / "r.json").read_text())
    effects = [(f["effect"], f["channel"]) for f in js["findings"]]
    assert ("thrust_loss", "Z") in effects
    for f in ("index.md", "index.html", "spectrum.png"):
        assert (repo / "out" / "rep" / f).is_file(), f
    # a joint from the independent generator: the truth it prints, the cut-offs and the
    # parameters with their sigmas that the residual loop reports, as the README gives them
    gen = _inline(".venv/bin/python tests/residual/joint_generator.py")
    res = _inline(".venv/bin/cdam residual out/joint.csv")
    r = _bash(repo, env, gen)
    assert r.returncode == 0, r.stderr[-2000:]
    truth = json.loads(r.stdout)
    said = re.search(r"prints the truth \(([^)]*)\)", text).group(1)
    assert said == ", ".join(f"{k} {v:g}" for k, v in truth.items())
    r = _bash(repo, env, res)
    assert r.returncode == 0, r.stderr[-2000:]
    js = json.loads((repo / "out" / "joint_residual.json").read_text())
    assert "final parameters (value, relative sigma):" in r.stdout  # the summary, not the JSON
    assert (repo / "out" / "joint" / "index.html").is_file()
    cut = js["settings"]["filter_choice"]["chosen_hz"]
    motor, link = re.search(r"cut-offs per encoder \(motor (\S+) Hz, link (\S+) Hz\)",
                            text).groups()
    assert _as_written(cut["theta_m"], motor) and _as_written(cut["q"], link), cut
    fin, sd = js["final_parameters"], js["final_std"]
    fin["Fc"], sd["Fc"] = fin["coulomb_friction@tau_m.Fc"], sd["coulomb_friction@tau_m.Fc"]
    stated = re.search(r"\(relative %\): (.*?): within", text).group(1)
    stated = re.findall(r"(\w+) ([\d.]+) \(([\d.]+) %\)", stated)
    assert [k for k, _, _ in stated] == ["Im", "Dm", "Ks", "Kd", "I", "Dl", "G", "Fc"], stated
    for k, v, pct in stated:
        rel = 100 * sd[k] / fin[k]   # a sigma moves with its estimate (Kd: 0.2236 against 0.23)
        assert _as_estimated(fin[k], v, sd[k]) and (_as_written(rel, pct) or
                                                   abs(rel / float(pct) - 1) <= 0.05), \
            (k, fin[k], sd[k])
    # the notebook, EMPS from the file in data/ to the report
    r = _bash(repo, env, _fenced("examples/emps_residual.ipynb"))
    assert r.returncode == 0, r.stderr[-3000:]
    assert (repo / "out" / "emps-notebook" / "index.html").is_file()
    _nothing_tracked_changed(repo)


def _as_written(x: float, written: str) -> bool:
    """``x`` rounds to the README's ``written`` figure (within half its last digit)."""
    decimals = len(written.split(".")[1]) if "." in written else 0
    return abs(x - float(written)) <= 0.5 * 10.0 ** -decimals * (1 + 1e-9)


def _as_estimated(x: float, written: str, sigma: float) -> bool:
    """``x`` as written, or within half its own standard deviation of it (well inside the
    estimate's uncertainty). An output-error estimate stops where the optimiser's tolerance is
    met, and that point moves with the CPU's floating-point kernels (OpenBLAS picks them per
    CPU): measured in session 20, the README joint's Dm 0.049949, Kd 0.049900 and G 0.59980
    on one machine where the README, from another, prints 0.04993, 0.04989 and 0.5999 (0.12,
    0.09 and 0.26 sigma), the same tree and inputs."""
    return _as_written(x, written) or abs(x - float(written)) <= 0.5 * sigma


def _nothing_tracked_changed(repo):
    """Nothing tracked changed, nothing new outside the folders the README names as output
    (``out/``; ``reports/`` and ``build/`` of the main job) but the ``.venv`` link."""
    st = subprocess.run(["git", "status", "--porcelain", "--ignored"], cwd=repo,
                        capture_output=True, text=True).stdout.splitlines()
    assert [ln for ln in st if not ln.startswith("!!")] == ["?? .venv"], st
    ignored = [ln[3:] for ln in st if ln.startswith("!!")]
    assert all(p in ("out/", "reports/", "build/") or p.endswith("__pycache__/")
               for p in ignored), ignored


def test_what_needs_the_shared_flights_says_they_are_absent(clone):
    repo, env = clone
    for prefix in ("cross_trajectory.py out/nanodrone", "cross_trajectory.py out/papernets"):
        r = _bash(repo, env, _inline(".venv/bin/python docs/examples/nanodrone/" + prefix))
        assert r.returncode == 3 and r.stdout == "", prefix
        assert "Traceback" not in r.stderr and r.stderr.count("\n") == 1, prefix
        assert "CDAM_SHARED_DATA" in r.stderr and "not in the repository" in r.stderr
    # the batch over the same flights: exit 2 (a missing input), one line naming the variable,
    # and nothing written
    r = _bash(repo, env, _fenced("nanodrone_crossfold.json"))
    assert r.returncode == 2 and r.stdout == ""
    assert "Traceback" not in r.stderr and r.stderr.count("\n") == 1
    assert r.stderr.startswith("cdam batch: error: spec.records: 'shared:nanodrone/")
    assert "CDAM_SHARED_DATA" in r.stderr and "not in the repository" in r.stderr
    assert not (repo / "out" / "batch-crossfold").exists()
    # their tests skip and name the folder and the variable (-rs prints why)
    r = _bash(repo, env, ".venv/bin/python -m pytest -q -rs -p no:cacheprovider "
                         "tests/record/test_nanodrone.py", timeout=600)
    assert r.returncode == 0, r.stdout[-2000:]
    skips = [ln for ln in r.stdout.splitlines() if ln.startswith("SKIPPED")]
    assert skips and all("nano-drone flights not found" in ln and "CDAM_SHARED_DATA" in ln
                         for ln in skips), r.stdout[-2000:]


@pytest.mark.slow
def test_first_use_snippet_runs_and_matches_its_explanation(clone):
    """"In `.venv/bin/python`, from the repository root (about 30 s)": the snippet as written;
    the README explains the printed correlations (near 1 one step ahead on the outputs that
    move, near 0 on those that only hold noise, q1 and q2 drifting in free run)."""
    repo, env = clone
    body = next(b for lang, b in re.findall(r"^ *```(\w+)\n(.*?)^ *```", README, re.M | re.S)
                if lang == "python" and "simulate_flight" in b)
    r = subprocess.run([".venv/bin/python", "-c", body], cwd=repo, env=env, capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    corr = {}
    for line in r.stdout.splitlines():
        mode, _, rest = line.partition(" ")
        corr[mode] = eval(rest, {})                  # the printed dict of r per output
    assert min(corr["one_step"][o] for o in ("theta", "X", "q1", "q2")) > 0.99
    assert max(abs(corr["one_step"][o]) for o in ("phi", "psi", "Y", "Z")) < 0.1
    assert 0.5 < corr["free_run"]["q2"] < 0.8 and 0.15 < corr["free_run"]["q1"] < 0.45
    assert (repo / "out" / "model.json").is_file()
    # the Firmware section's two commands, on that model
    from cdam_core.firmware import toolchain_available
    why = toolchain_available()
    if why:
        pytest.skip(f"the firmware commands need the toolchain: {why}")
    export = _inline(".venv/bin/cdam export-firmware out/model.json")
    check = _inline(".venv/bin/cdam firmware check out/model.json")
    t0 = time.perf_counter()
    r = _bash(repo, env, f"{export}\n{check}")
    print(f"firmware commands in the clone: {time.perf_counter() - t0:.1f} s")
    assert r.returncode == 0, r.stderr[-3000:]
    assert "#include" in (repo / "out" / "model.hpp").read_text()
    rep = json.loads((repo / "out" / "check.json").read_text())
    assert json.loads(r.stdout[r.stdout.index("{"):]) == rep
    assert rep["kind"] == "bp_network" and rep["heap_free"] is True
    _nothing_tracked_changed(repo)      # firmware_stubs/generated/model.hpp untouched


def _git(cwd, *args) -> str:
    return subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True,
                          check=True).stdout.strip()


@pytest.fixture(scope="module")
def built(clone):
    """The main job's set-up (``scripts/setup.sh``) in the clone works on the clone's ``.venv``,
    here the venv running the tests: it must find the clone's tree already built there (the
    stamp that scripts/setup.sh writes after a build from a checkout with no uncommitted
    change), else it would build again into that venv."""
    repo, env = clone
    if "PYTHONPATH" in env:
        pytest.skip("source-tree run (PYTHONPATH): the main job's set-up would install into the "
                    "venv running the tests; scripts/test.sh runs it")
    if _git(ROOT, "status", "--porcelain", "--", ".", ":(exclude).venv"):
        pytest.skip("the checkout has uncommitted changes, so the venv running the tests was "
                    "not built from the clone's commit: commit, then scripts/test.sh")
    stamp = Path(sys.prefix) / "cdam-setup.stamp"
    tree = _git(repo, "rev-parse", "HEAD^{tree}")
    assert stamp.is_file() and stamp.read_text().split()[0] == tree, (
        f"{stamp} does not name the clone's tree {tree}: scripts/setup.sh did not build this "
        "venv from this commit")
    return repo, env


def _paper_rows(stdout: str) -> dict:
    """``cdam paper``'s printed tables: {"Table 2"|"Table 3": {output: {(section, mode):
    (IBOA's mean r or None, every algorithm reaches its published r)}}}."""
    tables, cur = {}, None
    for line in stdout.splitlines():
        m = re.match(r"(Table [23]), iboa mean r ", line)
        if m:
            cur = tables.setdefault(m.group(1), {})
            continue
        m = re.match(r"  (\w+) +paper (\d\.\d{4}) \| (.*)$", line)
        if m and cur is not None:
            row = cur.setdefault(m.group(1), {})
            for cell in m.group(3).split(" | "):
                sec, mode, r, yes = re.fullmatch(r"(\w+) (.+) (\S+) (yes|no)", cell).groups()
                row[(sec, mode)] = (None if r == "n/a" else float(r), yes == "yes")
    return tables


@pytest.mark.slow
def test_main_job_as_written_in_a_plain_clone(built):
    """``bash scripts/main.sh``: the set-up, then ``cdam paper --out reports/paper``; the
    report and the printed tables say what the README's "The paper's study" says."""
    repo, env = built
    cmd = next(ln.split("#", 1)[0].strip() for ln in _fenced("bash scripts/main.sh").splitlines()
               if ln.startswith("bash scripts/main.sh"))
    t0 = time.perf_counter()
    r = _bash(repo, env, cmd, timeout=1800)
    seconds = time.perf_counter() - t0
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-3000:]
    lines = r.stdout.splitlines()
    assert lines[0].startswith("setup: cdam_core already built from this commit's tree"), lines
    assert re.fullmatch(r"setup: cdam_core \S+ ready \(log: build/setup\.log\)", lines[1])
    assert (repo / "build" / "setup.log").is_file()
    print(f"main job in the clone: {seconds:.1f} s")
    # the report: every promised file, 16 figures, each with its caption under it
    d = repo / "reports" / "paper"
    res = json.loads((d / "results.json").read_text())
    for f in ("index.md", "index.html", "predictions.npz"):
        assert (d / f).is_file(), f
    figs = res["files"]["preprocessing"] + res["files"]["convergence"] + res["files"]["identified"]
    assert len(figs) == 16 and all((d / f).is_file() for f in figs)
    sys.path.insert(0, str(ROOT / "tests" / "report"))
    from _browser import captions_follow_figures
    page = (d / "index.html").read_text()
    assert page.count("<img") == 16 and captions_follow_figures(page)
    # the printed tables, as the README reads them
    tables = _paper_rows(r.stdout)
    assert set(tables) == {"Table 2", "Table 3"}
    for t in tables.values():
        assert set(t) == {"phi", "theta", "psi", "X", "Y", "Z", "q1", "q2"}

    def reached(table, section, mode):
        return sum(row[(section, mode)][1] for row in tables[table].values())
    # "the paper's static 6-20-8 network reaches none of the published correlations"
    assert reached("Table 2", "static", "one-step") == reached("Table 3", "static", "one-step") == 0
    # "The hybrid NARX model ... reaches them on 8 of 8 outputs in Tables 2 and 3 in one-step
    # prediction, the NARX network on 5/8 and 8/8"
    assert reached("Table 2", "hybrid", "one-step") == reached("Table 3", "hybrid", "one-step") == 8
    assert (reached("Table 2", "narx", "one-step"), reached("Table 3", "narx", "one-step")) == (5, 8)
    # "free run, where these closed-loop flights drift (only the hybrid model's arm joints stay
    # near r 0.98 in free run)"
    for t in tables.values():
        for o, row in t.items():
            r_free = [row[(sec, "free-run")][0] for sec in ("narx", "hybrid")]
            if o in ("q1", "q2"):
                assert r_free[1] is not None and r_free[1] > 0.95, (o, r_free)
            else:
                assert all(v is None or v < 0.9 for v in r_free), (o, r_free)
    # "IBOA does not beat BOA or CABC significantly here (rank-sum test)"
    assert not any(m["iboa_better"] for sec in res["rank_sum"].values()
                   for other in sec.values() for m in other.values())
    _nothing_tracked_changed(repo)


# Published IDIM-LS estimates of the EMPS axis (Janot, Gautier, Brunot 2019; typed from
# ../shared/docs/ALGORITHMS.md, section EMPS, as in tests/residual/test_emps.py)
EMPS_PUBLISHED = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935}


def _p(p: float) -> str:
    """A p-value as the README writes it: one digit, '3e-11', '1e-5'."""
    return re.sub(r"e-0*", "e-", f"{p:.0e}")


@pytest.mark.slow
def test_emps_example_as_written_in_a_plain_clone(clone):
    """``.venv/bin/python -m cdam_core.cli.example emps out/emps`` with the records of the
    clone's data/emps: the report files, every figure captioned, and the printed benchmark
    table and the report's figures as the README's "EMPS, real data" states them."""
    repo, env = clone
    cmd = _inline(".venv/bin/python -m cdam_core.cli.example emps")
    t0 = time.perf_counter()
    r = _bash(repo, env, cmd, timeout=1800)
    print(f"EMPS example in the clone: {time.perf_counter() - t0:.1f} s")
    assert r.returncode == 0, r.stderr[-3000:]
    out = repo / cmd.split()[-1]
    assert r.stdout.splitlines()[-1] == f"wrote {out.relative_to(repo)}/index.md"
    for f in ("index.md", "index.html", "residual.json", "benchmark.json", "spectrum.png",
              "pulses/index.md", "pulses/index.html", "pulses/residual.json"):
        assert (out / f).is_file(), f
    sys.path.insert(0, str(ROOT / "tests" / "report"))
    from _browser import captions_follow_figures
    for page in (out / "index.html", out / "pulses" / "index.html"):
        html = page.read_text()
        assert html.count("<img") >= 2 and captions_follow_figures(html), page
        assert all((page.parent / src).is_file() for src in re.findall(r'<img[^>]*src="([^"]+)"',
                                                                        html)), page
    text = " ".join(README.split())
    # the printed table (simulation RMSE of qm in mm under the benchmark's protocol)
    rows = dict(re.findall(r"^  (.+?) +(\d+\.\d\d) mm   ", r.stdout, re.M))
    rows = {k: float(v) for k, v in rows.items()}
    assert f"declared model {rows['cdam declared model (no effects)']:.1f} mm" in text
    final = rows["cdam final model (coulomb_friction@tau, asymmetric_friction@tau)"]
    assert f"final model (Coulomb + asymmetric friction) {final:.1f} mm" in text
    arx = next(k for k in rows if k.startswith("least-squares ARX("))
    orders = re.match(r"least-squares (ARX\(\d, \d, 1\))", arx).group(1)
    assert f"{orders} with orders chosen on DATA_EMPS {rows[arx]:.1f} mm" in text
    se = next(k for k in rows if "fitted by simulation error" in k)
    windows = re.search(r"(\d\.\d\d s windows)", se).group(1)
    assert f"({'multiple shooting, ' + windows}) {rows[se]:.1f} mm" in text
    whole = next(k for k in rows if "(whole record, its initial state fitted)" in k)
    assert f"(whole record, its initial state fitted) {rows[whole]:.1f} mm" in text
    assert f"the published IDIM-LS model {rows['IDIM-LS (M, Fv, Fc, offset)']:.1f} mm" in text
    lti = next(k for k in rows if k.startswith("LTI output error, order "))
    assert f"reproduced here at {rows[lti]:.1f} mm" in text
    for name in ("LSTM", "RNN", "MLP FIR", "GRU"):
        assert f"{name} {rows[name]:g}" in text, name
    bench = json.loads((out / "benchmark.json").read_text())
    assert {b["model"]: b["rmse_mm"] for b in bench["results"]}.keys() == rows.keys()
    # the report: the cut-off, the two findings and their held-out evidence, the dropped offset
    js = json.loads((out / "residual.json").read_text())
    assert js["settings"]["filter_choice"]["chosen_hz"]["q"] == 400.0          # "400 Hz"
    f1, f2 = js["findings"]
    assert (f1["effect"], f2["effect"]) == ("coulomb_friction", "asymmetric_friction")
    e0, e1, e2 = (100 * x["tau"]["nrmse"] for x in (f1["error_before"], f1["error_after"],
                                                    f2["error_after"]))
    assert f"force error {e0:.1f} % -> {e1:.1f} %" in text
    assert f"`asymmetric_friction` second ({e2:.1f} %)" in text
    p1, p2 = (f["evidence"]["validation"]["p_value"] for f in (f1, f2))
    assert f"Wilcoxon p {_p(p1)} and {_p(p2)}" in text
    assert [d["term"] for d in js["settings"]["declared_terms_dropped"]] == ["offset"]
    fin = js["final_parameters"]
    # the input timing the data choose, and what it does to the published values
    tm = js["settings"]["timing"]
    assert tm["chosen"] == "held" and f"after each force sample, Wilcoxon p {_p(tm['p_value'])}" in text
    assert abs(fin["M"] / EMPS_PUBLISHED["M"] - 1) < 0.002              # "within 0.2 %"
    assert round(100 * (f1["parameters"]["Fc"] / EMPS_PUBLISHED["Fc"] - 1)) == -2   # "2 % below"
    fv = (f2["parameters"]["Fv_pos"] + f2["parameters"]["Fv_neg"]) / 2   # the two directions' mean
    assert abs(100 * (fv / EMPS_PUBLISHED["Fv"] - 1) - 2.5) < 0.5        # "Fv 2.5 % above"
    # the estimator chosen on the same held-out windows
    est = js["settings"]["estimator"]
    iv, oe = est["validation"]["IDIM-IV"], est["validation"]["output error (multiple shooting)"]
    assert est["chosen"] == "IDIM-LS" and not iv["better"] and not oe["better"]
    assert f"is no better there (p {iv['p_value']:.3f} at level {iv['level']:g})" in text
    # output error's windows move with the CPU (_as_estimated): the README's 52 % and p 0.024
    # from one machine, 52.8 % and 0.0247 on another (session 20); the level is exact
    gain = 100 * (1 - oe["score_rich"] / oe["score_simple"])
    said_gain = float(re.search(r"held-out window error by (\d+) %", text).group(1))
    assert abs(gain - said_gain) <= 1.0, (gain, said_gain)
    said_p = re.search(r"\(Wilcoxon p ([\d.]+) at level (\S+),", text).groups()
    assert abs(oe["p_value"] - float(said_p[0])) <= 0.001, (oe["p_value"], said_p)
    assert f"{oe['level']:g}" == said_p[1] and oe["p_value"] > oe["level"]
    assert js["settings"]["stability"]["stable"]
    # the residual's lines: the mains' near 50 Hz (DATA_EMPS) and 100 Hz (both) unexplained;
    # the 20.4 Hz line of both records within what the model's terms produce (listed as the
    # model's); PULSES under the hold the data choose there too (the 24 Hz hump of the
    # published timing: tests/residual/test_emps)
    pulses = json.loads((out / "pulses" / "residual.json").read_text())
    for rec, mains in ((js, 50.0), (pulses, 100.0)):
        lines = [u["frequency_hz"] for u in rec["unexplained"] if u["kind"] == "periodic_line"]
        assert any(abs(f - mains) < 0.7 for f in lines), lines
        model = rec["settings"]["residual_structure_explained_by_the_model"]["explained"]
        assert any(abs(u["frequency_hz"] - 20.4) < 0.1 for u in model)
    tp = pulses["settings"]["timing"]
    assert tp["chosen"] == "held" and f"data choose (p {_p(tp['p_value'])} there)" in text
    md = (out / "index.md").read_text()                  # "with their amplitudes": in N
    assert re.search(r"^\| tau \| periodic_line \| 49\.\d\d \| amplitude \S+ N \(x", md, re.M)
    _nothing_tracked_changed(repo)


def test_batch_examples_hold_the_tasks_the_readme_counts(clone):
    """The batch examples themselves take minutes (tests/fleet runs every command on small
    grids): here the README's set-up lines of the seeds example run as written, and both specs
    read from the clone give the task counts the README states (90 and 60)."""
    from cdam_core.fleet.spec import load_spec
    repo, env = clone
    text = " ".join(README.split())
    block = _fenced("docs/examples/batch/seeds.json")
    r = _bash(repo, env, "\n".join(ln for ln in block.splitlines()
                                   if not ln.startswith(".venv/bin/cdam batch")))
    assert r.returncode == 0, r.stderr[-2000:]
    counts = {}
    for name in ("paper_seeds", "seeds"):
        spec = load_spec(repo / "docs" / "examples" / "batch" / f"{name}.json", base=repo)
        counts[name] = len(spec.tasks())
    assert f"as {counts['paper_seeds']} tasks on a LocalCluster" in text
    assert f"score the second: {counts['seeds']} tasks)" in text
    assert counts == {"paper_seeds": 90, "seeds": 60}
    assert sorted(p.name for p in (repo / "out" / "sim").glob("*.csv")) == ["flight1.csv",
                                                                             "flight2.csv"]
