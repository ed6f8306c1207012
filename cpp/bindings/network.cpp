// Bindings: BP network kernels (forward, MSE gradient, Jacobian, J'J) and its trainers
// (Levenberg-Marquardt, gradient descent).
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "cdam/host/normal_equations.hpp"
#include "cdam/host/training.hpp"
#include "cdam/mlp.hpp"
#include <cmath>
#include <string>

#include "common.hpp"

namespace py = pybind11;
using namespace cdam;
using namespace cdam::bind;

namespace {

template <typename T>
using CArr = py::array_t<T, py::array::c_style>;

// The checked pieces every network call needs.
template <typename T>
struct NetArgs {
  Mlp<T> net;
  CArr<T> theta, X;
  typename NormalEquations<T>::ConstMap Xm;
  NetArgs(const py::array& th, const py::array& x, long long hidden, long long outputs,
          const std::string& act)
      : net(1, 1, 1),
        X(matrix<T>(x, "X")),
        Xm(X.data(), X.shape(1), X.shape(0)) {
    const Index D = mlp_params_or_raise(X.shape(1), hidden, outputs);
    net = Mlp<T>(X.shape(1), hidden, outputs, activation_from(act));
    theta = vector<T>(th, "theta", D);  // bounds h and m by theta's real length
  }
};

template <typename T>
typename NormalEquations<T>::ConstMap targets(const CArr<T>& t, const Mlp<T>& net) {
  return typename NormalEquations<T>::ConstMap(t.data(), net.outputs(), t.shape(0));
}

py::array forward(const py::array& theta, const py::array& X, long long hidden,
                  long long outputs, const std::string& act) {
  return dispatch(X, "X", [&](auto tag) -> py::array {
    using T = decltype(tag);
    NetArgs<T> a(theta, X, hidden, outputs, act);
    alloc_elements<T>(Checked<Index>(X.shape(0)) * outputs, "outputs");
    py::array_t<T> Y({X.shape(0), static_cast<py::ssize_t>(outputs)});
    Eigen::Map<typename NormalEquations<T>::Mat> Ym(Y.mutable_data(), outputs, X.shape(0));
    {
      py::gil_scoped_release nogil;
      NormalEquations<T> ne(a.net);
      ne.predict(a.theta.data(), a.Xm, Ym);
    }
    return Y;
  });
}

py::tuple mse_gradient(const py::array& theta, const py::array& X, const py::array& Tt,
                       long long hidden, const std::string& act) {
  return dispatch(X, "X", [&](auto tag) -> py::tuple {
    using T = decltype(tag);
    if (Tt.ndim() != 2) value_error("T: expected a 2-D array (samples x outputs)");
    NetArgs<T> a(theta, X, hidden, Tt.shape(1), act);
    auto t = matrix<T>(Tt, "T", -1, X.shape(0));
    typename NormalEquations<T>::Vec jte;
    double sse;
    {
      py::gil_scoped_release nogil;
      NormalEquations<T> ne(a.net);
      sse = ne.evaluate(a.theta.data(), a.Xm, targets(t, a.net), &jte, nullptr);
    }
    const double nm = static_cast<double>(t.shape(0) * t.shape(1));
    py::array_t<T> grad(jte.size());
    for (Index k = 0; k < jte.size(); ++k)
      grad.mutable_at(k) = static_cast<T>(-2.0 / nm * static_cast<double>(jte[k]));
    return py::make_tuple(sse / nm, grad);
  });
}

py::array jacobian(const py::array& theta, const py::array& X, long long hidden,
                   long long outputs, const std::string& act) {
  return dispatch(X, "X", [&](auto tag) -> py::array {
    using T = decltype(tag);
    NetArgs<T> a(theta, X, hidden, outputs, act);
    const Index n = X.shape(0), m = outputs, D = a.net.num_params();
    alloc_elements<T>(Checked<Index>(n) * m * D, "X");  // the (N m) x D Jacobian
    py::array_t<T> J({n * m, D});
    T* out = J.mutable_data();
    {
      py::gil_scoped_release nogil;
      Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic> Jn(m, D);
      Eigen::Matrix<T, Eigen::Dynamic, 1> hid(hidden);
      for (Index s = 0; s < n; ++s) {
        a.net.jacobian(a.theta.data(), a.X.data() + s * a.net.inputs(), hid.data(), Jn.data());
        // rows s*m + k of the row-major output
        Eigen::Map<Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(out + s * m * D, m, D) = Jn;
      }
    }
    return J;
  });
}

py::tuple jtj(const py::array& theta, const py::array& X, const py::array& Tt, long long hidden,
              const std::string& act, long long threads_) {
  const int threads = int_arg(threads_, "threads", 1);
  return dispatch(X, "X", [&](auto tag) -> py::tuple {
    using T = decltype(tag);
    if (Tt.ndim() != 2) value_error("T: expected a 2-D array (samples x outputs)");
    NetArgs<T> a(theta, X, hidden, Tt.shape(1), act);
    alloc_elements<T>(Checked<Index>(a.net.num_params()) * a.net.num_params(), "hidden");
    auto t = matrix<T>(Tt, "T", -1, X.shape(0));
    typename NormalEquations<T>::Vec jte;
    typename NormalEquations<T>::Mat JtJ;
    double sse;
    {
      py::gil_scoped_release nogil;
      NormalEquations<T> ne(a.net, 256, threads);
      sse = ne.evaluate(a.theta.data(), a.Xm, targets(t, a.net), &jte, &JtJ);
    }
    const Index D = a.net.num_params();
    py::array_t<T> A({D, D}), b(D);
    Eigen::Map<Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic>>(A.mutable_data(), D, D) = JtJ;  // symmetric
    std::copy(jte.data(), jte.data() + D, b.mutable_data());
    return py::make_tuple(A, b, sse);
  });
}

py::dict history_dict(const TrainHistory& h) {
  py::dict d;
  d["mse"] = py::array_t<double>(h.mse.size(), h.mse.data());
  d["mu"] = py::array_t<double>(h.mu.size(), h.mu.data());
  d["grad_norm"] = py::array_t<double>(h.grad_norm.size(), h.grad_norm.data());
  d["val_mse"] = py::array_t<double>(h.val_mse.size(), h.val_mse.data());
  d["stop"] = to_string(h.stop);
  d["best_epoch"] = h.best_epoch;
  return d;
}

// The epoch hook of the trainers: Python's signal handlers (Ctrl-C, through `poll`), then the
// optional Python callable(epoch, mse) -> bool|None, called with the GIL held.
EpochCallback make_callback(const py::object& cb, SignalPoll& poll) {
  return [&cb, &poll](int epoch, double mse) {
    if (!poll()) return false;
    if (cb.is_none()) return true;
    py::gil_scoped_acquire gil;
    py::object r = cb(epoch, mse);
    return r.is_none() || r.cast<bool>();
  };
}

// The ranges of LmOptions::valid(), each with a message naming the option.
void check_options(const LmOptions& o) {
  if (!(o.mu > 0) || !std::isfinite(o.mu)) value_error("mu: must be > 0 and finite");
  if (!(o.mu_dec > 0 && o.mu_dec < 1)) value_error("mu_dec: must be in (0, 1)");
  if (!(o.mu_inc > 1) || !std::isfinite(o.mu_inc)) value_error("mu_inc: must be > 1 and finite");
  if (!(o.mu_max > 0) || !std::isfinite(o.mu_max)) value_error("mu_max: must be > 0 and finite");
  if (!(o.goal >= 0) || !std::isfinite(o.goal)) value_error("goal: must be >= 0 and finite");
  if (!(o.min_grad >= 0) || !std::isfinite(o.min_grad))
    value_error("min_grad: must be >= 0 and finite");
}

py::tuple lm(const py::array& theta0, const py::array& X, const py::array& Tt, long long hidden,
             const std::string& act, long long epochs, double goal, double mu, double mu_dec,
             double mu_inc, double mu_max, double min_grad, long long max_fail,
             const py::object& Xv, const py::object& Tv, long long threads,
             const py::object& callback) {
  LmOptions o;
  o.epochs = int_arg(epochs, "epochs");
  o.max_fail = int_arg(max_fail, "max_fail", 1);
  o.threads = int_arg(threads, "threads", 1);
  o.goal = goal; o.mu = mu; o.mu_dec = mu_dec; o.mu_inc = mu_inc;
  o.mu_max = mu_max; o.min_grad = min_grad;
  check_options(o);
  return dispatch(X, "X", [&](auto tag) -> py::tuple {
    using T = decltype(tag);
    using Map = typename NormalEquations<T>::ConstMap;
    if (Tt.ndim() != 2) value_error("T: expected a 2-D array (samples x outputs)");
    NetArgs<T> a(theta0, X, hidden, Tt.shape(1), act);
    auto t = matrix<T>(Tt, "T", -1, X.shape(0));
    CArr<T> xv, tv;
    const bool val = !Xv.is_none() || !Tv.is_none();
    if (val) {
      if (Xv.is_none() || Tv.is_none()) value_error("X_val, T_val: give both or neither");
      xv = matrix<T>(py::array::ensure(Xv), "X_val", a.net.inputs());
      tv = matrix<T>(py::array::ensure(Tv), "T_val", a.net.outputs(), xv.shape(0));
    }
    py::array_t<T> theta(a.net.num_params());
    std::copy(a.theta.data(), a.theta.data() + a.net.num_params(), theta.mutable_data());
    TrainHistory h;
    SignalPoll poll;
    auto cb = make_callback(callback, poll);
    Status st;
    {
      py::gil_scoped_release nogil;
      Map tm = targets(t, a.net);
      if (val) {
        Map xvm(xv.data(), a.net.inputs(), xv.shape(0)), tvm(tv.data(), a.net.outputs(), tv.shape(0));
        st = train_lm(a.net, theta.mutable_data(), a.Xm, tm, &xvm, &tvm, o, h, cb);
      } else {
        st = train_lm<T>(a.net, theta.mutable_data(), a.Xm, tm, nullptr, nullptr, o, h, cb);
      }
    }
    poll.raise_if_interrupted();
    check_status(st, "train_lm");
    return py::make_tuple(theta, history_dict(h));
  });
}

py::tuple gd(const py::array& theta0, const py::array& X, const py::array& Tt, long long hidden,
             const std::string& act, double lr, long long epochs_, double goal, long long threads_,
             const py::object& callback) {
  if (!(lr > 0) || !std::isfinite(lr)) value_error("lr: must be > 0 and finite");
  const int epochs = int_arg(epochs_, "epochs");
  const int threads = int_arg(threads_, "threads", 1);
  if (!(goal >= 0) || !std::isfinite(goal)) value_error("goal: must be >= 0 and finite");
  return dispatch(X, "X", [&](auto tag) -> py::tuple {
    using T = decltype(tag);
    if (Tt.ndim() != 2) value_error("T: expected a 2-D array (samples x outputs)");
    NetArgs<T> a(theta0, X, hidden, Tt.shape(1), act);
    auto t = matrix<T>(Tt, "T", -1, X.shape(0));
    py::array_t<T> theta(a.net.num_params());
    std::copy(a.theta.data(), a.theta.data() + a.net.num_params(), theta.mutable_data());
    TrainHistory h;
    SignalPoll poll;
    auto cb = make_callback(callback, poll);
    Status st;
    {
      py::gil_scoped_release nogil;
      st = train_gd(a.net, theta.mutable_data(), a.Xm, targets(t, a.net), lr, epochs, goal, h,
                    threads, cb);
    }
    poll.raise_if_interrupted();
    if (st == Status::Diverged)
      value_error("lr: training diverged (the MSE became NaN or Inf at epoch " +
                  std::to_string(h.mse.size() - 1) + "); use a smaller lr");
    check_status(st, "train_gd");
    return py::make_tuple(theta, history_dict(h));
  });
}

}  // namespace

