"""`cdam residual` end to end on a small synthetic CSV."""
import json
import re

import numpy as np
import pytest
from test_residual_synth_data import rigid_axis_record

from cdam_core.cli.main import main


def _csv(path, rec, extra=()):
    cols = ["t", "force", "pos"] + list(extra)
    data = np.column_stack([rec["t"], rec["tau"], rec["q"]] + [rec[c] for c in extra])
    np.savetxt(path, data, delimiter=",", header=",".join(cols), comments="", fmt="%.10g")


def test_cli_json_and_report(tmp_path):
    rec = rigid_axis_record(seed=2, Fc=1.5, duration=6.0)
    _csv(tmp_path / "r.csv", rec)
    rc = main(["residual", str(tmp_path / "r.csv"), "--model", "rigid_axis", "--map",
               "tau=force,q=pos", "--json", str(tmp_path / "o.json"), "--report",
               str(tmp_path / "rep")])
    assert rc == 0
    js = json.loads((tmp_path / "o.json").read_text())
    assert set(js) >= {"model", "declared_error", "findings", "residual_white_after", "unexplained"}
    assert js["findings"][0]["effect"] == "coulomb_friction"
    f = js["findings"][0]
    assert set(f) == {"effect", "channel", "parameters", "error_before", "error_after", "evidence"}
    assert set(f["error_before"]) == {"tau", "q"}   # equation and free-run errors
    assert f["error_after"]["tau"]["rmse"] < f["error_before"]["tau"]["rmse"]
    assert (tmp_path / "rep" / "index.md").is_file()
    assert list((tmp_path / "rep").glob("finding_1_*.png"))


def test_cli_stdout_is_a_summary_of_the_json(tmp_path, capsys):
    """stdout has the summary a person reads (every final parameter with its relative sigma,
    the findings), not the JSON: that goes to --json FILE, as for every command."""
    rec = rigid_axis_record(seed=2, Fc=1.5, duration=6.0)
    _csv(tmp_path / "r.csv", rec)
    capsys.readouterr()
    assert main(["residual", str(tmp_path / "r.csv"), "--model", "rigid_axis", "--map",
                 "tau=force,q=pos", "--json", str(tmp_path / "o.json")]) == 0
    out = capsys.readouterr().out
    js = json.loads((tmp_path / "o.json").read_text())
    assert not out.lstrip().startswith("{")
    rows = dict(re.findall(r"^  (\S+) \S+ \((\S+) %\)$", out, flags=re.M))
    dropped = set(re.findall(r"^  (\S+) 0 \(dropped: no held-out gain\)$", out, flags=re.M))
    assert dropped == {d["term"] for d in js["settings"]["declared_terms_dropped"]}
    assert set(rows) | dropped == set(js["final_parameters"]) and not set(rows) & dropped
    for k, v in js["final_parameters"].items():
        if k in dropped:
            continue
        rel = 100 * abs(js["final_std"][k] / v)
        assert float(rows[k]) == pytest.approx(rel, rel=0.05), k
    assert f"found coulomb_friction on {js['findings'][0]['channel']}" in out


def test_cli_saves_the_augmented_model(tmp_path):
    """`--save` writes the final model (declared + found effects) as a greybox model file
    that loads and predicts the record like any other kind."""
    from cdam_core.models import load_model
    rec = rigid_axis_record(seed=2, Fc=1.5, duration=6.0)
    _csv(tmp_path / "r.csv", rec)
    assert main(["residual", str(tmp_path / "r.csv"), "--model", "rigid_axis", "--map",
                 "tau=force,q=pos", "--json", str(tmp_path / "o.json"), "--save",
                 str(tmp_path / "m.json")]) == 0
    js = json.loads((tmp_path / "o.json").read_text())
    m = load_model(tmp_path / "m.json")
    assert m.kind == "greybox" and m.input_names_ == ["force"] and m.output_names_ == ["pos"]
    assert js["saved_model"]["kind"] == "greybox"
    assert [e.key for e in m.effects] == ["coulomb_friction@tau"]
    p = m.parameters()
    # the saved model holds the final estimates (those of the estimator chosen on held-out data)
    for name, value in js["final_parameters"].items():
        assert p[name][0] == pytest.approx(value, rel=1e-12), name
    U, Y = rec["tau"][:, None], rec["q"][:, None]
    P = m.predict(U, Y, mode="k_step", k=100)
    assert np.sqrt(np.mean((P - Y) ** 2)) < 0.05 * np.std(Y)


