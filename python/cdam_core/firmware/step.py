"""The dynamic model kinds on the firmware (``arx``, ``hybrid``, ``greybox``): the numbers the
target's ``fw::StepModel`` (firmware_stubs/include/fw/step_model.hpp) runs, and the Python model
it is checked against.

What reaches the generated header is numbers only: sizes and orders, coefficients, the network's
weights and scalers, the grey-box parameters, its inverse inertia matrix, step and substeps, and
for each effect an integer code (:data:`EFFECT_CODES`) with its values. The declared model is a
code too (:data:`DECLARED_CODES`). Names, effect names, column names and any other text of the
file never do.

Grey-box: the firmware supports the declared models in :data:`DECLARED_CODES` with the effects in
:data:`EFFECT_CODES`; any other is refused with the model or effect named (which is safe: those
names were checked against the library's own on load, and go to the error message only).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cdam_core.base.orders import parse_orders
from cdam_core.evaluate.monitor import watched_channels
from cdam_core.firmware.numbers import c_array, c_float, c_int_array, finite32, theta_fnv1a

KIND_CODES = {"bp_network": 0, "arx": 1, "hybrid": 2, "greybox": 3, "quad_physics": 4,
              "quad_hybrid": 6}
DECLARED_CODES = {"rigid_axis": 0, "flexible_joint": 1, "quadrotor": 2, "aerial_manipulator": 3}
EFFECT_CODES = {"coulomb_friction": 1, "asymmetric_friction": 2, "external_force": 3,
                "actuator_delay": 4, "backlash": 5, "hardening_stiffness": 6, "payload_mass": 7,
                "ground_effect": 8, "thrust_loss": 9}
NETWORK_STEP_CODE = 5      # a bp_network one sample at a time (with its monitor): CDAM_MODEL_KIND
G0 = 9.81   # cdam_core.models.greybox.effects.G0 and flight.G0 (the firmware's kG0), tested
MAX_DELAY_ROWS = 1024      # input rows kept for an actuator delay (4 KB of RAM per input)
MAX_COEFS = 100_000        # ARX rows x outputs, network weights (above the M4F's flash)
MAX_SUBSTEPS = 1000        # grey-box substeps per sample on the target


@dataclass
class StepFirmwareModel:
    """A dynamic model as the firmware runs it (see the module doc)."""

    kind: str
    model: object              # the Python model (cdam_core.models), the reference
    inputs: list
    outputs: list
    history: int               # measured rows before the first prediction (t0)
    sha256: str
    source: str = ""
    ints: dict = field(default_factory=dict)        # constexpr int (and bool) constants
    floats: dict = field(default_factory=dict)      # constexpr float constants
    arrays: dict = field(default_factory=dict)      # float arrays, in the header's order
    int_arrays: dict = field(default_factory=dict)
    macros: dict = field(default_factory=dict)      # preprocessor selection (integers)
    hashed: tuple = ()         # arrays the firmware's FNV-1a covers, in order
    monitor: dict | None = None   # the model file's monitor section (fw/monitor.hpp), if any

    @property
    def n_inputs(self) -> int:
        return len(self.inputs)

    @property
    def n_outputs(self) -> int:
        return len(self.outputs)

    def params_fnv1a(self) -> int:
        return theta_fnv1a(np.concatenate([np.asarray(self.arrays[n], np.float64).ravel()
                                           for n in self.hashed]))

    def monitor_fnv1a(self) -> int:
        """FNV-1a of the monitor's numbers as the firmware hashes them (0 without a monitor)."""
        if self.monitor is None:
            return 0
        return theta_fnv1a(np.concatenate(
            [np.asarray(self.arrays[n], np.float64).ravel() for n in MONITOR_ARRAYS] +
            [np.asarray([self.floats["kMonK"], self.floats["kMonLambda"]])]))

    def predict(self, U, Y, mode: str, k: int = 1) -> np.ndarray:
        """The Python model's prediction (float64), rows t0.. (``one_step``, ``k_step`` with
        ``k`` or ``free_run``)."""
        return self.model.predict(U, Y, mode=mode, k=k)[self.history:]

    def describe(self) -> str:
        """One line without any name from the file."""
        i = self.ints
        if self.kind in ("arx", "hybrid"):
            net = (f" + {i['kNetInputs']}-{i['kNetHidden']}-{self.n_outputs} network"
                   if self.macros.get("CDAM_MODEL_HAS_NET") else "")
            feats = "physics" if i["kPhysics"] else "raw"
            return (f"{self.kind} ({i['kNa']}, {i['kNb']}, {i['kNk']}) on {feats} features, "
                    f"{self.n_inputs} in, {self.n_outputs} out{net}")
        if self.kind == "bp_network":
            return (f"bp_network {i['kNetInputs']}-{i['kNetHidden']}-{self.n_outputs}, NARX "
                    f"({i['kNa']}, {i['kNb']}, {i['kNk']}), one sample at a time")
        if self.kind == "quad_physics":
            return (f"quad_physics, 13 states, rates {'dynamic' if i['kRatesDynamic'] else 'held'}"
                    f", {i['kKernel']}-tap actuation lag, delays {i['kDelayTrans']}/"
                    f"{i['kDelayRot']} samples, one RK4 step per sample")
        if self.kind == "quad_hybrid":
            return (f"quad_hybrid, 13 states, physics prior "
                    f"{'dynamic' if i['kPriorDynamic'] else 'hold'} + {i['kNetInputs']}-"
                    f"{i['kNetHidden']}-3 tanh network on the rates ({i['kLags']} rotor lags), "
                    f"delays {i['kDelayTrans']}/{i['kDelayRot']} samples, one RK4 step per sample")
        arm = sum(int(q >= 0) for q in self.int_arrays.get("kArmEq", ()))
        return (f"greybox, {self.model.declared}, {i['kEffects']} effect(s)"
                + (f" + causal arm coupling on {arm} channel(s)" if arm else "")
                + f", {i['kSubsteps']} substep(s) per sample")

    def header(self) -> list[str]:
        """The header's lines after the common preamble (namespace cdam_model, numbers only)."""
        lines = [f"#define {k} {int(v)}" for k, v in self.macros.items()]
        lines += ["", "namespace cdam_model {", ""]
        for k, v in self.ints.items():
            lines.append(f"constexpr bool {k} = {'true' if v else 'false'};" if isinstance(v, bool)
                         else f"constexpr int {k} = {int(v)};")
        for k, v in self.floats.items():
            lines.append(f"constexpr float {k} = {c_float(v)};")
        lines.append(f'constexpr char kSourceSha256[] = "{self.sha256}";')
        lines.append(f"constexpr std::uint32_t kParamsFnv1a = 0x{self.params_fnv1a():08X}u;")
        if self.monitor is not None:
            lines.append(f"constexpr std::uint32_t kMonitorFnv1a = 0x{self.monitor_fnv1a():08X}u;")
        lines.append("")
        for k, v in self.arrays.items():
            lines.append(c_array(k, np.asarray(v, np.float64).ravel()))
        for k, v in self.int_arrays.items():
            lines.append(c_int_array(k, v))
        lines += ["}  // namespace cdam_model", ""]
        return lines


