"""
cdam_core._core: the C++/Eigen core (private; use the cdam_core package)
"""
from __future__ import annotations
import numpy
import numpy.typing
import typing
__all__: list[str] = ['GREYBOX_STICK_SLIP', 'GREYBOX_TAPE_OPS', 'Rng', 'SIM_CONTROL_SIZE', 'SIM_NLOG', 'SIM_NSP', 'SIM_NU', 'SIM_NX', 'SIM_PLANT_SIZE', 'bp_fitness', 'cancel_native_loops', 'five_point_cubic_smooth', 'greybox_rollout', 'kstep_jacobian', 'kstep_normal', 'kstep_num_params', 'kstep_train_lm', 'minmax_apply', 'minmax_fit', 'mlp_forward', 'mlp_jacobian', 'mlp_jtj', 'mlp_mse_gradient', 'mlp_num_params', 'narx_regressors', 'narx_simulate', 'optimise', 'sim_closed_loop', 'sim_fastest_rate', 'sim_open_loop', 'sim_rhs', 'sim_substeps', 'train_gd', 'train_lm']
class Rng:
    """
    xoshiro128** with splitmix32 seeding; the numpy twin draws the same stream.
    """
    def __init__(self, seed: typing.SupportsInt | typing.SupportsIndex = 0) -> None:
        ...
    def index(self, n: typing.SupportsInt | typing.SupportsIndex) -> int:
        ...
    def next_u32(self) -> int:
        ...
    def normal(self) -> float:
        ...
    def uniform(self, a: typing.SupportsFloat | typing.SupportsIndex = 0.0, b: typing.SupportsFloat | typing.SupportsIndex = 1.0) -> float:
        ...
    def uniform_array(self, n: typing.SupportsInt | typing.SupportsIndex, a: typing.SupportsFloat | typing.SupportsIndex = 0.0, b: typing.SupportsFloat | typing.SupportsIndex = 1.0) -> numpy.typing.NDArray[numpy.float64]:
        ...
def bp_fitness(thetas: numpy.ndarray, X: numpy.ndarray, T: numpy.ndarray, hidden: typing.SupportsInt | typing.SupportsIndex, activation: str = 'tansig', threads: typing.SupportsInt | typing.SupportsIndex = 2, precision: str = 'float64') -> numpy.ndarray:
    """
    Training MSE sum((T - Y)^2) / (N m) of each theta (rows of a (n, D) array, or one (D,)); deterministic for any thread count. precision 'float32': computed in float (agrees to float rounding).
    """
def cancel_native_loops(cancel: bool = True) -> None:
    """
    Ask every native loop running in any thread to stop at its next poll (they end with RuntimeError: cancelled), or, with cancel=False, withdraw the request. For a program that is shutting down worker threads (cdam batch on Ctrl-C).
    """
def five_point_cubic_smooth(y: numpy.ndarray, passes: typing.SupportsInt | typing.SupportsIndex = 1) -> numpy.ndarray:
    """
    Five-point cubic smoothing, `passes` times, per column of a (N,) or (N, C) array.
    """
def greybox_rollout(op: typing.Annotated[numpy.typing.ArrayLike, numpy.int32], a: typing.Annotated[numpy.typing.ArrayLike, numpy.int32], b: typing.Annotated[numpy.typing.ArrayLike, numpy.int32], c: typing.Annotated[numpy.typing.ArrayLike, numpy.float64], outputs: typing.Annotated[numpy.typing.ArrayLike, numpy.int32], series: typing.Annotated[numpy.typing.ArrayLike, numpy.float64], theta: typing.Annotated[numpy.typing.ArrayLike, numpy.float64], inverse: typing.Annotated[numpy.typing.ArrayLike, numpy.float64], x0: typing.Annotated[numpy.typing.ArrayLike, numpy.float64], v0: typing.Annotated[numpy.typing.ArrayLike, numpy.float64], starts: typing.Annotated[numpy.typing.ArrayLike, numpy.int64], steps: typing.SupportsInt | typing.SupportsIndex, substeps: typing.SupportsInt | typing.SupportsIndex, rk4: bool, dt: typing.SupportsFloat | typing.SupportsIndex, t_start: typing.SupportsFloat | typing.SupportsIndex, path: bool, sticky: typing.Annotated[numpy.typing.ArrayLike, numpy.int32] = ...) -> tuple[numpy.typing.NDArray[numpy.float64], int]:
    """
    Integrate a grey-box model given as a tape (models/greybox/trace.py) over every lane (rk4: the switching nodes, sign and comparisons, held over each step's stages; the coordinates flagged in `sticky` stick and slip, models/greybox/stickslip.py); returns (positions, diverged row or -1): (steps, lanes, positions) with path, else (lanes, positions).
    """
