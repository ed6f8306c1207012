"""`cdam identify --model arx_kstep` then `cdam evaluate`, the documented path of the ARX-anchored
k-step model, on small records of an independent two-output plant a linear ARX cannot follow
(generated here in plain numpy): the validation records are the rule's (the last of each type),
the saved model predicts what the fitted one does, evaluate scores it beside naive and the ARX
chosen on the same validation records; options checked with one line each. The published
table and its markers on a real flight (skipped without the shared flights)."""
import json

import numpy as np
import pytest

from cdam_core.cli.main import main
from cdam_core.record.dataset import Dataset, write_dataset
from cdam_core.record.realdata import shared_data_dir

FLIGHTS = shared_data_dir() / "nanodrone"


def _plant(n, seed):
    """y1' = 0.85 y1 + 0.1 y2 + 0.4 tanh(2 u1(t-1)); y2' = 0.8 y2 + 0.3 u2(t-1) - 0.3 y1 |y1|,
    inputs first-order filtered white noise, small output noise."""
    rng = np.random.default_rng(seed)
    U = np.zeros((n, 2))
    for t in range(1, n):
        U[t] = 0.9 * U[t - 1] + 0.3 * rng.normal(size=2)
    Y = np.zeros((n, 2))
    for t in range(1, n):
        y1, y2 = Y[t - 1]
        Y[t] = [0.85 * y1 + 0.1 * y2 + 0.4 * np.tanh(2 * U[t - 1, 0]),
                0.8 * y2 + 0.3 * U[t - 1, 1] - 0.3 * y1 * abs(y1)]
    Y += 0.002 * rng.normal(size=Y.shape)
    return Dataset(t=np.arange(n) * 0.01, columns=["u1", "u2", "y1", "y2"],
                   data=np.column_stack([U, Y]),
                   meta={"inputs": ["u1", "u2"], "outputs": ["y1", "y2"]})


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    """Two types of two runs each for training, a third type to test on."""
    d = tmp_path_factory.mktemp("plant")
    names = ["stepa_run1", "stepa_run2", "stepb_run1", "stepb_run2", "stepc_run1"]
    paths = []
    for k, name in enumerate(names):
        paths.append(d / f"{name}.parquet")
        write_dataset(paths[-1], _plant(1200, k + 1))
    return paths[:4], paths[4]


SMALL = ["--hidden", "4", "--lags", "1", "--horizon", "10", "--epochs", "6", "--stride", "10"]


@pytest.mark.parametrize("design", [[], ["--blend-design", "flights"]])
def test_identify_save_evaluate_round_trip(records, tmp_path, capsys, monkeypatch, design):
    import cdam_core.models.file as model_file
    from cdam_core.models.file import load_model
    from cdam_core.record.stack import stack_records

    train, test = records
    fitted = {}
    save = model_file.save_model

    def spy(path, model, **kw):             # the in-memory model the command saves
        fitted["model"] = model
        return save(path, model, **kw)

    monkeypatch.setattr(model_file, "save_model", spy)
    path = tmp_path / "m.json"
    assert main(["identify", *map(str, train), "--model", "arx_kstep", "--validation",
                 "per-type", *SMALL, *design, "--save", str(path), "--json",
                 str(tmp_path / "id.json"), "--quiet"]) == 0
    out = capsys.readouterr().out
    idj = json.loads((tmp_path / "id.json").read_text())
    # the rule's validation records: the last run of each type, by file name
    assert idj["validation_files"] == [str(train[1]), str(train[3])]
    # the plant is nonlinear: the network is kept (kind arx_kstep, or a blend holding it)
    assert idj["kind"] != "arx" and "network kept" in out
    assert idj["fixed"]["net_features"] == "raw"                     # two inputs: no rotors
    assert idj["choice"]["validation"][idj["choice"]["chosen"]] < \
        idj["choice"]["validation"]["arx"]
    # the default (auto): type out over the two training types, the direct decision
    assert idj["choice"]["blend_design_asked"] == ("flights" if design else "auto")
    if not design:
        assert idj["choice"]["blend_design"] == "types"
        t = idj["choice"]["type_out"]
        assert t["types"] == ["stepa", "stepb"] and "weights chosen type out" in out
        assert t["keep_direct"] == (t["scores"]["with_direct"] < t["scores"]["without_direct"])
        assert any(" direct " in n for n in idj["choice"]["blend_components"]) == \
            t["keep_direct"]
        closed = sum(len(v) for v in t["gate"]["closed"])
        assert f"the ARX's weights alone (the held-out types did not prefer the blend) at " \
            f"{closed} of 100 steps x groups" in out        # 50 steps, two outputs
    else:
        assert idj["choice"]["blend_design"] == "flights" and "type_out" not in idj["choice"]
    # the file predicts what the fitted model does (k-step and from the inputs alone)
    st = stack_records([test])
    mem, disk = fitted["model"], load_model(path)
    for mode, k in (("k_step", 10), ("one_step", 1)):
        a = mem.predict(st.U, st.Y, mode=mode, k=k)
        b = disk.predict(st.U, st.Y, mode=mode, k=k)
        assert np.max(np.abs(a - b)) <= 1e-12 * np.max(np.abs(a))
    np.testing.assert_array_equal(mem.predict(st.U[:300]), disk.predict(st.U[:300]))
    # evaluate on the unseen type, the ARX baseline chosen on the same validation records
    assert main(["evaluate", str(path), str(test), "--horizon", "10", "--no-free-run",
                 "--baselines", *map(str, train), "--validation", "per-type", "--json",
                 str(tmp_path / "ev.json"),
                 "--report", str(tmp_path / "rep"), "--quiet"]) == 0
    ev = json.loads((tmp_path / "ev.json").read_text())
    assert ev["model"]["kind"] == idj["kind"]
    assert ev["baselines"]["arx"]["narx"] == idj["choice"]["arx_orders"]
    assert ev["baselines"]["arx"]["validation"] == idj["validation_files"]
    rm = ev["rmse"]
    for o in ("y1", "y2"):                   # held out: below naive and the ARX at h = 10
        assert rm["model"][o][-1] < min(rm["naive"][o][-1], rm["arx"][o][-1]), (o, rm)
    assert (tmp_path / "rep" / "rmse_vs_horizon.png").stat().st_size > 0