def step_model(mf, source: str = "") -> StepFirmwareModel:
    """The StepFirmwareModel of a read model file (``cdam_core.models.file.read_model_file``)."""
    if mf.kind in ("arx", "hybrid"):
        fm = _arx(mf)
    elif mf.kind == "greybox":
        fm = _greybox(mf)
    elif mf.kind == "quad_physics":
        fm = _quad_physics(mf)
    elif mf.kind == "quad_hybrid":
        fm = _quad_hybrid(mf)
    elif mf.kind == "bp_network":
        fm = _network(mf)
    else:
        raise ValueError(f"MODEL: a {mf.kind!r} model cannot run on the firmware")
    fm.source = str(source)
    _monitor(fm, mf)
    for name, values in fm.arrays.items():
        finite32(name, values)
    for name, value in fm.floats.items():
        finite32(name, [value])
    return fm


MONITOR_ARRAYS = ("kMonMean", "kMonStd", "kMonH", "kMonEwmaLimit", "kMonWatch")


def _monitor(fm: StepFirmwareModel, mf) -> None:
    """The residual monitor's numbers (fw/monitor.hpp) from the file's ``monitor`` section."""
    sec = getattr(mf, "monitor", None)
    fm.macros["CDAM_MODEL_HAS_MONITOR"] = int(sec is not None)
    if sec is None:
        return
    fm.monitor = sec
    fm.floats.update({"kMonK": float(sec["k"]), "kMonLambda": float(sec["lambda"])})
    for name, key in zip(MONITOR_ARRAYS, ("mean", "std", "h", "ewma_limit")):
        fm.arrays[name] = np.asarray(sec[key], np.float64)
    # 1 for a watched output, 0 for one that never alarms (evaluate.monitor: a unit
    # quaternion's largest component); all 1 for a section without the field
    fm.arrays["kMonWatch"] = watched_channels(sec).astype(np.float64)


