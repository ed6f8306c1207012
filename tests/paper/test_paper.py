"""`cdam paper`: files, published values, JSON against tables, r against saved predictions,
the data pipeline against scipy, bad arguments. One tiny run (short records, few iterations)
is shared by the tests of its output."""
import json

import numpy as np
import pytest
from scipy.signal import decimate, savgol_filter

from cdam_core.cli.main import main
from cdam_core.record.dataset import read_dataset

# Typed from ../shared/docs/PAPER.md ("The numbers to beat"), columns IBOA, BOA, CABC.
PAPER_T2 = {"theta": (0.9661, 0.9288, 0.8699), "phi": (0.9671, 0.9199, 0.8671),
            "psi": (0.8706, 0.8023, 0.7327), "X": (0.9526, 0.9121, 0.8515),
            "Y": (0.9769, 0.9562, 0.9199), "Z": (0.9922, 0.9815, 0.9600),
            "q1": (0.9991, 0.9980, 0.9940), "q2": (0.9914, 0.9678, 0.9024)}
PAPER_T3 = {"theta": (0.9157, 0.8520, 0.8946), "phi": (0.9685, 0.8874, 0.9239),
            "psi": (0.9755, 0.8955, 0.8497), "X": (0.8630, 0.8252, 0.7643),
            "Y": (0.9288, 0.9210, 0.8436), "Z": (0.7977, 0.7993, 0.5959),
            "q1": (0.9696, 0.9359, 0.8874), "q2": (0.9913, 0.9785, 0.9735)}
PAPER_FITNESS = (0.9962, 0.9844, 0.9684)
PAPER_SECONDS = (2.4, 3.7, 1.8)
ALGOS = ("iboa", "boa", "cabc")
LABELS = ("IBOA-BP", "BOA-BP", "CABC-BP")
TINY = ["--seeds", "2", "--duration", "4", "--iterations", "2", "--population", "6",
        "--epochs", "3", "--rate", "100", "--narx", "1,1,1", "--smoothing", "3", "--quiet"]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("paper")
    assert main(["paper", "--out", str(out)] + TINY) == 0
    return out, json.loads((out / "results.json").read_text())


def _tables(md_text):
    """{heading: [row cells]} of the pipe table under each '### ' heading."""
    tables, head = {}, None
    for line in md_text.splitlines():
        if line.startswith("#"):
            head = line[4:] if line.startswith("### ") else None
            if head:
                tables[head] = []
        elif line.startswith("|") and head and not line.startswith("|---"):
            tables[head].append([c.strip() for c in line.strip().strip("|").split("|")])
    return tables


MODE_LABEL = {"one_step": "one-step", "free_run": "free-run", "k_step_0.1s": "k-step 0.1 s"}
SECTION_MODES = {"static": ("one_step",),
                 "narx": ("one_step", "k_step_0.1s", "free_run"),
                 "hybrid": ("one_step", "k_step_0.1s", "free_run")}


def _table(tables, section, rec, mode):
    key = next(k for k in tables if k.startswith(f"{section}: Table {2 if rec == 'test' else 3}")
               and k.endswith(f"{MODE_LABEL[mode]}: Pearson r"))
    return tables[key]


def test_writes_every_promised_file(run):
    out, res = run
    for name in ("index.md", "index.html", "results.json", "predictions.npz"):
        assert (out / name).stat().st_size > 0, name
    figs = res["files"]["preprocessing"] + res["files"]["convergence"] + res["files"]["identified"]
    for n in (8, 9, 10, 11, 12, 13, 14, 15):
        assert any(f.startswith(f"fig{n:02d}") for f in figs), n
    md, page = (out / "index.md").read_text(), (out / "index.html").read_text()
    for f in figs:
        assert (out / f).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", f
        assert f"]({f})" in md and f'src="{f}"' in page
    for csv in ("flight_i.csv", "flight_ii.csv", "validation_i.csv", "validation_ii.csv"):
        ds = read_dataset(out / csv)
        assert ds.outputs == ["phi", "theta", "psi", "X", "Y", "Z", "q1", "q2"]
        assert (out / csv.replace(".csv", ".json")).exists()
    assert len(read_dataset(out / "flight_i.csv")) == 4000
    assert len(read_dataset(out / "validation_ii.csv")) == 2000
    assert "decimated from 1000 Hz to 100 Hz" in md            # the report says so
    assert "How the two experiments form the training data" in md
    assert "<table>" in page and "Does IBOA beat BOA and CABC" in page


