// k-step (simulation) training of a recurrent residual network (cdam/host/kstep.hpp): the
// windows' residuals and Jacobian (tests), J'J / J'e (tests, benchmarks) and the LM trainer.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <string>
#include <vector>

#include "cdam/host/kstep.hpp"
#include "common.hpp"

namespace py = pybind11;
using namespace cdam;
using namespace cdam::bind;

namespace {

using Arr = py::array_t<double, py::array::c_style>;
using IArr = py::array_t<long long, py::array::c_style>;

// The checked arrays of one set of windows (kept alive while the core reads them).
struct Windows {
  Arr S, E, Dr;
  IArr starts;
  host::KStepData d;
};

Windows windows(const py::array& S, const py::array& E, const py::array& Dr,
                const py::array& starts, long long K, const char* tag, long long first = 0) {
  const std::string t(tag);
  Windows w;
  w.S = matrix<double>(S, (t + "S").c_str());
  const py::ssize_t N = w.S.shape(0);
  w.E = matrix<double>(E, (t + "E").c_str(), -1, N);
  w.Dr = matrix<double>(Dr, (t + "D").c_str(), w.S.shape(1), N);
  if (starts.ndim() != 1) value_error(t + "starts: expected a 1-D array of row indices");
  if (starts.dtype().kind() != 'i' && starts.dtype().kind() != 'u')
    value_error(t + "starts: expected integers");
  w.starts = IArr::ensure(starts);
  if (!w.starts) value_error(t + "starts: expected integers");
  const long long* a = w.starts.data();
  for (py::ssize_t k = 0; k < w.starts.shape(0); ++k)
    if (a[k] < first || a[k] + K >= N)
      value_error(t + "starts[" + std::to_string(k) + "]: row " + std::to_string(a[k]) +
                  (a[k] < first ? " has not the " + std::to_string(first) +
                                      " earlier rows the linear part's lags need"
                                : " leaves no " + std::to_string(K) + " steps inside the " +
                                      std::to_string(N) + " rows"));
  w.d = host::KStepData{w.S.data(), w.E.data(), w.Dr.data(), static_cast<Index>(N), a,
                        static_cast<Index>(w.starts.shape(0))};
  return w;
}

struct Problem {
  Windows w;
  Arr in_mean, in_scale, out_scale, err_scale, step_weight, lin, err_scale_k;
  host::KStepShape sh;
};

// The linear part (None or ns x na ns): its lag count, checked before the windows.
long long lin_lags(const py::object& lin, const py::array& S) {
  if (lin.is_none()) return 0;
  const py::array L = lin.cast<py::array>();
  if (L.ndim() != 2 || S.ndim() != 2 || L.shape(0) != S.shape(1) || L.shape(1) == 0 ||
      L.shape(1) % S.shape(1) != 0)
    value_error("lin: expected an (ns, na ns) array, ns the columns of S");
  return L.shape(1) / S.shape(1);
}

Problem problem(const py::array& S, const py::array& E, const py::array& Dr,
                const py::array& starts, long long K, long long hidden, const py::array& in_mean,
                const py::array& in_scale, const py::array& out_scale,
                const py::array& err_scale, const py::object& step_weight,
                const py::object& lin) {
  const int k = int_arg(K, "K", 1, 100000);
  const int H = int_arg(hidden, "hidden", 1, 100000);
  const long long na = lin_lags(lin, S);
  Problem p;
  p.w = windows(S, E, Dr, starts, k, "", na > 0 ? na - 1 : 0);
  const py::ssize_t ns = p.w.S.shape(1);
  p.in_mean = vector<double>(in_mean, "in_mean", ns);
  p.in_scale = vector<double>(in_scale, "in_scale", ns);
  p.out_scale = vector<double>(out_scale, "out_scale", ns);
  const bool per_step = err_scale.ndim() == 2;
  if (per_step) {   // (K, ns): one scale per step and state
    p.err_scale_k = matrix<double>(err_scale, "err_scale", ns, k);
    for (py::ssize_t i = 0; i < ns * k; ++i)
      if (!(p.err_scale_k.data()[i] > 0)) value_error("scales: every err_scale must be > 0");
    if (!step_weight.is_none()) value_error("step_weight: not with a per-step err_scale");
  }
  if (per_step) {
    p.err_scale = Arr({ns});
    std::fill(p.err_scale.mutable_data(), p.err_scale.mutable_data() + ns, 1.0);
  } else {
    p.err_scale = vector<double>(err_scale, "err_scale", ns);
  }
  for (const auto* a : {&p.in_scale, &p.out_scale, &p.err_scale})
    for (py::ssize_t i = 0; i < ns; ++i)
      if (!(a->data()[i] > 0)) value_error("scales: every in_scale, out_scale and err_scale must be > 0");
  p.sh = host::KStepShape{static_cast<Index>(ns), static_cast<Index>(p.w.E.shape(1)), H, k,
                          p.in_mean.data(), p.in_scale.data(), p.out_scale.data(),
                          p.err_scale.data()};
  if (!step_weight.is_none()) {
    p.step_weight = vector<double>(step_weight.cast<py::array>(), "step_weight", k);
    for (int j = 0; j < k; ++j)
      if (!(p.step_weight.data()[j] > 0)) value_error("step_weight: every weight must be > 0");
    p.sh.step_weight = p.step_weight.data();
  }
  if (per_step) p.sh.err_scale_k = p.err_scale_k.data();
  if (na > 0) {
    p.lin = matrix<double>(lin.cast<py::array>(), "lin", ns * na, ns);
    p.sh.na = static_cast<Index>(na);
    p.sh.lin = p.lin.data();
  }
  return p;
}

Arr theta_of(const py::array& theta, const host::KStepShape& sh) {
  return vector<double>(theta, "theta", static_cast<py::ssize_t>(sh.dim()));
}

}  // namespace