def _bad_identify(records, extra):
    train, _ = records
    return ["identify", *map(str, train), *extra, "--quiet"]


@pytest.mark.parametrize("argv, message", [
    (["--model", "arx_kstep", "--hidden", "0"], "--hidden: must be"),
    (["--model", "arx_kstep", "--stride", "-2"], "--stride: must be"),
    (["--model", "arx_kstep", "--narx", "2,2,1"], "--narx: not used by --model arx_kstep"),
    (["--model", "arx_kstep", "--weighting", "flat"], "--weighting: not used by"),
    (["--model", "arx_kstep", "--horizon", "5000"], "--horizon: windows of 5000 steps do not"),
    (["--stride", "5"], "--stride: needs --model arx_kstep"),
    (["--validation", "last"], "--validation: needs --model arx_kstep"),
    (["--blend-design", "types"], "--blend-design: needs --model arx_kstep"),
])
def test_identify_options_are_checked(records, capsys, argv, message):
    assert main(_bad_identify(records, argv)) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("cdam identify: error: ") and message in err and "\n" not in err


def test_per_type_needs_a_record_left_to_fit(records, capsys):
    train, test = records
    argv = ["identify", str(train[0]), str(train[2]), str(test), "--model", "arx_kstep",
            "--validation", "per-type", "--quiet"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("cdam identify: error: --validation per-type: every record is the "
                          "only one of its type") and "\n" not in err


def test_evaluate_validation_needs_baselines(records, tmp_path, capsys):
    from cdam_core.models import ArxModel, save_model
    from cdam_core.record.stack import stack_records
    train, test = records
    st = stack_records(train[:1])
    save_model(tmp_path / "a.json", ArxModel((1, 1, 1)).fit(st.U, st.Y), inputs=st.inputs,
               outputs=st.outputs)
    assert main(["evaluate", str(tmp_path / "a.json"), str(test), "--validation", "last",
                 "--quiet"]) == 2
    assert "cdam evaluate: error: --validation: needs --baselines" in capsys.readouterr().err


@pytest.mark.skipif(not (FLIGHTS / "square_20251017_run1.parquet").is_file(),
                    reason=f"nano-drone flights not found at {FLIGHTS} (set CDAM_SHARED_DATA)")
def test_evaluate_prints_the_published_table_beside_ours_on_flights(tmp_path, capsys):
    """On the benchmark's 13 states: the published table (evaluate.published) printed and on
    the report page, its h = 50 markers on the per-group plot (units on the axes)."""
    from cdam_core.evaluate.published import NANODRONE_PUBLISHED
    from cdam_core.models import ArxModel, save_model
    from cdam_core.record.stack import stack_records
    flight = FLIGHTS / "random1_20251017_run1.parquet"
    st = stack_records([flight], loader="nanodrone")
    save_model(tmp_path / "a.json", ArxModel((1, 1, 1)).fit(st.U, st.Y, segments=st.lengths),
               inputs=st.inputs, outputs=st.outputs)
    assert main(["evaluate", str(tmp_path / "a.json"), str(FLIGHTS / "square_20251017_run1"
                                                           ".parquet"),
                 "--loader", "nanodrone", "--horizon", "50", "--no-free-run", "--report",
                 str(tmp_path / "rep"), "--quiet"]) == 0
    out = capsys.readouterr().out
    page = (tmp_path / "rep" / "index.md").read_text()
    for name, row in NANODRONE_PUBLISHED.items():
        line = f"| {name} | {row['position'][0]:.3f} ({row['position'][1]:.2f}) |"
        assert line in out and line in page
    assert "## Published" in page and "markers at h = 50" in page
    assert (tmp_path / "rep" / "group_mae_vs_horizon.png").stat().st_size > 0


def test_help_states_the_anchored_defaults():
    """`cdam identify --help` states arx_kstep's defaults: the fixed ones as evaluate.crossfold
    holds them (the help text is static: this fails when they change and the help does not),
    the structure's as chosen among ANCHORED_GRID's."""
    import argparse

    from cdam_core.cli.identify import ANCHORED_OPTIONS
    from cdam_core.cli.main import build_parser
    from cdam_core.evaluate.crossfold import ANCHORED_FIXED, ANCHORED_GRID
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    helps = {a.dest: " ".join(a.help.split()) for a in sub.choices["identify"]._actions}
    for name in ANCHORED_OPTIONS:
        if any(name in kw for kw in ANCHORED_GRID.values()):
            assert "arx_kstep: chosen on validation among" in helps[name] and \
                "ANCHORED_GRID" in helps[name], (name, helps[name])
        else:
            v = ANCHORED_FIXED[name]
            assert f"arx_kstep: {v}," in helps[name] or (name == "stride" and f"default: {v},"
                                                         in helps[name]), (name, helps[name])


def test_type_out_needs_two_types(records, capsys):
    train, _ = records
    argv = ["identify", str(train[0]), str(train[1]), "--model", "arx_kstep", "--validation",
            "last", "--blend-design", "types", *SMALL, "--quiet"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("cdam identify: error: TRAIN: blend_design 'types': the training "
                          "flights hold 1 type(s)") and "\n" not in err