void register_network(py::module_& m) {
  m.def("mlp_num_params", [](long long i, long long h, long long o) {
    return mlp_params_or_raise(i, h, o);
  }, py::arg("inputs"), py::arg("hidden"), py::arg("outputs"));
  m.def("mlp_forward", &forward, py::arg("theta"), py::arg("X"), py::arg("hidden"),
        py::arg("outputs"), py::arg("activation") = "tansig",
        "Network outputs (N, m) for inputs X (N, i); theta = [W1(:); b1; W2(:); b2].");
  m.def("mlp_mse_gradient", &mse_gradient, py::arg("theta"), py::arg("X"), py::arg("T"),
        py::arg("hidden"), py::arg("activation") = "tansig",
        "(mse, d mse / d theta) by backpropagation; mse = sum((T - Y)^2) / (N m).");
  m.def("mlp_jacobian", &jacobian, py::arg("theta"), py::arg("X"), py::arg("hidden"),
        py::arg("outputs"), py::arg("activation") = "tansig",
        "Jacobian (N m, D) of the outputs; row n m + k is d Y[n, k] / d theta.");
  m.def("mlp_jtj", &jtj, py::arg("theta"), py::arg("X"), py::arg("T"), py::arg("hidden"),
        py::arg("activation") = "tansig", py::arg("threads") = 1,
        "(J'J, J'e, sse) accumulated in blocks without forming J; e = T - Y. "
        "Bit-identical for any thread count.");
  m.def("train_lm", &lm, py::arg("theta0"), py::arg("X"), py::arg("T"), py::arg("hidden"),
        py::arg("activation") = "tansig", py::kw_only(), py::arg("epochs") = 1000,
        py::arg("goal") = 0.0, py::arg("mu") = 1e-3, py::arg("mu_dec") = 0.1,
        py::arg("mu_inc") = 10.0, py::arg("mu_max") = 1e10, py::arg("min_grad") = 1e-7,
        py::arg("max_fail") = 6, py::arg("X_val") = py::none(), py::arg("T_val") = py::none(),
        py::arg("threads") = 2, py::arg("callback") = py::none(),
        "Levenberg-Marquardt with trainlm's semantics; returns (theta, history). "
        "Bit-identical for any thread count.");
  m.def("train_gd", &gd, py::arg("theta0"), py::arg("X"), py::arg("T"), py::arg("hidden"),
        py::arg("activation") = "tansig", py::kw_only(), py::arg("lr") = 0.01,
        py::arg("epochs") = 1000, py::arg("goal") = 0.0, py::arg("threads") = 2,
        py::arg("callback") = py::none(),
        "Plain batch gradient-descent BP on the MSE; returns (theta, history). "
        "Bit-identical for any thread count.");
}