def _arx(mf) -> StepFirmwareModel:
    m = mf.model
    na, nb, nk = (int(v) for v in m.narx)
    ny, nf = int(m.n_outputs_), int(m.n_features)
    coef = np.asarray(m.coef_, dtype=np.float64)
    if coef.shape != (na * ny + nb * nf + 1, ny) or coef.size > MAX_COEFS:
        raise ValueError(f"MODEL: model.coef: shape {coef.shape} does not fit the firmware")
    physics = m.features == "physics"
    fm = StepFirmwareModel(
        mf.kind, m, list(mf.inputs), list(mf.outputs), int(m.t0), mf.sha256,
        ints={"kKind": KIND_CODES[mf.kind], "kInputs": int(m.n_inputs_), "kOutputs": ny,
              "kHistory": int(m.t0), "kNa": na, "kNb": nb, "kNk": nk, "kFeatures": nf,
              "kPhysics": physics},
        macros={"CDAM_MODEL_KIND": KIND_CODES[mf.kind]}, hashed=("kCoef",))
    fm.arrays["kCoef"] = coef                       # row-major: rows x outputs
    fm.arrays["kFeatureScale"] = (np.asarray(m.feature_scale_, np.float64) if physics
                                  else np.ones(4))
    net = getattr(m, "net_", None) if mf.kind == "hybrid" else None
    has_net = net is not None and float(m.residual_weight_) != 0.0
    fm.macros["CDAM_MODEL_HAS_NET"] = int(has_net)
    if has_net:
        if net.activation not in ("tansig", "logsig"):
            raise ValueError(f"MODEL: model.network.activation {net.activation!r} is not supported")
        if np.asarray(net.theta_).size > MAX_COEFS:
            raise ValueError(f"MODEL: model.network: {np.asarray(net.theta_).size} weights do "
                             f"not fit the firmware (at most {MAX_COEFS})")
        fm.ints.update({"kNetInputs": int(net.n_inputs_), "kNetHidden": int(net.hidden_),
                        "kNetTansig": net.activation == "tansig"})
        fm.floats["kResidualWeight"] = float(m.residual_weight_)
        fm.arrays.update({"kNetTheta": net.theta_, "kNetXMin": net.scaler_x_.data_min_,
                          "kNetXMax": net.scaler_x_.data_max_,
                          "kNetYMin": net.scaler_y_.data_min_,
                          "kNetYMax": net.scaler_y_.data_max_})
        fm.hashed = ("kCoef", "kNetTheta")
    return fm


