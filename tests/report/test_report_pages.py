"""Every report is a page that opens in a browser (issue 22 item 6): each command's --report
HTML is loaded by headless Chromium, which takes a screenshot (not blank) and reports every
image that did not load (none may be missing); every figure has a caption under it, and the
tables give units (the record's, from its sidecar) and standard deviations."""
import json
import re
import sys
from pathlib import Path

import numpy as np

from cdam_core.cli.main import main

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _browser import browser, captions_follow_figures, open_page  # noqa: E402


def _check(page: Path, shots: Path) -> dict:
    browser()                                            # skips, naming the set-up, if absent
    html = page.read_text()
    res = open_page(page, shots / f"{page.parent.name}.png")
    assert res["missing"] == [], res
    assert res["images"] == html.count("<img")
    assert res["shot"][:2] == (1400, 1100) and res["shot_std"] > 0.01      # drawn (a blank page: 0)
    assert captions_follow_figures(html)
    return res


def test_residual_report_page_with_units_and_sigmas(tmp_path, bundled_record):
    from cdam_core.record.realdata.emps import load_emps
    d = load_emps(path=bundled_record("emps/DATA_EMPS.mat"))
    rows = np.column_stack([d["t"], d["force"], d["qm"]])
    np.savetxt(tmp_path / "emps.csv", rows, delimiter=",", header="t,force,qm", comments="",
               fmt="%.10g")
    (tmp_path / "emps.json").write_text(json.dumps(
        {"inputs": ["force"], "outputs": ["qm"], "units": {"force": "N", "qm": "m"}}))
    assert main(["residual", str(tmp_path / "emps.csv"), "--model", "rigid_axis", "--map",
                 "tau=force,q=qm", "--no-free-run", "--quiet", "--json", str(tmp_path / "r.json"),
                 "--report", str(tmp_path / "rep")]) == 0
    js = json.loads((tmp_path / "r.json").read_text())
    res = _check(tmp_path / "rep" / "index.html", tmp_path)
    assert res["images"] == len(js["findings"]) + 1           # one per finding, the spectrum
    md = (tmp_path / "rep" / "index.md").read_text()
    # units from the sidecar: force N, position m -> M in kg, Fv in N s/m; sigma beside each
    head = "| parameter | value | standard deviation | relative sigma [%] | unit |"
    assert md.count(head) == 2                                 # declared and final tables
    rows = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[2:-1]]
            for ln in md.splitlines() if ln.startswith("| ") and ln.count("|") == 6}
    assert rows["M"][3] == "kg" and rows["Fv"][3] == "N s/m" and rows["offset"][3] == "N"
    assert float(rows["M"][1]) > 0 and rows["coulomb_friction@tau.Fc"][3] == "N"
    # the residual's periodic lines (50 Hz mains on DATA_EMPS): amplitudes in the force's unit
    lines = [ln for ln in md.splitlines() if ln.startswith("| tau | periodic_line |")]
    assert lines and all(re.search(r"\| amplitude [-0-9.e]+ N \(x", ln) for ln in lines), lines
    # each finding's held-out decision, as the JSON has it
    held = [ln for ln in md.splitlines() if ln.startswith("Held out: ")]
    assert len(held) == len(js["findings"]) and js["findings"]
    for ln, f in zip(held, js["findings"]):
        v = f["evidence"]["validation"]
        assert f"p {v['p_value']:.2g} at level {v['level']:.2g}" in ln, (ln, v)


def _small_record(d: Path):
    t = np.arange(600) / 100.0
    u = np.sin(1.3 * t) + 0.5 * np.sin(3.1 * t)
    y = np.zeros_like(u)
    for k in range(2, t.size):                    # a stable second-order system
        y[k] = 1.5 * y[k - 1] - 0.6 * y[k - 2] + 0.1 * u[k - 1]
    (d / "small.csv").write_text("t,u,y\n" + "".join(
        f"{a!r},{b!r},{c!r}\n" for a, b, c in zip(t.tolist(), u.tolist(), y.tolist())))
    (d / "small.json").write_text('{"inputs": ["u"], "outputs": ["y"], "units": {"y": "m"}}')


def test_identify_and_evaluate_report_pages(tmp_path):
    _small_record(tmp_path)
    assert main(["identify", str(tmp_path / "small.csv"), "--algo", "bp", "--epochs", "5",
                 "--hidden", "3", "--narx", "2,2,1", "--smoothing", "0", "--quiet",
                 "--report", str(tmp_path / "id"), "--save", str(tmp_path / "m.json")]) == 0
    res = _check(tmp_path / "id" / "report.html", tmp_path)
    html = (tmp_path / "id" / "report.html").read_text()
    assert "predicted_test.png" in html and "residual_test.png" in html and res["images"] >= 3
    assert main(["evaluate", str(tmp_path / "m.json"), str(tmp_path / "small.csv"),
                 "--horizon", "5", "--quiet", "--report", str(tmp_path / "ev")]) == 0
    res = _check(tmp_path / "ev" / "index.html", tmp_path)
    assert res["images"] >= 1


def test_summary_report_page(tmp_path):
    from cdam_core.report.summary import write_summary_report
    write_summary_report(tmp_path / "sum", "A summary", ["a line", "another"], {"x": 1.0},
                         source="here")
    res = _check(tmp_path / "sum" / "index.html", tmp_path)
    assert res["images"] == 0


def test_monitor_report_page(tmp_path):
    """`cdam monitor --report`: the page opens with its figure captioned; the table's alarm
    count and first alarm per output are those of --json, the residual statistics carry the
    output's unit (the sidecar's)."""
    _small_record(tmp_path)
    rec = tmp_path / "small.csv"
    assert main(["identify", str(rec), "--algo", "bp", "--epochs", "5", "--hidden", "3",
                 "--narx", "2,2,1", "--smoothing", "0", "--quiet",
                 "--save", str(tmp_path / "m.json")]) == 0
    assert main(["monitor", str(tmp_path / "m.json"), str(rec), "--paths", "100", "--quiet",
                 "--calibrate", str(tmp_path / "mm.json")]) == 0
    assert main(["monitor", str(tmp_path / "mm.json"), str(rec), "--calibrate",
                 str(tmp_path / "x.json"), "--report", str(tmp_path / "no")]) == 2
    assert main(["monitor", str(tmp_path / "mm.json"), str(rec), "--quiet", "--json",
                 str(tmp_path / "a.json"), "--report", str(tmp_path / "mon")]) == 0
    js = json.loads((tmp_path / "a.json").read_text())
    res = _check(tmp_path / "mon" / "index.html", tmp_path)
    assert res["images"] == 1
    md = (tmp_path / "mon" / "index.md").read_text()
    row = next(ln for ln in md.splitlines() if ln.startswith("| y |")).split("|")
    sec = json.loads((tmp_path / "mm.json").read_text())["monitor"]
    assert row[3].strip() == f"{sec['std'][0]:.4g} m"
    alarms = [a["t"] for a in js["alarms"]]
    assert int(row[6]) == len(alarms) == js["alarm_count"]["y"]
    assert row[7].strip() == (f"{alarms[0]:.4f}" if alarms else "-")