def kstep_jacobian(theta: numpy.ndarray, S: numpy.ndarray, E: numpy.ndarray, D: numpy.ndarray, starts: numpy.ndarray, K: typing.SupportsInt | typing.SupportsIndex, hidden: typing.SupportsInt | typing.SupportsIndex, in_mean: numpy.ndarray, in_scale: numpy.ndarray, out_scale: numpy.ndarray, err_scale: numpy.ndarray, step_weight: typing.Any = None, lin: typing.Any = None) -> tuple[numpy.typing.NDArray[numpy.float64], numpy.typing.NDArray[numpy.float64]]:
    """
    (e, J) of the K-step windows: e (W K ns) the scaled errors, row (w K + j) ns + i for step j + 1 of window w, times step_weight[j] (K weights; None: 1); J (W K ns, D) = d y_hat / d theta step_weight / err_scale by forward sensitivities (cdam/host/kstep.hpp). lin (ns, na ns): the linear part L (None: none), s_{t+1} = s_t + D_t + r o + sum_l L_l s_{t-l}; starts then need na - 1 earlier rows. err_scale (ns) or (K, ns): one scale per step and state (then no step_weight).
    """
def kstep_normal(theta: numpy.ndarray, S: numpy.ndarray, E: numpy.ndarray, D: numpy.ndarray, starts: numpy.ndarray, K: typing.SupportsInt | typing.SupportsIndex, hidden: typing.SupportsInt | typing.SupportsIndex, in_mean: numpy.ndarray, in_scale: numpy.ndarray, out_scale: numpy.ndarray, err_scale: numpy.ndarray, step_weight: typing.Any = None, threads: typing.SupportsInt | typing.SupportsIndex = 1, lin: typing.Any = None) -> tuple[numpy.typing.NDArray[numpy.float64], numpy.typing.NDArray[numpy.float64], float]:
    """
    (J'J, J'e, sse) over the K-step windows, without forming J; bit-identical for any thread count.
    """
def kstep_num_params(states: typing.SupportsInt | typing.SupportsIndex, exogenous: typing.SupportsInt | typing.SupportsIndex, hidden: typing.SupportsInt | typing.SupportsIndex) -> int:
    ...
def kstep_train_lm(theta0: numpy.ndarray, S: numpy.ndarray, E: numpy.ndarray, D: numpy.ndarray, starts: numpy.ndarray, K: typing.SupportsInt | typing.SupportsIndex, hidden: typing.SupportsInt | typing.SupportsIndex, in_mean: numpy.ndarray, in_scale: numpy.ndarray, out_scale: numpy.ndarray, err_scale: numpy.ndarray, *, epochs: typing.SupportsInt | typing.SupportsIndex = 100, mu: typing.SupportsFloat | typing.SupportsIndex = 0.001, mu_dec: typing.SupportsFloat | typing.SupportsIndex = 0.1, mu_inc: typing.SupportsFloat | typing.SupportsIndex = 10.0, mu_max: typing.SupportsFloat | typing.SupportsIndex = 10000000000.0, min_grad: typing.SupportsFloat | typing.SupportsIndex = 1e-07, max_fail: typing.SupportsInt | typing.SupportsIndex = 6, val: typing.Any = None, step_weight: typing.Any = None, threads: typing.SupportsInt | typing.SupportsIndex = 2, lin: typing.Any = None) -> tuple[numpy.typing.NDArray[numpy.float64], dict]:
    """
    Levenberg-Marquardt (trainlm's semantics, levenberg_marquardt.hpp) on the K-step error of the windows; val = (S, E, D, starts) validation windows (best-validation weights returned, max_fail). Returns (theta, history). Bit-identical for any thread count.
    """