def test_cli_errors(tmp_path, capsys):
    rec = rigid_axis_record(seed=2, duration=2.0)
    _csv(tmp_path / "r.csv", rec)
    assert main(["residual", str(tmp_path / "r.csv"), "--model", "quadrotor"]) == 2
    assert "column 'T'" in capsys.readouterr().err   # the flight model's columns are missing
    assert main(["residual", str(tmp_path / "r.csv"), "--model", "rigid_axis", "--map",
                 "tau=force,q=pos", "--fixed", "M=heavy"]) == 2
    assert "--fixed" in capsys.readouterr().err
    assert main(["residual", str(tmp_path / "r.csv"), "--model", "rigid_axis",
                 "--map", "tau=nope,q=pos"]) == 2
    assert "nope" in capsys.readouterr().err
    assert main(["residual", str(tmp_path / "r.csv"), "--model", "rigid_axis",
                 "--map", "tau"]) == 2


def test_cli_on_a_simulated_flight(tmp_path):
    """`cdam simulate` output -> `cdam residual --model aerial_manipulator`: the sidecar's
    declared arm_coupling is part of the declared model, the hidden thrust loss is found."""
    from cdam_core.sim import simulate_flight, write_flight
    ds = simulate_flight("both", duration=6.0, seed=3, effects=["thrust_loss:c=0.005"],
                         declare=["arm_coupling"])
    write_flight(tmp_path / "f.csv", ds)
    rc = main(["residual", str(tmp_path / "f.csv"), "--model", "aerial_manipulator", "--fixed",
               "m=1.82", "--no-free-run", "--json", str(tmp_path / "o.json"), "--save",
               str(tmp_path / "m.json")])
    assert rc == 0
    from cdam_core.models import load_model
    m = load_model(tmp_path / "m.json")
    assert sorted(e.key for e in m.effects) == sorted(
        ["arm_coupling@" + c for c in ("X", "Y", "Z", "tau_phi", "tau_theta")] + ["thrust_loss@Z"])
    assert m.input_names_[:4] == ["T", "tau_phi", "tau_theta", "tau_psi"]
    js = json.loads((tmp_path / "o.json").read_text())
    assert js["declared_effects"] == ["arm_coupling"]
    assert [(f["effect"], f["channel"]) for f in js["findings"]] == [("thrust_loss", "Z")]
    assert js["findings"][0]["parameters"]["c"] == pytest.approx(0.005, rel=0.2)
    assert set(js["declared_error"]) >= {"X", "Z", "tau_theta", "tau_m1", "tau_l2"}


def test_cli_firmware_refit_on_causal_columns(tmp_path, capsys):
    """--save --firmware: the saved arm_coupling effects are causal (computable row by row),
    the model is refitted on them (the hidden thrust loss keeps its value), and the firmware
    exporter takes the file, which it refuses with the zero-phase columns."""
    from cdam_core import firmware as fw
    from cdam_core.sim import simulate_flight, write_flight
    ds = simulate_flight("both", duration=6.0, seed=3, effects=["thrust_loss:c=0.005"],
                         declare=["arm_coupling"])
    write_flight(tmp_path / "f.csv", ds)
    base = ["residual", str(tmp_path / "f.csv"), "--model", "aerial_manipulator", "--fixed",
            "m=1.82", "--no-free-run", "--estimator", "idim-ls"]
    assert main(base + ["--firmware"]) == 2
    assert "--firmware: needs --save" in capsys.readouterr().err
    assert main(base + ["--json", str(tmp_path / "o.json"), "--save", str(tmp_path / "m.json"),
                        "--firmware"]) == 0
    from cdam_core.models import load_model
    m = load_model(tmp_path / "m.json")
    arm = [e for e in m.effects if e.name == "arm_coupling"]
    assert len(arm) == 5 and all(e.causal for e in arm)
    assert m.theta_["thrust_loss@Z.c"] == pytest.approx(0.005, rel=0.2)
    saved = json.loads((tmp_path / "o.json").read_text())["saved_model"]
    assert saved["firmware_refit"] is True
    # refitted by the loop's own estimator (selection.refit): with the zero-phase columns it is
    # the loop's model again (GreyBox's own IDIM fit, used until session 9, was 0.2-0.85 % off
    # on the joint channels)
    assert saved["estimator"] == "IDIM-LS"
    np.testing.assert_allclose(saved["one_step_rms_zero_phase"],
                               saved["one_step_rms_residual_model"], rtol=1e-9)
    # refitted alike, causal and zero-phase columns predict one step ahead alike (1 % per
    # output; the monitor watches this error)
    np.testing.assert_allclose(saved["one_step_rms_causal"], saved["one_step_rms_zero_phase"],
                               rtol=1e-2)
    fw.export_header(tmp_path / "m.json", tmp_path / "m.hpp")
    assert "#define CDAM_MODEL_ARM 1" in (tmp_path / "m.hpp").read_text()


