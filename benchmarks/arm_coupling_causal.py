"""Could the board compute the `arm_coupling` columns sample by sample? A measurement, not a
benchmark: `python benchmarks/arm_coupling_causal.py`.

(Answered since: the board runs the causal form of cdam_core.models.greybox.causal, filtered
increments as jets, and a model meant for it is refitted on those columns, `cdam residual
--save FILE --firmware`; the comparison below is of the plain forward filter and backward
differences, a close relative of that form (which takes the sines and cosines at the measured
angle and the filtered increments around it), with the zero-phase fit's parameters: why the
refit is needed.)

The columns (cdam_core.models.greybox.effects.ArmCoupling.columns) are built from the prepared
signals: a zero-phase Butterworth low-pass (scipy's sosfiltfilt: a forward and a backward pass
over the whole record) and central differences (numpy.gradient: row t + 1 is needed), twice
for the force columns. Their causal counterpart, computable on the board row by row, is the
same Butterworth run forward only (started at rest on the first value) with backward
differences. On a simulated flight (`simulate_flight('both', 10 s, seed 3)`, 1 kHz) this prints
each column's RMS difference between the two over its own RMS (edges of 1 s left out), and the
aerial_manipulator grey-box model's one-step and 100-step RMS errors per output without the
effect, with the zero-phase columns and with the causal ones (the same fitted parameters).
"""
import numpy as np
import scipy.signal as sps

from cdam_core.models.greybox import declared as decl, effects as eff
from cdam_core.models.greybox.augmented import GreyBox
from cdam_core.models.greybox.registry import get_model
from cdam_core.sim import simulate_flight
from cdam_core.sim.parameters import plant_dict, plant_vector, total_mass


def _causal_apply(self, x, dt):
    sos = sps.butter(int(self.order), self.cutoff_hz, fs=1.0 / dt, output="sos")
    xf, _ = sps.sosfilt(sos, x, zi=sps.sosfilt_zi(sos) * x[0])
    xd = np.r_[0.0, np.diff(xf)] / dt
    return xf, xd, np.r_[0.0, np.diff(xd)] / dt


def _causal_d(x, dt):
    return np.r_[0.0, np.diff(np.asarray(x, float))] / dt


def main():
    ds = simulate_flight("both", duration=10.0, seed=3, declare=["arm_coupling"])
    m = get_model("aerial_manipulator")
    U = np.column_stack([ds.column(k) for k in m.inputs])
    Y = np.column_stack([ds.column(k) for k in m.positions])
    dt = float(np.median(np.diff(ds.t)))
    fixed = {"m": total_mass(plant_dict(plant_vector()), with_payload=False)}
    arm = [eff.ArmCoupling(c) for c in ("X", "Y", "Z", "tau_phi", "tau_theta")]
    without = GreyBox("aerial_manipulator", dt, effects=(), fixed=fixed).fit(U, Y)
    with_arm = GreyBox("aerial_manipulator", dt, effects=arm, fixed=fixed).fit(U, Y)
    zero = with_arm._precomputed(U, Y)
    saved = decl.DerivativeFilter.apply, eff._d
    decl.DerivativeFilter.apply, eff._d = _causal_apply, _causal_d
    try:
        causal = with_arm._precomputed(U, Y)
    finally:
        decl.DerivativeFilter.apply, eff._d = saved
    inner = slice(int(1 / dt), len(U) - int(1 / dt))
    for key, cols in zero.items():
        rel = [np.sqrt(np.mean((causal[key][n][inner] - c[inner]) ** 2) / np.mean(c[inner] ** 2))
               for n, c in cols.items()]
        print(f"{key}: causal - zero-phase, RMS over the column's RMS:", np.round(rel, 2))
    print("outputs:", ", ".join(m.positions))
    for name, g, pre in (("without arm_coupling", without, None),
                         ("arm_coupling, zero-phase columns", with_arm, zero),
                         ("arm_coupling, causal columns", with_arm, causal)):
        if pre is not None:
            g._precomputed = lambda U_, Y_, pre=pre: pre
        one = g.predict(U, Y, mode="one_step")
        k100 = g.predict(U, Y, mode="k_step", k=100)
        print(f"{name}: one-step RMS", np.array2string(
            np.sqrt(np.mean((one[2:] - Y[2:]) ** 2, axis=0)), precision=4))
        print(f"{' ' * len(name)}  100-step RMS", np.array2string(
            np.sqrt(np.mean((k100[200:] - Y[200:]) ** 2, axis=0)), precision=4))


if __name__ == "__main__":
    main()