def minmax_apply(X: numpy.ndarray, data_min: numpy.ndarray, data_max: numpy.ndarray, inverse: bool = False) -> numpy.ndarray:
    """
    Scale to [-1, 1] (or back with inverse=True); constant columns map to 0.
    """
def minmax_fit(X: numpy.ndarray) -> tuple:
    """
    Per-column (min, max) of a (N, C) array.
    """
def mlp_forward(theta: numpy.ndarray, X: numpy.ndarray, hidden: typing.SupportsInt | typing.SupportsIndex, outputs: typing.SupportsInt | typing.SupportsIndex, activation: str = 'tansig') -> numpy.ndarray:
    """
    Network outputs (N, m) for inputs X (N, i); theta = [W1(:); b1; W2(:); b2].
    """
def mlp_jacobian(theta: numpy.ndarray, X: numpy.ndarray, hidden: typing.SupportsInt | typing.SupportsIndex, outputs: typing.SupportsInt | typing.SupportsIndex, activation: str = 'tansig') -> numpy.ndarray:
    """
    Jacobian (N m, D) of the outputs; row n m + k is d Y[n, k] / d theta.
    """
def mlp_jtj(theta: numpy.ndarray, X: numpy.ndarray, T: numpy.ndarray, hidden: typing.SupportsInt | typing.SupportsIndex, activation: str = 'tansig', threads: typing.SupportsInt | typing.SupportsIndex = 1) -> tuple:
    """
    (J'J, J'e, sse) accumulated in blocks without forming J; e = T - Y. Bit-identical for any thread count.
    """
def mlp_mse_gradient(theta: numpy.ndarray, X: numpy.ndarray, T: numpy.ndarray, hidden: typing.SupportsInt | typing.SupportsIndex, activation: str = 'tansig') -> tuple:
    """
    (mse, d mse / d theta) by backpropagation; mse = sum((T - Y)^2) / (N m).
    """
def mlp_num_params(inputs: typing.SupportsInt | typing.SupportsIndex, hidden: typing.SupportsInt | typing.SupportsIndex, outputs: typing.SupportsInt | typing.SupportsIndex) -> int:
    ...
def narx_regressors(U: numpy.ndarray, Y: numpy.ndarray, na: typing.SupportsInt | typing.SupportsIndex, nb: typing.SupportsInt | typing.SupportsIndex, nk: typing.SupportsInt | typing.SupportsIndex) -> numpy.ndarray:
    """
    Lagged regressors (N - t0, na m + nb i): [y(t-1..t-na), u(t-nk..t-nk-nb+1)], channels fastest.
    """
def narx_simulate(theta: numpy.ndarray, U: numpy.ndarray, Y0: numpy.ndarray, hidden: typing.SupportsInt | typing.SupportsIndex, activation: str, na: typing.SupportsInt | typing.SupportsIndex, nb: typing.SupportsInt | typing.SupportsIndex, nk: typing.SupportsInt | typing.SupportsIndex) -> numpy.ndarray:
    """
    Free-run simulation (N, m): Y0 holds the first t0 outputs; predictions are fed back.
    """
def optimise(algorithm: str, objective: str = 'bp', *, X: typing.Any = None, T: typing.Any = None, hidden: typing.SupportsInt | typing.SupportsIndex = 1, activation: str = 'tansig', dim: typing.SupportsInt | typing.SupportsIndex = 1, seed: typing.SupportsInt | typing.SupportsIndex = 0, options: typing.Any = None, threads: typing.SupportsInt | typing.SupportsIndex = 2, precision: str = 'float64') -> dict:
    """
    Run BOA, IBOA or CABC (algorithm 'boa'|'iboa'|'cabc') on the BP fitness (training MSE of the network given by the individual on X (N, i), T (N, m)) or a test function ('sphere', 'rastrigin' of `dim` variables). Returns a dict: best, best_fitness, curve (iterations + 1), evaluations, positions (n, D), fitness (n). precision 'float32': the BP fitness in float (8/16-lane kernel; the swarm itself stays double).
    """