def test_report_page_opens_in_a_browser_with_every_figure_captioned(run, tmp_path):
    """Headless Chromium: all 16 figures of index.html load (none missing) and the screenshot
    is drawn; each figure has its caption under it."""
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "report"))
    from _browser import browser, captions_follow_figures, open_page
    browser()
    out, res = run
    figs = res["files"]["preprocessing"] + res["files"]["convergence"] + res["files"]["identified"]
    got = open_page(out / "index.html", tmp_path / "paper.png")
    assert got["missing"] == [] and got["images"] == len(figs) == 16
    assert got["shot_std"] > 0.01
    page = (out / "index.html").read_text()
    assert captions_follow_figures(page)
    for n in range(8, 16):
        assert f"<em>Figure {n}:" in page, n


def test_tables_hold_the_published_values(run):
    out, res = run
    tables = _tables((out / "index.md").read_text())
    assert set(res["tables"]) == set(SECTION_MODES)
    for section, modes in SECTION_MODES.items():
        for rec, paper in (("test", PAPER_T2), ("validation", PAPER_T3)):
            for mode in modes:
                rows = _table(tables, section, rec, mode)
                assert rows[0][2:7:2] == [f"{lab} (paper)" for lab in LABELS]
                got = {r[0]: tuple(float(r[k]) for k in (2, 4, 6)) for r in rows[1:]}
                assert got == paper
        fit = tables[f"{section}: Final fitness and run time (mean ± std over seeds)"]
        assert [float(r[2]) for r in fit[1:]] == list(PAPER_FITNESS)
        assert [float(r[4]) for r in fit[1:]] == list(PAPER_SECONDS)


def test_json_numbers_are_what_the_tables_show(run):
    out, res = run
    tables = _tables((out / "index.md").read_text())
    for section, t in res["tables"].items():
        for rec, modes in t["r"].items():
            for mode, rows in modes.items():
                md_rows = {r[0]: r for r in _table(tables, section, rec, mode)[1:]}
                for o, row in rows.items():
                    for k, a in enumerate(ALGOS):
                        v = row[a]
                        shown = ("n/a" if v["mean"] is None
                                 else f"{v['mean']:.4f} ± {v['std']:.4f}")
                        assert md_rows[o][1 + 2 * k] == shown
                        assert float(md_rows[o][2 + 2 * k]) == v["paper"]
                    assert md_rows[o][-1].startswith("yes" if row["all_reached"] else "no")
        fit = {r[0]: r for r in tables[f"{section}: Final fitness and run time (mean ± std "
                                       "over seeds)"][1:]}
        for a, lab in zip(ALGOS, LABELS):
            f, s = t["fitness"][a], t["run_time_s"][a]
            assert fit[lab][1] == f"{f['mean']:.4f} ± {f['std']:.4f}"
            assert fit[lab][3] == f"{s['mean']:.2f} ± {s['std']:.2f}"
            # the table's mean is the mean over the seeds' runs
            runs = res["sections"][section]["algorithms"][a]["runs"]
            assert f["mean"] == pytest.approx(np.mean([r["fitness"] for r in runs]), rel=1e-12)


def test_r_equals_corrcoef_of_the_saved_predictions(run):
    out, res = run
    npz = np.load(out / "predictions.npz")
    checked = 0
    for section, sec in res["sections"].items():
        outputs = sec["outputs"]
        for a, data in sec["algorithms"].items():
            rs = {}
            for r in data["runs"]:
                for rec, modes in r["metrics"].items():
                    for mode, m in modes.items():
                        Y = npz[f"{section}/{rec}/{mode}/measured"]
                        P = npz[f"{section}/{rec}/{mode}/{a}/seed{r['seed']}"]
                        for k, o in enumerate(outputs):
                            if m[o]["r"] is None:       # a diverged free run
                                assert not np.all(np.isfinite(P))
                                continue
                            r_np = np.corrcoef(Y[:, k], P[:, k])[0, 1]
                            assert m[o]["r"] == pytest.approx(r_np, rel=1e-12, abs=1e-14)
                            rs.setdefault((rec, mode, o), []).append(r_np)
                            checked += 1
            for (rec, mode, o), vals in rs.items():
                row = res["tables"][section]["r"][rec][mode][o][a]
                assert len(vals) == 2 and row["mean"] == pytest.approx(np.mean(vals), rel=1e-12)
                assert row["std"] == pytest.approx(np.std(vals, ddof=1), rel=1e-10, abs=1e-14)
    assert checked > 0


