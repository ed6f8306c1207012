"""Mutation fuzz of the files users hand to `cdam` (issue 24 item 8): dataset CSVs and Parquet
files with their sidecars, model files of every kind, CAN logs (candump, BLF, ASC) and a PX4
ULog (the shared sample, when present), mutated byte- and line-wise with a seeded
generator, run through the command line in a child process. A finding is a crash (the child
dies), a traceback, an exception escaping `main`, or exit code 4 (internal error): every bad file
must end in a named error (exit 2 or 3) or a completed run (0, or 1 for a partial import).

CI runs a small budget per family; ``pytest -m fuzz tests/robust`` runs the long one (800 per
family) and prints the counts."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cdam_core.models import ArxModel, BPNetwork, HybridNarx, save_model
from cdam_core.models.greybox.augmented import GreyBox
from cdam_core.models.greybox.effects import CoulombFriction
from cdam_core.record.realdata import shared_data_dir

ALLOWED = {0, 1, 2, 3}
WORKER = Path(__file__).with_name("_fuzz_worker.py")


def _mutate(data: bytes, rng) -> bytes:
    """One of: flip bytes, truncate, delete a chunk, duplicate or drop a line, splice in
    hostile text (huge/NaN numbers, quotes, control characters, other encodings)."""
    b = bytearray(data)
    op = rng.integers(8)
    if op == 0 and b:
        for _ in range(int(rng.integers(1, 8))):
            b[int(rng.integers(len(b)))] = int(rng.integers(256))
    elif op == 1:
        b = b[:int(rng.integers(len(b) + 1))]
    elif op == 2 and b:
        a = int(rng.integers(len(b)))
        del b[a:a + int(rng.integers(1, 64))]
    elif op in (3, 4):
        lines = bytes(b).split(b"\n")
        k = int(rng.integers(len(lines)))
        if op == 3:
            lines.insert(k, lines[int(rng.integers(len(lines)))])
        else:
            del lines[k]
        b = bytearray(b"\n".join(lines))
    else:
        junk = [b"1e400", b"-1e308", b"nan", b"NaN", b"inf", b"\"", b"\x00", b"\xff\xfe",
                b"\n\n", b",,,,", b"{", b"]", b"9" * 40, b"-0", b"\xe2\x80\xae", b"#", b"t"]
        a = int(rng.integers(len(b) + 1))
        b[a:a + int(rng.integers(0, 6))] = junk[int(rng.integers(len(junk)))]
    return bytes(b)


def _seeds(folder: Path) -> dict:
    """Valid files of each family, and the command that reads them ({} = the file's path)."""
    rng = np.random.default_rng(0)
    n = 300
    t = np.arange(n) * 0.01
    u = rng.uniform(-1, 1, n)
    y = np.zeros(n)
    for k in range(1, n):
        y[k] = 0.9 * y[k - 1] + 0.5 * u[k - 1]
    data = folder / "data.csv"
    np.savetxt(data, np.column_stack([t, u, y]), delimiter=",", header="t,u,y", comments="",
               fmt="%.10g")
    (folder / "data.json").write_text(json.dumps(
        {"rate": 100.0, "inputs": ["u"], "outputs": ["y"], "units": {"u": "N", "y": "m"}}))
    U, Y = u[:, None], y[:, None]
    models = {}
    for name, m in (("arx", ArxModel((1, 1, 1))), ("bp", BPNetwork(hidden=3, epochs=3, seed=1)),
                    ("hybrid", HybridNarx((1, 1, 1), seed=1)),
                    ("greybox", GreyBox("rigid_axis", 0.01, [CoulombFriction("tau")], cutoff_hz=20.0))):
        path = folder / f"model_{name}.json"
        save_model(path, m.fit(U, Y), inputs=["u"], outputs=["y"])
        models[name] = path
    can_frames = [(1000 + k / 1000, 0x200 + m, bytes.fromhex(
        f"{(k * 37 % 8192):04X}{(k % 200):04X}{(k * 3 % 4000):04X}0000"))
        for k in range(400) for m in (1, 2)]
    can = folder / "can.log"
    with open(can, "w") as f:
        for tf, i, b in can_frames:
            f.write(f"({tf:.6f}) can0 {i:03X}#{b.hex().upper()}\n")
    import can as pycan
    for suffix, writer in ((".blf", pycan.BLFWriter), (".asc", pycan.ASCWriter)):
        w = writer(str(folder / f"can{suffix}"))
        if suffix == ".blf":
            w.max_container_size = 48 * 100         # 100 frames per zlib container
        for tf, i, b in can_frames:
            w.on_message_received(pycan.Message(timestamp=tf, arbitration_id=i,
                                                is_extended_id=False, data=b))
        w.stop()
    import pandas as pd
    pd.DataFrame({"t": t, "u": u, "y": y}).to_parquet(folder / "data.parquet")
    ulog = shared_data_dir() / "ulog" / "sample_appended_multiple.ulg"
    return {
        "csv": (data.read_bytes(), ["evaluate", str(models["arx"]), "{}", "--horizon", "3",
                                    "--quiet"], ".csv", (folder / "data.json").read_bytes()),
        "sidecar": ((folder / "data.json").read_bytes(),
                    ["evaluate", str(models["arx"]), "{csv}", "--horizon", "2", "--quiet"],
                    ".json", data.read_bytes()),
        **{f"model_{k}": (p.read_bytes(), ["evaluate", "{}", str(data), "--horizon", "2",
                                           "--quiet"], ".json", None)
           for k, p in models.items()},
        "parquet": ((folder / "data.parquet").read_bytes(),
                    ["evaluate", str(models["arx"]), "{}", "--horizon", "3", "--quiet"],
                    ".parquet", (folder / "data.json").read_bytes()),
        "can_log": (can.read_bytes(), ["import-can", "{}", "-o", "{out}"], ".log", None),
        **{f"can_{x}": ((folder / f"can.{x}").read_bytes(),
                        ["import-can", "{}", "-o", "{out}"], f".{x}", None)
           for x in ("blf", "asc")},
        **({"ulog": (ulog.read_bytes(), ["import-ulog", "{}", "-o", "{out}", "--rate", "50"],
                     ".ulg", None)} if ulog.is_file() else {}),
    }


def _cases(folder: Path, per_family: int, seed: int) -> list:
    cases, meta = [], []
    for fam, (good, argv, suffix, partner) in _seeds(folder).items():
        rng = np.random.default_rng([seed, sum(fam.encode())])
        for j in range(per_family):
            d = folder / f"{fam}_{j}"
            d.mkdir()
            if fam == "sidecar":       # a good CSV beside a mutated sidecar
                target = d / "rec.json"
                (d / "rec.csv").write_bytes(partner)
            else:
                target = d / f"in{suffix}"
                if partner is not None:
                    (d / "in.json").write_bytes(partner)
            target.write_bytes(_mutate(good, rng) if j else good)   # case 0: the valid file
            cases.append([a.replace("{}", str(target)).replace("{out}", str(d / "out.csv"))
                          .replace("{csv}", str(d / "rec.csv")) for a in argv])
            meta.append((fam, j))
    return cases, meta


def _run(folder: Path, cases: list) -> list:
    """Run every case in a child; restart after a crash. Returns per-case results."""
    spec = folder / "cases.json"
    spec.write_text(json.dumps(cases))
    results, first = {}, 0
    env = dict(os.environ)
    while first < len(cases):
        r = subprocess.run([sys.executable, str(WORKER), str(spec), str(first)],
                           capture_output=True, text=True, env=env, timeout=3600,
                           cwd=str(folder))
        started = None
        for line in r.stdout.splitlines():
            if line.startswith("start "):
                started = int(line.split()[1])
            elif line.startswith("{"):
                d = json.loads(line)
                results[d["i"]] = d
        if r.returncode == 0:
            break
        if started is None or started in results:   # died outside a case
            raise RuntimeError(f"fuzz worker failed: {r.stderr[-2000:]}")
        results[started] = {"i": started, "rc": f"crash {r.returncode}", "traceback": True,
                            "stderr": r.stderr[-300:]}
        first = started + 1
    return [results[i] for i in range(len(cases))]


def _findings(results, meta) -> list:
    return [(meta[r["i"]], r["rc"], r["stderr"]) for r in results
            if r["rc"] not in ALLOWED or r["traceback"]]


def _check(tmp_path, per_family, seed):
    cases, meta = _cases(tmp_path, per_family, seed)
    results = _run(tmp_path, cases)
    valid = [r for r, (fam, j) in zip(results, meta) if j == 0]
    assert all(r["rc"] == 0 for r in valid), [r for r in valid if r["rc"] != 0]
    bad = _findings(results, meta)
    counts = {}
    for r, (fam, _) in zip(results, meta):
        counts.setdefault(fam, {}).setdefault(str(r["rc"]), 0)
        counts[fam][str(r["rc"])] += 1
    print(json.dumps({"files": len(cases), "findings": len(bad), "exit_codes": counts}))
    assert not bad, bad[:5]


def test_mutated_files_end_in_named_errors(tmp_path):
    _check(tmp_path, per_family=20, seed=1)


@pytest.mark.fuzz
def test_mutated_files_long(tmp_path):
    _check(tmp_path, per_family=int(os.environ.get("CDAM_FUZZ_FILES", "800")), seed=2)