def _network(mf) -> StepFirmwareModel:
    """A bp_network one sample at a time (fw::StepModel of kind NETWORK_STEP_CODE): NARX
    orders (a static network: na 0, nb 1, nk 0), the weights, one pair of scaling numbers per
    regressor element (the output scaler's for past outputs, the input scaler's for inputs)."""
    net = mf.model
    if net.activation not in ("tansig", "logsig"):
        raise ValueError(f"MODEL: model.activation {net.activation!r} is not supported")
    na, nb, nk = (0, 1, 0) if net.narx is None else (int(v) for v in parse_orders(net.narx))
    ni, m, h = len(mf.inputs), int(net.n_outputs_), int(net.hidden_)
    theta = np.asarray(net.theta_, np.float64)
    n_in = na * m + nb * ni
    if theta.shape != (n_in * h + h + h * m + m,) or theta.size > MAX_COEFS:
        raise ValueError(f"MODEL: model.theta: {theta.size} weights do not fit a {n_in}-{h}-{m} "
                         f"network on the firmware (at most {MAX_COEFS})")
    xs, ys = net.scaler_x_, net.scaler_y_
    fm = StepFirmwareModel(
        mf.kind, net, list(mf.inputs), list(mf.outputs), int(net.t0), mf.sha256,
        ints={"kKind": NETWORK_STEP_CODE, "kInputs": ni, "kOutputs": m, "kHistory": int(net.t0),
              "kNa": na, "kNb": nb, "kNk": nk, "kNetInputs": n_in, "kNetHidden": h,
              "kNetTansig": net.activation == "tansig"},
        macros={"CDAM_MODEL_KIND": NETWORK_STEP_CODE, "CDAM_MODEL_STATIC": int(net.narx is None)},
        hashed=("kNetTheta",))
    fm.arrays.update({
        "kNetTheta": theta,
        "kNetXMin": np.concatenate([ys.data_min_] * na + [xs.data_min_] * nb),
        "kNetXMax": np.concatenate([ys.data_max_] * na + [xs.data_max_] * nb),
        "kNetYMin": ys.data_min_, "kNetYMax": ys.data_max_})
    return fm