def _smoothed_decimated(path):
    """The record's outputs through scipy alone: three savgol (5-point cubic) passes, then
    decimation by 10 (the paper pipeline's preprocessing, written independently)."""
    ds = read_dataset(path)
    Y = ds.select(ds.outputs)
    for _ in range(3):
        Y = savgol_filter(Y, 5, 3, mode="interp", axis=0)
    return decimate(Y, 10, ftype="fir", axis=0, zero_phase=True)


def test_measured_arrays_are_the_smoothed_decimated_records(run):
    """Independent of the package: scipy's savgol (5-point cubic) passes and decimate on the
    saved CSV records give the pooled 'measured' arrays of the static and NARX sections."""
    out, res = run
    npz = np.load(out / "predictions.npz")

    def prep(name):
        return _smoothed_decimated(out / name)

    ti, tii = prep("flight_i.csv"), prep("flight_ii.csv")
    test = np.vstack([ti[len(ti) // 2:], tii[len(tii) // 2:]])
    np.testing.assert_allclose(npz["static/test/one_step/measured"], test, rtol=0, atol=1e-9)
    val = [prep("validation_i.csv"), prep("validation_ii.csv")]
    t0 = res["predictions"]["t0"]["narx"]
    assert t0 == 1
    np.testing.assert_allclose(npz["narx/validation/free_run/measured"],
                               np.vstack([v[t0:] for v in val]), rtol=0, atol=1e-9)


def test_bad_arguments_give_clear_errors(tmp_path, capsys):
    assert main(["paper", "--seeds", "0", "--out", str(tmp_path / "a")]) == 2
    assert "--seeds" in capsys.readouterr().err
    blocker = tmp_path / "file.txt"
    blocker.write_text("x")
    assert main(["paper", "--out", str(blocker)] + TINY) == 3   # I/O error (EXIT_CODES)
    err = capsys.readouterr().err
    assert "--out" in err and "not a folder" in err
    assert main(["paper", "--out", str(blocker / "sub")] + TINY) == 3
    err = capsys.readouterr().err
    assert "--out" in err and "cannot create" in err
    assert main(["paper", "--out", str(tmp_path / "b"), "--rate", "300", "--quiet"]) == 2
    assert "rate" in capsys.readouterr().err
    assert main(["paper", "--out", str(tmp_path / "c"), "--narx", "1,x,1"]) == 2
    assert "--narx" in capsys.readouterr().err


def test_config_and_data_reject_bad_input():
    from cdam_core.paper import PaperConfig, prepare_data
    from cdam_core.paper.records import decimation_factor
    with pytest.raises(ValueError, match="seeds"):
        PaperConfig(seeds=0)
    with pytest.raises(ValueError, match="duration"):
        PaperConfig(duration=float("nan"))
    with pytest.raises(ValueError, match="rate"):
        decimation_factor(1000.0, 0.0)
    with pytest.raises(ValueError, match="rate"):
        decimation_factor(1000.0, 2000.0)
    assert decimation_factor(1000.0, 250.0) == 4
    with pytest.raises(ValueError, match="rate"):
        PaperConfig(rate=300.0)
    with pytest.raises(ValueError, match="smoothing"):
        PaperConfig(smoothing=-1)
    with pytest.raises(ValueError, match="records: missing"):
        prepare_data({}, 5, 200.0)


def test_full_rate_keeps_every_sample_and_the_split_is_half():
    from cdam_core.paper import prepare_data, simulate_records
    recs = simulate_records(5, 1.0)
    data = prepare_data(recs, 0, 1000.0)
    Y = recs["exp_ii"].select(recs["exp_ii"].outputs)
    np.testing.assert_array_equal(data.train[1].Y, Y[:500])
    np.testing.assert_array_equal(data.test[1].Y, Y[500:])
    assert len(data.validation[0].t) == 500 and data.rate == 1000.0


def test_a_diverged_free_run_gives_null_metrics_not_a_crash():
    from cdam_core.paper import evaluate_segments
    from cdam_core.paper.records import Segment

    class Diverging:
        narx, t0 = (1, 1, 1), 1

        def predict(self, U, Y, mode="one_step"):
            return Y + 0.1 if mode == "one_step" else np.full_like(Y, np.inf)

    g = np.random.default_rng(0)
    seg = Segment("s", np.arange(20.0), g.normal(size=(20, 2)), g.normal(size=(20, 2)))
    m, arr = evaluate_segments(Diverging(), [seg, seg], ["a", "b"])
    assert m["one_step"]["a"]["r"] == pytest.approx(1.0)
    assert arr["one_step"][0].shape == (38, 2)               # t0 = 1 dropped per segment
    assert np.isnan(m["free_run"]["b"]["r"]) and m["free_run"]["b"]["diverged"]


def test_same_seed_same_section():
    from cdam_core.paper import PaperConfig, prepare_data, run_section, simulate_records
    cfg = PaperConfig(seeds=1, duration=2.0, rate=100.0, iterations=1, population=6,
                      lm_epochs=2, algos=("iboa",), narx=None)
    data = prepare_data(simulate_records(3, 2.0), 2, 100.0)
    a, pa, _ = run_section(data, cfg, None)
    b, pb, _ = run_section(data, cfg, None)
    assert a["summary"]["iboa"]["records"] == b["summary"]["iboa"]["records"]
    for k in pa:
        np.testing.assert_array_equal(pa[k], pb[k])


def test_verdict_names_exactly_the_models_that_reach_the_paper(run):
    out, res = run
    md = (out / "index.md").read_text()
    for o in PAPER_T2:
        line = next(l for l in md.splitlines() if l.startswith(f"- **{o}**:"))
        for rec, table in (("test", "Table 2"), ("validation", "Table 3")):
            part = line.split(f"{table}: ")[1].split(";")[0].rstrip(".")
            expect = []
            for section, modes in SECTION_MODES.items():
                for mode in modes:
                    vals = [np.mean([r["metrics"][rec][mode][o]["r"] for r in a["runs"]])
                            for a in (res["sections"][section]["algorithms"][x] for x in ALGOS)]
                    paper = (PAPER_T2 if rec == "test" else PAPER_T3)[o]
                    if all(round(v, 4) >= p for v, p in zip(vals, paper)):
                        name = {"static": "static", "narx": "NARX net",
                                "hybrid": "hybrid"}[section]
                        expect.append(f"{name} {MODE_LABEL[mode]}")
            assert part == (", ".join(expect) if expect else "no model"), (o, table)


def test_hybrid_structure_is_chosen_on_training_data_and_reported(run):
    out, res = run
    sec = res["sections"]["hybrid"]
    st = sec["structure"]
    rs = [c["training_tail_free_run_r"] for c in st["candidates"]]
    assert rs == sorted(rs, reverse=True) and st["training_tail_free_run_r"] == rs[0]
    assert st["narx"] == st["candidates"][0]["narx"] == sec["config"]["narx"]
    assert sec["config"]["model"] == "hybrid"
    for a in ALGOS:
        for r in sec["algorithms"][a]["runs"]:
            w = r["residual_weight"]
            tail = r["training_tail_free_run_r"]
            assert w == (1.0 if tail["1.0"] > tail["0.0"] else 0.0)
    assert f"orders (na, nb, nk) = {tuple(st['narx'])}" in (out / "index.md").read_text()


def test_k_step_measured_arrays_drop_t0_plus_k_minus_one_per_segment(run):
    out, res = run
    npz = np.load(out / "predictions.npz")
    k = 10                                           # 0.1 s at 100 Hz
    for section in ("narx", "hybrid"):
        t0 = res["predictions"]["t0"][section]
        one = npz[f"{section}/validation/one_step/measured"]
        ks = npz[f"{section}/validation/k_step_0.1s/measured"]
        n = len(one) // 2                            # two equal validation segments
        np.testing.assert_array_equal(ks, np.vstack([one[k - 1:n], one[n + k - 1:]]))
        assert len(ks) == len(one) - 2 * (k - 1) and t0 >= 0


from cdam_core.models.protocol import Model  # noqa: E402


class _LinearArx(Model):
    """y(t) = a1 y(t-1) + a2 y(t-2) + b u(t-1): a model with a one-step predictor only (the
    protocol derives k-step prediction from it)."""
    kind = "test_arx"
    t0 = 2
    n_inputs_ = n_outputs_ = 1

    def __init__(self, a1, a2, b):
        self.a1, self.a2, self.b = a1, a2, b

    def _fit(self, U, Y):
        pass

    def _one_step(self, U, Y):
        return self.a1 * Y[1:-1] + self.a2 * Y[:-2] + self.b * U[1:-1, :1]

    def to_dict(self):
        return {}

    @classmethod
    def from_dict(cls, d):
        return cls(0, 0, 0)


def test_k_step_prediction_against_an_explicit_simulation():
    from cdam_core.evaluate.kstep import horizon_steps, k_step_predict
    g = np.random.default_rng(1)
    U, Y = g.normal(size=(40, 1)), g.normal(size=(40, 1))
    model = _LinearArx(1.5, -0.6, 0.3)
    for k in (1, 3, 7):
        P = k_step_predict(model, U, Y, k)
        for t in range(2 + k - 1, 40):              # simulate from the measured y(..t-k)
            z = list(Y[t - k - 1:t - k + 1, 0])     # y(t-k-1), y(t-k)
            for s in range(t - k + 1, t + 1):
                z.append(1.5 * z[-1] - 0.6 * z[-2] + 0.3 * U[s - 1, 0])
            assert P[t, 0] == pytest.approx(z[-1], rel=1e-12, abs=1e-12)
        np.testing.assert_array_equal(P[:2 + k - 1], Y[:2 + k - 1])
    np.testing.assert_array_equal(k_step_predict(model, U, Y, 1), model.predict(U, Y))
    assert horizon_steps(0.1, 200.0) == 20 and horizon_steps(0.5, 1000.0) == 500
    with pytest.raises(ValueError, match="horizon_s"):
        horizon_steps(0.001, 200.0)
    with pytest.raises(ValueError, match="k"):
        k_step_predict(model, U, Y, 0)
    with pytest.raises(ValueError, match="U, Y"):
        k_step_predict(model, U[:5], Y, 2)
    with pytest.raises(ValueError, match="NaN"):
        k_step_predict(model, U, np.full_like(Y, np.nan), 2)
    with pytest.raises(ValueError, match="dynamic"):
        k_step_predict(type("Static", (), {"narx": None})(), U, Y, 2)


def test_bad_horizon_is_rejected(tmp_path, capsys):
    from cdam_core.paper import PaperConfig
    with pytest.raises(ValueError, match="horizon_s"):
        PaperConfig(horizons=(0.001,))
    with pytest.raises(ValueError, match="horizon_s"):
        PaperConfig(horizons=(float("nan"),))
    assert main(["paper", "--out", str(tmp_path / "h"), "--horizon", "-1", "--quiet"]) == 2
    assert "horizon" in capsys.readouterr().err


def test_persistence_baseline_from_the_records(run):
    """Independent: savgol passes + decimate on the saved test CSVs, then corrcoef of y(t)
    against y(t - k) per output, segments pooled."""
    out, res = run
    npz = np.load(out / "predictions.npz")

    def prep(name):
        return _smoothed_decimated(out / name)

    segs = [y[len(y) // 2:] for y in (prep("flight_i.csv"), prep("flight_ii.csv"))]
    for mode, k in (("one_step", 1), ("k_step_0.1s", 10)):
        Ym = np.vstack([s[k:] for s in segs])
        Pm = np.vstack([s[:-k] for s in segs])
        np.testing.assert_allclose(npz[f"persistence/test/{mode}/measured"], Ym, atol=1e-9)
        np.testing.assert_allclose(npz[f"persistence/test/{mode}/predicted"], Pm, atol=1e-9)
        for j, o in enumerate(res["sections"]["static"]["outputs"]):
            r_np = np.corrcoef(Ym[:, j], Pm[:, j])[0, 1]
            assert res["persistence"]["test"][mode][o]["r"] == pytest.approx(r_np, abs=1e-9)
    with pytest.raises(ValueError, match="segments"):
        from cdam_core.evaluate.baselines import persistence
        persistence([], ["a"], 100.0)


def test_above_persistence_lists_match_the_runs(run):
    out, res = run
    md = (out / "index.md").read_text()
    names = {"narx": "NARX net", "hybrid": "hybrid"}
    for section in ("narx", "hybrid"):
        for rec, table in (("test", "Table 2"), ("validation", "Table 3")):
            for mode in ("one_step", "k_step_0.1s"):
                runs = res["sections"][section]["algorithms"]["iboa"]["runs"]
                base = res["persistence"][rec][mode]
                mean = {o: np.mean([r["metrics"][rec][mode][o]["r"] for r in runs])
                        for o in PAPER_T2}
                above = [o for o in PAPER_T2 if mean[o] > base[o]["r"]]
                head = f"- {names[section]}, {MODE_LABEL[mode]}: reaches {table}"
                line = next(l for l in md.splitlines() if l.startswith(head))
                tail = line.split(f"above persistence {MODE_LABEL[mode]} on ")[1]
                assert tail.startswith(f"{len(above)} of 8")
                if above:
                    assert tail.endswith(f"({', '.join(above)}).")
    assert "- static, one-step: reaches Table 2 on" in md and "static, one-step: reaches " \
        "Table 2 on 0 of 8 outputs; IBOA" not in md