def sim_closed_loop(plant: numpy.ndarray, control: numpy.ndarray, x0: numpy.ndarray, setpoints: numpy.ndarray, dt: typing.SupportsFloat | typing.SupportsIndex, substeps: typing.SupportsInt | typing.SupportsIndex) -> tuple[numpy.typing.NDArray[numpy.float64], numpy.typing.NDArray[numpy.float64]]:
    """
    Closed-loop flight: (states (N, 21), log (N, 10)) for setpoints (N, 8).
    """
def sim_fastest_rate(plant: numpy.ndarray) -> float:
    """
    Fastest motor-side mode bound (rad/s) used for the RK4 sub-step rule.
    """
def sim_open_loop(plant: numpy.ndarray, x0: numpy.ndarray, U: numpy.ndarray, dt: typing.SupportsFloat | typing.SupportsIndex, substeps: typing.SupportsInt | typing.SupportsIndex) -> numpy.typing.NDArray[numpy.float64]:
    """
    States (N+1, 21) under inputs U (N, 6) held for dt each.
    """
def sim_rhs(plant: numpy.ndarray, t: typing.SupportsFloat | typing.SupportsIndex, x: numpy.ndarray, u: numpy.ndarray) -> numpy.typing.NDArray[numpy.float64]:
    """
    dx/dt of the coupled aerial manipulator (state 21, input 6: rotor speeds, motor torques).
    """
def sim_substeps(plant: numpy.ndarray, dt: typing.SupportsFloat | typing.SupportsIndex) -> int:
    """
    RK4 sub-steps per dt so that h * fastest_rate <= 2.5.
    """
def train_gd(theta0: numpy.ndarray, X: numpy.ndarray, T: numpy.ndarray, hidden: typing.SupportsInt | typing.SupportsIndex, activation: str = 'tansig', *, lr: typing.SupportsFloat | typing.SupportsIndex = 0.01, epochs: typing.SupportsInt | typing.SupportsIndex = 1000, goal: typing.SupportsFloat | typing.SupportsIndex = 0.0, threads: typing.SupportsInt | typing.SupportsIndex = 2, callback: typing.Any = None) -> tuple:
    """
    Plain batch gradient-descent BP on the MSE; returns (theta, history). Bit-identical for any thread count.
    """
def train_lm(theta0: numpy.ndarray, X: numpy.ndarray, T: numpy.ndarray, hidden: typing.SupportsInt | typing.SupportsIndex, activation: str = 'tansig', *, epochs: typing.SupportsInt | typing.SupportsIndex = 1000, goal: typing.SupportsFloat | typing.SupportsIndex = 0.0, mu: typing.SupportsFloat | typing.SupportsIndex = 0.001, mu_dec: typing.SupportsFloat | typing.SupportsIndex = 0.1, mu_inc: typing.SupportsFloat | typing.SupportsIndex = 10.0, mu_max: typing.SupportsFloat | typing.SupportsIndex = 10000000000.0, min_grad: typing.SupportsFloat | typing.SupportsIndex = 1e-07, max_fail: typing.SupportsInt | typing.SupportsIndex = 6, X_val: typing.Any = None, T_val: typing.Any = None, threads: typing.SupportsInt | typing.SupportsIndex = 2, callback: typing.Any = None) -> tuple:
    """
    Levenberg-Marquardt with trainlm's semantics; returns (theta, history). Bit-identical for any thread count.
    """
GREYBOX_STICK_SLIP: int = 1
GREYBOX_TAPE_OPS: int = 25
SIM_CONTROL_SIZE: int = 26
SIM_NLOG: int = 10
SIM_NSP: int = 8
SIM_NU: int = 6
SIM_NX: int = 21
SIM_PLANT_SIZE: int = 51
__version__: str = '0.1.0'