def _greybox(mf) -> StepFirmwareModel:
    g = mf.model
    if g.declared not in DECLARED_CODES:
        raise ValueError(f"MODEL: a greybox model of {g.declared!r} cannot run on the firmware "
                         f"yet (it runs {', '.join(DECLARED_CODES)})")
    decl = g.declared_model                       # the declared model
    inertia = g.inertia                           # how the accelerations enter
    n, ni = len(decl.positions), len(decl.inputs)
    dt, sub = float(g.dt), int(g.substeps_)
    if not 1 <= sub <= MAX_SUBSTEPS:
        raise ValueError(f"MODEL: model.substeps: {sub} is outside 1..{MAX_SUBSTEPS} on the "
                         f"firmware")
    base = [g.theta_[p] for p in decl.parameter_names]
    codes, eqs, vels, index, lag, params = [], [], [], [], [], []
    delayed = set()
    equations = _equation_order(g)
    cables = list(getattr(decl, "cables", {}))     # aerial_manipulator: tau_l1, tau_l2
    arm = _arm_coupling(g)
    for j, e in enumerate(g.effects):
        if e.name == "arm_coupling":
            continue                          # its own arrays (_arm_coupling)
        if e.name not in EFFECT_CODES:
            raise ValueError(f"MODEL: model.effects[{j}]: effect {e.name!r} cannot run on the "
                             f"firmware yet (it runs {', '.join(EFFECT_CODES)})")
        key, th = e.key, g.theta_
        eq = equations.index(e.channel) if e.channel in equations else 0
        vel = (list(decl.positions).index(decl.viscous[e.channel][1][:-2])
               if e.channel in decl.viscous else 0)
        if e.name == "coulomb_friction":
            rows = [(0, 0, [th[f"{key}.Fc"], float(e.eps), 0.0, 0.0])]
        elif e.name == "asymmetric_friction":
            has_dfc = f"{key}.dFc" in th   # the column exists when no offset is estimated
            rows = [(0, 0, [th[f"{key}.dFv"], th[f"{key}.dFc"] if has_dfc else 0.0,
                            float(has_dfc), 0.0])]
        elif e.name == "external_force":
            col = ni + list(g.extra_columns).index(e.column)
            rows = [(col, 0, [th[f"{key}.gain"], 0.0, 0.0, 0.0])]
        elif e.name == "backlash":     # the cable (aerial_manipulator) as the index
            rows = [(_cable(g, cables, e), 0, [0.5 * float(e.width), 0.0, 0.0, 0.0])]
        elif e.name == "hardening_stiffness":
            rows = [(_cable(g, cables, e), 0, [th[f"{key}.K3"], 0.0, 0.0, 0.0])]
        elif e.name == "payload_mass" and g.declared == "flexible_joint":
            rows = [(0, 0, [th[f"{key}.m"], G0 * float(e.length), 0.0, 0.0])]
        elif e.name == "payload_mass":     # the flight models: a mass on Z
            rows = [(0, 0, [th[f"{key}.mass"], 0.0, 0.0, 0.0])]
        elif e.name == "ground_effect":
            rows = [(0, 0, [th[f"{key}.k"], float(e.rotor_radius), 0.0, 0.0])]
        elif e.name == "thrust_loss":
            rows = [(0, 0, [th[f"{key}.c"], 0.0, 0.0, 0.0])]
        else:   # actuator_delay: u(t - delay) by linear interpolation between two rows
            if float(e.delay) <= 0.0:
                continue                        # Python leaves the inputs as they are
            lags = float(e.delay) / dt
            L = int(np.ceil(lags))
            if L > MAX_DELAY_ROWS:
                raise ValueError(f"MODEL: model.effects[{j}].delay: {L} samples exceed the "
                                 f"firmware's {MAX_DELAY_ROWS}")
            rows = []
            for c in e.commands:
                cidx = list(decl.inputs).index(c)
                if cidx in delayed:
                    raise ValueError(f"MODEL: model.effects[{j}]: a second delay on one input")
                delayed.add(cidx)
                rows.append((cidx, L, [L * dt - float(e.delay), dt, 0.0, 0.0]))
        for col, L, p in rows:
            codes.append(EFFECT_CODES[e.name])
            eqs.append(eq)
            vels.append(vel)
            index.append(col)
            lag.append(L)
            params.append(p)
    E = len(codes)
    fm = StepFirmwareModel(
        "greybox", g, list(mf.inputs), list(mf.outputs), int(g.t0), mf.sha256,
        ints={"kKind": KIND_CODES["greybox"], "kInputs": int(g.n_inputs_), "kOutputs": n,
              "kHistory": int(g.t0), "kSubsteps": sub, "kEffects": E,
              "kDelayLag": max(lag, default=0)},
        floats={"kDt": dt, "kH": dt / sub},
        macros={"CDAM_MODEL_KIND": KIND_CODES["greybox"],
                "CDAM_MODEL_DECLARED": DECLARED_CODES[g.declared]},
        hashed=("kBase", "kInertia", "kEffectParam"))
    if g.declared == "aerial_manipulator":   # joint 1 below the body: the build's geometry
        fm.floats["kJointDepth"] = float(decl.joint_depth)
    fm.arrays = {"kBase": base, "kInertia": inertia,
                 # one row of four values per effect (a zero row when there is none)
                 "kEffectParam": np.asarray(params, np.float64).ravel() if E else np.zeros(4)}
    fm.macros["CDAM_MODEL_ARM"] = int(arm is not None)
    if arm is not None:
        eq_index, ncols, theta, sos = arm
        fm.ints["kArmSections"] = int(sos.shape[1])
        fm.arrays.update({"kArmTheta": theta, "kArmSos": sos})
        fm.hashed = fm.hashed + ("kArmTheta", "kArmSos")
    fm.int_arrays = {"kEffectCode": codes or [0], "kEffectEq": eqs or [0],
                     "kEffectVel": vels or [0], "kEffectIndex": index or [0],
                     "kEffectLag": lag or [0]}
    if arm is not None:
        fm.int_arrays.update({"kArmEq": arm[0], "kArmCols": arm[1]})
    return fm


ARM_CHANNELS = ("X", "Y", "Z", "tau_theta", "tau_phi")   # fw/arm_columns.hpp's order
ARM_COLS = 8                                             # columns per channel, at most