void register_kstep(py::module_& m) {
  m.def("kstep_num_params", [](long long ns, long long ne, long long hidden) {
    int_arg(ns, "states", 1, 100000);
    int_arg(ne, "exogenous", 0, 100000);
    int_arg(hidden, "hidden", 1, 100000);
    return host::KStepShape{static_cast<Index>(ns), static_cast<Index>(ne),
                            static_cast<Index>(hidden), 1}.dim();
  }, py::arg("states"), py::arg("exogenous"), py::arg("hidden"));
  m.def("kstep_jacobian", [](const py::array& theta, const py::array& S, const py::array& E,
                             const py::array& Dr, const py::array& starts, long long K,
                             long long hidden, const py::array& in_mean,
                             const py::array& in_scale, const py::array& out_scale,
                             const py::array& err_scale, const py::object& step_weight,
                             const py::object& lin) {
    Problem p = problem(S, E, Dr, starts, K, hidden, in_mean, in_scale, out_scale, err_scale,
                        step_weight, lin);
    Arr th = theta_of(theta, p.sh);
    const Index R = p.sh.K * p.sh.ns, D = p.sh.dim(), W = p.w.d.W;
    Arr e({static_cast<py::ssize_t>(W * R)});
    Arr J({static_cast<py::ssize_t>(W * R), static_cast<py::ssize_t>(D)});
    host::KStep ks(p.sh, 1);
    for (Index w = 0; w < W; ++w)
      ks.window(th.data(), p.w.d, w, e.mutable_data() + w * R, J.mutable_data() + w * R * D);
    return py::make_tuple(e, J);
  }, py::arg("theta"), py::arg("S"), py::arg("E"), py::arg("D"), py::arg("starts"),
     py::arg("K"), py::arg("hidden"), py::arg("in_mean"), py::arg("in_scale"),
     py::arg("out_scale"), py::arg("err_scale"), py::arg("step_weight") = py::none(),
     py::arg("lin") = py::none(),
     "(e, J) of the K-step windows: e (W K ns) the scaled errors, row (w K + j) ns + i for "
     "step j + 1 of window w, times step_weight[j] (K weights; None: 1); J (W K ns, D) = "
     "d y_hat / d theta step_weight / err_scale by forward "
     "sensitivities (cdam/host/kstep.hpp). lin (ns, na ns): the linear part L (None: none), "
     "s_{t+1} = s_t + D_t + r o + sum_l L_l s_{t-l}; starts then need na - 1 earlier rows. "
     "err_scale (ns) or (K, ns): one scale per step and state (then no step_weight).");
  m.def("kstep_normal", [](const py::array& theta, const py::array& S, const py::array& E,
                           const py::array& Dr, const py::array& starts, long long K,
                           long long hidden, const py::array& in_mean, const py::array& in_scale,
                           const py::array& out_scale, const py::array& err_scale,
                           const py::object& step_weight, long long threads,
                           const py::object& lin) {
    Problem p = problem(S, E, Dr, starts, K, hidden, in_mean, in_scale, out_scale, err_scale,
                        step_weight, lin);
    Arr th = theta_of(theta, p.sh);
    const int nt = int_arg(threads, "threads", 1, 256);
    const Index D = p.sh.dim();
    Arr jte({static_cast<py::ssize_t>(D)});
    Arr jtj({static_cast<py::ssize_t>(D), static_cast<py::ssize_t>(D)});
    double sse;
    {
      py::gil_scoped_release nogil;
      host::KStep ks(p.sh, nt);
      sse = ks.normal(th.data(), p.w.d, jte.mutable_data(), jtj.mutable_data());
    }
    return py::make_tuple(jtj, jte, sse);
  }, py::arg("theta"), py::arg("S"), py::arg("E"), py::arg("D"), py::arg("starts"),
     py::arg("K"), py::arg("hidden"), py::arg("in_mean"), py::arg("in_scale"),
     py::arg("out_scale"), py::arg("err_scale"), py::arg("step_weight") = py::none(),
     py::arg("threads") = 1, py::arg("lin") = py::none(),
     "(J'J, J'e, sse) over the K-step windows, without forming J; bit-identical for any "
     "thread count.");
  m.def("kstep_train_lm", [](const py::array& theta0, const py::array& S, const py::array& E,
                             const py::array& Dr, const py::array& starts, long long K,
                             long long hidden, const py::array& in_mean,
                             const py::array& in_scale, const py::array& out_scale,
                             const py::array& err_scale, long long epochs, double mu,
                             double mu_dec, double mu_inc, double mu_max, double min_grad,
                             long long max_fail, const py::object& val,
                             const py::object& step_weight, long long threads,
                           const py::object& lin) {
    Problem p = problem(S, E, Dr, starts, K, hidden, in_mean, in_scale, out_scale, err_scale,
                        step_weight, lin);
    Arr th0 = theta_of(theta0, p.sh);
    LmOptions o;
    o.epochs = int_arg(epochs, "epochs");
    o.mu = mu;
    o.mu_dec = mu_dec;
    o.mu_inc = mu_inc;
    o.mu_max = mu_max;
    o.min_grad = min_grad;
    o.max_fail = int_arg(max_fail, "max_fail", 1);
    o.threads = int_arg(threads, "threads", 1, 256);
    if (!o.valid())
      value_error("options: mu > 0, 0 < mu_dec < 1, mu_inc > 1, mu_max > 0, min_grad >= 0, "
                  "all finite");
    Windows vw;
    const bool has_val = !val.is_none();
    if (has_val) {
      py::tuple t = val.cast<py::tuple>();
      if (t.size() != 4) value_error("val: expected (S, E, D, starts)");
      vw = windows(t[0].cast<py::array>(), t[1].cast<py::array>(), t[2].cast<py::array>(),
                   t[3].cast<py::array>(), p.sh.K, "val.", p.sh.na > 0 ? p.sh.na - 1 : 0);
      if (vw.S.shape(1) != p.sh.ns || vw.E.shape(1) != p.sh.ne)
        value_error("val: S and E must have the training columns");
    }
    const Index D = p.sh.dim();
    Arr theta({static_cast<py::ssize_t>(D)});
    std::copy(th0.data(), th0.data() + D, theta.mutable_data());
    struct { std::vector<double> mse, mu, grad_norm, val_mse; } h;
    SignalPoll poll;
    LmResult r;
    Status st;
    {
      py::gil_scoped_release nogil;
      host::LmKStep pol(p.sh, p.w.d, has_val ? &vw.d : nullptr, o.threads);
      st = lm_train(pol, theta.mutable_data(), o, &r,
                    [&h](int, const LmEpoch& e) {
                      h.mse.push_back(e.mse);
                      h.mu.push_back(e.mu);
                      h.grad_norm.push_back(e.grad_norm);
                      h.val_mse.push_back(e.val_mse);
                    },
                    [&poll](int, double) { return poll(); });
    }
    poll.raise_if_interrupted();
    check_status(st, "kstep_train_lm");
    py::dict d;
    d["mse"] = py::array_t<double>(h.mse.size(), h.mse.data());
    d["mu"] = py::array_t<double>(h.mu.size(), h.mu.data());
    d["grad_norm"] = py::array_t<double>(h.grad_norm.size(), h.grad_norm.data());
    d["val_mse"] = py::array_t<double>(h.val_mse.size(), h.val_mse.data());
    d["stop"] = to_string(r.stop);
    d["best_epoch"] = r.best_epoch;
    return py::make_tuple(theta, d);
  }, py::arg("theta0"), py::arg("S"), py::arg("E"), py::arg("D"), py::arg("starts"),
     py::arg("K"), py::arg("hidden"), py::arg("in_mean"), py::arg("in_scale"),
     py::arg("out_scale"), py::arg("err_scale"), py::kw_only(), py::arg("epochs") = 100,
     py::arg("mu") = 1e-3, py::arg("mu_dec") = 0.1, py::arg("mu_inc") = 10.0,
     py::arg("mu_max") = 1e10, py::arg("min_grad") = 1e-7, py::arg("max_fail") = 6,
     py::arg("val") = py::none(), py::arg("step_weight") = py::none(), py::arg("threads") = 2,
     py::arg("lin") = py::none(),
     "Levenberg-Marquardt (trainlm's semantics, levenberg_marquardt.hpp) on the K-step "
     "error of the windows; val = (S, E, D, starts) validation windows (best-validation "
     "weights returned, max_fail). Returns (theta, history). Bit-identical for any thread "
     "count.");
}
