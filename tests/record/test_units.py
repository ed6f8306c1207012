"""Declared units (issue 24: "declared units are ignored"; the sidecar's units were only
type-checked). A standard column whose physical meaning is fixed must be in its standard unit;
the inputs T / tau_* may be normalised commands (PX4 logs them so; import-ulog declares it); a
physical model refuses a normalised command or a unit its equations are not written in. Files
are written here with plain Python."""
import json
import math

import numpy as np
import pytest

from cdam_core.cli.main import main
from cdam_core.record.dataset import Dataset, read_dataset

COLS = ["T", "tau_phi", "tau_theta", "tau_psi", "phi", "theta", "psi", "X", "Y", "Z"]


def _record(path, columns, units, n=200):
    lines = [",".join(["t", *columns])]
    for k in range(n):
        lines.append(",".join([repr(k / 100)] + [repr(math.sin(0.1 * k + j))
                                                 for j in range(len(columns))]))
    path.write_text("\n".join(lines) + "\n")
    path.with_suffix(".json").write_text(json.dumps({"rate": 100.0, "units": units}))
    return path


@pytest.mark.parametrize("col, unit, std", [("phi", "deg", "rad"), ("Z", "mm", "m"),
                                            ("t", "ms", "s"), ("q1", "deg", "rad")])
def test_a_fixed_standard_column_in_another_unit_is_named(tmp_path, col, unit, std):
    cols = COLS + ["q1"]
    p = _record(tmp_path / "r.csv", cols, {col: unit})
    with pytest.raises(ValueError) as e:
        read_dataset(p)
    msg = str(e.value)
    assert "'units'" in msg and f"{col}:" in msg and repr(unit) in msg and repr(std) in msg


@pytest.mark.parametrize("col, unit", [("T", "kN"), ("T", "g"), ("tau_phi", "N cm")])
def test_a_command_column_in_another_physical_unit_is_named(tmp_path, col, unit):
    p = _record(tmp_path / "r.csv", COLS, {col: unit})
    with pytest.raises(ValueError, match=f"{col}: {unit!r} is neither the standard"):
        read_dataset(p)


def test_accepted_units(tmp_path):
    units = {"T": "normalised thrust (0..1 of full thrust)", "tau_phi": "Nm",
             "tau_theta": "N*m", "tau_psi": "N·m", "phi": "rad", "X": "m", "t": "s"}
    ds = read_dataset(_record(tmp_path / "r.csv", COLS, units))
    assert ds.units["T"].startswith("normalised") and ds.units["tau_phi"] == "Nm"
    # a map with a factor converts the column: it is then in the standard unit
    p = _record(tmp_path / "deg.csv", COLS, {"phi": "deg"})
    ds = read_dataset(p, mapping=f"phi=phi*{math.pi / 180!r}")
    assert ds.units["phi"] == "rad"
    np.testing.assert_allclose(ds.column("phi"), np.sin(0.1 * np.arange(200) + 4) * math.pi / 180)


def test_an_in_memory_dataset_is_checked_too():
    with pytest.raises(ValueError, match="phi: declared 'deg'"):
        Dataset(t=[0.0, 0.1], columns=["phi"], data=[[0.0], [1.0]], meta={"units": {"phi": "deg"}})


def test_import_ulog_record_reads_and_the_quadrotor_model_refuses_it(tmp_path, capsys):
    """The producer the strict check first broke: import-ulog writes PX4's normalised thrust
    and torques under the standard names, declaring them normalised; the record reads, and the
    quadrotor model (thrust in N) refuses it by name instead of fitting command units."""
    from cdam_core.record.realdata import shared_data_dir
    log = shared_data_dir() / "ulog" / "sample_px4_events.ulg"
    if not log.is_file():
        pytest.skip("shared ULog data not found")
    out = tmp_path / "flight.csv"
    assert main(["import-ulog", str(log), "-o", str(out), "--rate", "100"]) == 0
    ds = read_dataset(out)
    assert ds.units["T"] == "normalised thrust (0..1 of full thrust)"
    assert ds.units["phi"] == "rad" and ds.units["X"] == "m"
    capsys.readouterr()
    assert main(["residual", str(out), "--model", "quadrotor"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("T (column T) is a normalised command ('normalised thrust (0..1 of "
                        "full thrust)'); the quadrotor model needs it in physical units (N)"), err


@pytest.mark.parametrize("model, columns, units, text", [
    ("quadrotor", COLS, {"T": "normalised thrust (0..1 of full thrust)"},
     "T (column T) is a normalised command"),
    ("rigid_axis", ["tau", "q"], {"tau": "normalised command"},
     "tau (column tau) is a normalised command"),
    ("rigid_axis", ["tau", "q"], {"tau": "N", "q": "rad"}, "a force in N with a position in m"),
    ("flexible_joint", ["tau_m1", "theta_m1", "q1"], {"tau_m1": "normalised torque (-1..1)"},
     "tau_m (column tau_m1) is a normalised command"),
])
def test_a_physical_model_refuses_units_it_cannot_use(tmp_path, capsys, model, columns, units,
                                                      text):
    p = _record(tmp_path / "r.csv", columns, units)
    rc = main(["residual", str(p), "--model", model])
    err = capsys.readouterr().err.strip()
    assert rc == 2, err
    assert err.startswith("cdam residual: error: ") and text in err, err
    assert len(err.splitlines()) == 1


def test_evaluate_a_greybox_model_on_a_record_of_normalised_commands(tmp_path, capsys):
    """`cdam evaluate` with a saved grey-box model: the model checks the record's units."""
    from cdam_core.models import save_model
    from cdam_core.models.greybox.augmented import GreyBox
    rng = np.random.default_rng(0)
    n = 400
    tau = rng.uniform(-1, 1, n)
    q = np.cumsum(np.cumsum(tau)) * 1e-5
    save_model(tmp_path / "gb.json", GreyBox("rigid_axis", 0.01, [], cutoff_hz=20.0).fit(
        tau[:, None], q[:, None]), inputs=["tau"], outputs=["q"])
    lines = ["t,tau,q"] + [f"{k / 100!r},{a!r},{b!r}" for k, (a, b) in
                           enumerate(zip(tau.tolist(), q.tolist()))]
    rec = tmp_path / "r.csv"
    rec.write_text("\n".join(lines) + "\n")
    rec.with_suffix(".json").write_text(json.dumps({"units": {"tau": "normalised command"}}))
    assert main(["evaluate", str(tmp_path / "gb.json"), str(rec), "--horizon", "2",
                 "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "tau (column tau) is a normalised command" in err and len(err.splitlines()) == 1
    rec.with_suffix(".json").write_text(json.dumps({"units": {"tau": "N", "q": "m"}}))
    assert main(["evaluate", str(tmp_path / "gb.json"), str(rec), "--horizon", "2",
                 "--quiet"]) == 0