def _arm_coupling(g):
    """The arm_coupling effects of an aerial_manipulator as the firmware's arrays (equation
    index per channel, -1 without; columns per channel; theta (5 x 8, zero-padded); the
    Butterworth sections of the body and the joint bands (2, sections, 6: b0 b1 b2 1
    alpha1 alpha2, causal.arm_sections)), or None. Only
    causal columns run on the board: the zero-phase ones need the rows after t."""
    from cdam_core.models.greybox.causal import COLUMN_NAMES, arm_sections
    arm = [(j, e) for j, e in enumerate(g.effects) if e.name == "arm_coupling"]
    if not arm:
        return None
    for j, e in arm:
        if not e.causal:
            raise ValueError(f"MODEL: model.effects[{j}]: effect 'arm_coupling' cannot run on "
                             f"the firmware with zero-phase columns (they need the rows after "
                             f"t); refit it on causal columns (cdam residual ... --save FILE "
                             f"--firmware)")
    decl = g.declared_model
    equations = _equation_order(g)
    eq_index, ncols = [-1] * len(ARM_CHANNELS), [0] * len(ARM_CHANNELS)
    theta = np.zeros((len(ARM_CHANNELS), ARM_COLS))
    for j, e in arm:
        ch = ARM_CHANNELS.index(e.channel)
        names = COLUMN_NAMES[e.channel]
        eq_index[ch], ncols[ch] = equations.index(e.channel), len(names)
        theta[ch, :len(names)] = [g.theta_[f"{e.key}.{n}"] for n in names]
    filt = g._filter(decl)
    r = float(decl.derivative_ratio)
    sos = np.stack([arm_sections(filt.order, filt.cutoff_hz * r, g.dt),
                    arm_sections(filt.order, decl.joint_filter(filt).cutoff_hz * r, g.dt)])
    return eq_index, ncols, theta, sos



def _equation_order(g) -> list:
    """The equations in the order of the grey box's error vector (the rows of its inertia
    matrix's inverse): the declared model's equations dict at the zero state, which for
    aerial_manipulator is tau_m1, tau_m2, tau_l1, tau_l2 after the body's six, not
    ``equation_names``' order."""
    z, u, ex = g._zero_state(1)
    s = g._state(z, z, z, u, ex, np.zeros(1, dtype=int), np.zeros(1))
    return list(g.declared_model.equations(s))


def _cable(g, cables, e) -> int:
    """0 for the flexible joint's one cable; the cable's number for aerial_manipulator."""
    return cables.index(e.channel) if g.declared == "aerial_manipulator" else 0


# the quad_physics model section's fields this step knows (any other is refused by name)
QUAD_PHYSICS_FIELDS = {"dt", "rates", "drag", "gyro", "offsets", "damping", "reaction", "lag",
                       "delay", "max_delay", "gravity", "delays", "translation",
                       "translation_std", "rotation", "rotation_std", "start"}


def _quad_physics(mf) -> StepFirmwareModel:
    """The quad_physics flight model (fw/quad_physics_step.hpp): its translational and
    rotational parameters, the lag kernel's weights, delays, g, dt and two switches."""
    m = mf.model
    unknown = sorted(set(m.to_dict()) - QUAD_PHYSICS_FIELDS)
    if unknown:       # an option added to the model that this step would silently leave out
        raise ValueError(f"MODEL: model.{unknown[0]}: a quad_physics option the firmware "
                         f"does not run yet")
    if np.shape(m.trans_) != (3,) or np.shape(m.rot_) != (13,):
        raise ValueError("MODEL: model.translation, model.rotation: not the 3 and 13 "
                         "parameters the firmware runs")
    kernel = np.asarray(m._kernel(), np.float64)   # at most 500 taps (lag <= 100 dt)
    dT, dR = (int(d) for d in m.delays_)
    dt = float(m.dt)
    fm = StepFirmwareModel(
        "quad_physics", m, list(mf.inputs), list(mf.outputs), int(m.t0), mf.sha256,
        ints={"kKind": KIND_CODES["quad_physics"], "kInputs": 4, "kOutputs": 13,
              "kHistory": int(m.t0), "kKernel": int(kernel.size), "kDelayTrans": dT,
              "kDelayRot": dR, "kReaction": bool(m.reaction),
              "kRatesDynamic": m.rates == "dynamic"},
        floats={"kDt": dt, "kDt6": dt / 6.0, "kGravity": float(m.gravity)},
        macros={"CDAM_MODEL_KIND": KIND_CODES["quad_physics"]},
        hashed=("kTrans", "kRot", "kKernelW"))
    fm.arrays = {"kTrans": np.asarray(m.trans_, np.float64),
                 "kRot": np.asarray(m.rot_, np.float64), "kKernelW": kernel}
    return fm