def test_cli_test_record_under_the_simulation_protocol(tmp_path):
    """--test: the declared and final models simulated on another record from its first
    --n-init outputs; --simulated writes them beside the measured output."""
    _csv(tmp_path / "a.csv", rigid_axis_record(seed=2, Fc=1.5, duration=6.0))
    test = rigid_axis_record(seed=5, Fc=1.5, duration=4.0)
    _csv(tmp_path / "b.csv", test)
    assert main(["residual", str(tmp_path / "a.csv"), "--model", "rigid_axis", "--map",
                 "tau=force,q=pos", "--no-free-run", "--test", str(tmp_path / "b.csv"),
                 "--n-init", "20", "--simulated", str(tmp_path / "sim.csv"), "--json",
                 str(tmp_path / "o.json")]) == 0
    js = json.loads((tmp_path / "o.json").read_text())["test"]
    dec, fin = js["scores"]["declared"], js["scores"]["final"]
    assert dec["status"] == fin["status"] == "ok"
    assert fin["rmse"][0] < 0.5 * dec["rmse"][0]      # the Coulomb term the declared lacks
    sim = np.genfromtxt(tmp_path / "sim.csv", delimiter=",", names=True)
    assert sim.dtype.names == ("t", "pos", "pos_declared", "pos_final")
    np.testing.assert_allclose(sim["pos"], test["q"], rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(sim["pos_final"][:20], sim["pos"][:20])
    rmse = np.sqrt(np.mean((sim["pos_final"][20:] - sim["pos"][20:]) ** 2))
    assert rmse == pytest.approx(fin["rmse"][0], rel=1e-6)
    assert main(["residual", str(tmp_path / "a.csv"), "--model", "rigid_axis", "--map",
                 "tau=force,q=pos", "--test", str(tmp_path / "a.csv"), "--simulated",
                 str(tmp_path / "a.csv")]) != 0     # never over an input


def test_cli_never_loses_the_analysis(tmp_path):
    """A record no passive axis explains (the force opposes the acceleration: a negative
    inertia; the final model, refitted with the bounds, has none and cannot be simulated):
    its free run is reported unavailable with its reason, the JSON and report are still
    written, exit code 1."""
    rng = np.random.default_rng(0)
    t = np.arange(3000) * 1e-3
    q = 0.2 * np.sin(2 * np.pi * 1.1 * t) + 0.05 * np.sin(2 * np.pi * 3.7 * t)
    tau = -2.0 * np.gradient(np.gradient(q, 1e-3), 1e-3) + 0.01 * rng.standard_normal(t.size)
    np.savetxt(tmp_path / "r.csv", np.column_stack([t, tau, q]), delimiter=",",
               header="t,force,pos", comments="", fmt="%.10g")
    rc = main(["residual", str(tmp_path / "r.csv"), "--model", "rigid_axis", "--map",
               "tau=force,q=pos", "--json", str(tmp_path / "o.json"), "--report",
               str(tmp_path / "rep")])
    js = json.loads((tmp_path / "o.json").read_text())
    fr = js["error_final"]["q"]
    assert fr["status"] == "unavailable" and fr["reason"]
    assert js["complete"] is False and rc == 1
    assert (tmp_path / "rep" / "index.md").is_file()
    assert "tau" in js["declared_error"] and js["declared_error"]["tau"]["rmse"] > 0
    assert "M" in js["feasibility"]["declared"]["violations"]
    assert js["feasibility"]["declared"]["unconstrained"]["M"] == pytest.approx(-2.0, rel=0.05)


def test_map_takes_the_common_syntax_and_refuses_a_factor(tmp_path, capsys):
    """--map is parsed as every other --map (text or a JSON file); a scale factor, which the
    saved model could not carry, is a named error before anything is computed."""
    rec = rigid_axis_record(seed=2, Fc=1.5, duration=3.0)
    _csv(tmp_path / "r.csv", rec)
    rc = main(["residual", str(tmp_path / "r.csv"), "--model", "rigid_axis", "--map",
               "tau=force*2,q=pos"])
    assert rc == 2 and "--map: tau=force*2" in capsys.readouterr().err
    (tmp_path / "map.json").write_text(json.dumps({"tau": "force", "q": "pos"}))
    assert main(["residual", str(tmp_path / "r.csv"), "--model", "rigid_axis", "--map",
                 str(tmp_path / "map.json"), "--no-free-run", "--json",
                 str(tmp_path / "o.json")]) == 0
    js = json.loads((tmp_path / "o.json").read_text())
    assert js["findings"][0]["effect"] == "coulomb_friction"


def test_cli_estimator_pinned_forced_and_refused(tmp_path, capsys):
    """--estimator idim-ls: the alternatives are not tried (said in the JSON); --estimator oe
    forces the output-error refinement (its report in the JSON, rule "given"); --output-error,
    its older spelling, with another estimator is refused on one line (exit 2)."""
    rec = rigid_axis_record(seed=2, Fc=1.5, duration=6.0)
    _csv(tmp_path / "r.csv", rec)
    base = ["residual", str(tmp_path / "r.csv"), "--model", "rigid_axis", "--map",
            "tau=force,q=pos", "--no-free-run", "--quiet", "--json"]
    assert main(base + [str(tmp_path / "ls.json"), "--estimator", "idim-ls"]) == 0
    est = json.loads((tmp_path / "ls.json").read_text())["settings"]["estimator"]
    assert est["chosen"] == "IDIM-LS" and "not tried" in est["rule"]
    assert main(base + [str(tmp_path / "oe.json"), "--output-error"]) == 0
    est = json.loads((tmp_path / "oe.json").read_text())["settings"]["estimator"]
    assert est["rule"] == "given (oe)"
    assert est["chosen"] == "output error (multiple shooting)", est
    assert est["refinement"]["evaluations"] >= 1
    capsys.readouterr()
    assert main(base + [str(tmp_path / "x.json"), "--output-error", "--estimator",
                        "idim-iv"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["cdam residual: error: --output-error: conflicts with --estimator idim-iv"]


def test_cli_stick_slip_given_and_refused(tmp_path, capsys):
    """--stick-slip on / off: the chosen model's windows with or without the dry friction's
    stick-slip, given (said in the JSON, nothing tested); a value other than auto, on or off
    is refused on one line (exit 2)."""
    rec = rigid_axis_record(seed=2, Fc=1.5, duration=6.0)
    _csv(tmp_path / "r.csv", rec)
    base = ["residual", str(tmp_path / "r.csv"), "--model", "rigid_axis", "--map",
            "tau=force,q=pos", "--no-free-run", "--quiet", "--estimator", "idim-ls", "--json"]
    for given, chosen in (("on", "stick-slip"), ("off", "held")):
        assert main(base + [str(tmp_path / f"{given}.json"), "--stick-slip", given]) == 0
        js = json.loads((tmp_path / f"{given}.json").read_text())
        assert js["findings"][0]["effect"] == "coulomb_friction"
        ss = js["settings"]["stick_slip"]
        assert ss == {**ss, "chosen": chosen, "rule": f"given ({given})",
                      "sticky_positions": ["q"]} and "validation" not in ss
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        main(base + [str(tmp_path / "x.json"), "--stick-slip", "sometimes"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == ("cdam residual: error: argument --stick-slip: invalid choice: "
                       "'sometimes' (choose from 'auto', 'on', 'off')")