# the quad_hybrid model section's fields this step knows (any other is refused by name)
QUAD_HYBRID_FIELDS = {"dt", "hidden", "horizon", "lags", "prior", "epochs", "stride", "seed",
                      "weighting", "physics", "theta", "in_mean", "in_scale", "out_scale",
                      "err_scale", "feature_scale"}
MAX_LAGS = 100            # rotor-speed lags of the network on the target (1 s at 100 Hz)


def _quad_hybrid(mf) -> StepFirmwareModel:
    """The quad_hybrid flight model (fw/quad_hybrid_step.hpp): the physics' translational
    parameters, lag kernel and delays, its rate increment's b and e, the network's weights and
    its scales. Training settings (horizon, epochs, stride, seed, weighting, err_scale) do not
    act on the prediction and stay out of the header."""
    m = mf.model
    p = m.physics_
    unknown = sorted(set(m.to_dict()) - QUAD_HYBRID_FIELDS) or \
        [f"physics.{k}" for k in sorted(set(p.to_dict()) - QUAD_PHYSICS_FIELDS)]
    if unknown:
        raise ValueError(f"MODEL: model.{unknown[0]}: a quad_hybrid option the firmware does "
                         f"not run yet")
    lags, H = int(m.lags), int(m.hidden)
    if not 1 <= lags <= MAX_LAGS:
        raise ValueError(f"MODEL: model.lags: {lags} is outside 1..{MAX_LAGS} on the firmware")
    theta = np.asarray(m.theta_, np.float64)
    n_in = 3 + 3 * lags
    if theta.shape != (n_in * H + H + 3 * H + 3,) or theta.size > MAX_COEFS:
        raise ValueError(f"MODEL: model.theta: {theta.size} weights do not fit a {n_in}-{H}-3 "
                         f"network on the firmware (at most {MAX_COEFS})")
    kernel = np.asarray(p._kernel(), np.float64)
    dT, dR = (int(d) for d in p.delays_)
    dt = float(m.dt)
    dynamic = m.prior == "dynamic"
    fm = StepFirmwareModel(
        "quad_hybrid", m, list(mf.inputs), list(mf.outputs), int(m.t0), mf.sha256,
        ints={"kKind": KIND_CODES["quad_hybrid"], "kInputs": 4, "kOutputs": 13,
              "kHistory": int(m.t0), "kKernel": int(kernel.size), "kDelayTrans": dT,
              "kDelayRot": dR, "kLags": lags, "kNetInputs": n_in, "kNetHidden": H,
              "kPriorDynamic": dynamic},
        floats={"kDt": dt, "kDt6": dt / 6.0, "kGravity": float(p.gravity)},
        macros={"CDAM_MODEL_KIND": KIND_CODES["quad_hybrid"]},
        hashed=("kTrans", "kKernelW", "kDrift", "kNetScale", "kNetTheta"))
    rot = np.asarray(p.rot_, np.float64)
    fm.arrays = {"kTrans": np.asarray(p.trans_, np.float64), "kKernelW": kernel,
                 # the physics' rate increment dt (b o tau + e): b, then e
                 "kDrift": np.r_[rot[0:3], rot[6:9]],
                 "kNetScale": np.r_[m.in_mean_, m.in_scale_, m.out_scale_, m.feature_scale_],
                 "kNetTheta": theta}
    return fm
