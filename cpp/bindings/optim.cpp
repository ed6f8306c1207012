// Bindings: the population optimisers (BOA, IBOA, CABC) on the BP fitness or a test function,
// and the batch BP fitness. Double precision; the whole run happens in C++ without the GIL.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <climits>
#include <cmath>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "cdam/host/bp_fitness.hpp"
#include "cdam/optim/boa.hpp"
#include "cdam/optim/cabc.hpp"
#include "cdam/optim/iboa.hpp"
#include "common.hpp"

namespace py = pybind11;
using namespace cdam;
using namespace cdam::bind;
using namespace cdam::optim;

namespace {

using Map = NormalEquations<double>::ConstMap;

// Reads options[key] if present (marking it used).
struct OptionReader {
  py::dict d;
  std::set<std::string> used;
  double num(const char* key, double v) {
    used.insert(key);
    if (!d.contains(key)) return v;
    const double x = py::cast<double>(d[key]);
    if (!std::isfinite(x)) value_error(std::string("options['") + key + "']: must be finite");
    return x;
  }
  int integer(const char* key, int v) {
    used.insert(key);
    if (!d.contains(key)) return v;
    py::object o = d[key];
    const std::string name = std::string("options['") + key + "']";
    if (py::isinstance<py::bool_>(o) || !py::isinstance<py::int_>(o))
      value_error(name + ": must be an integer");
    int overflow = 0;
    const long long x = PyLong_AsLongLongAndOverflow(o.ptr(), &overflow);
    if (overflow != 0 || x < INT_MIN || x > INT_MAX)
      value_error(name + ": must be in " + std::to_string(INT_MIN) + " .. " +
                  std::to_string(INT_MAX));
    return static_cast<int>(x);
  }
  std::string str(const char* key, const std::string& v) {
    used.insert(key);
    if (!d.contains(key)) return v;
    return py::cast<std::string>(d[key]);
  }
  void finish(const std::string& algo) {
    for (auto item : d) {
      const std::string k = py::cast<std::string>(item.first);
      if (!used.count(k)) {
        std::string known;
        for (const auto& u : used) known += (known.empty() ? "" : ", ") + u;
        value_error("options: unknown key '" + k + "' for " + algo + " (known: " + known + ")");
      }
    }
  }
};

BoaOptions boa_options(OptionReader& r) {
  BoaOptions o;
  o.iterations = r.integer("iterations", 50);
  o.p = r.num("p", 0.8);
  o.c = r.num("c", 0.01);
  o.a = r.num("a", 0.1);
  o.lb = r.num("lb", -1.0);
  o.ub = r.num("ub", 1.0);
  const std::string form = r.str("form", "author");
  if (form == "author") o.form = BoaForm::Author;
  else if (form == "paper") o.form = BoaForm::Paper;
  else value_error("options['form']: unknown '" + form + "'; use 'author' or 'paper'");
  return o;
}

struct Result {
  std::vector<double> curve;
  Swarm<double> swarm;
  Result(Index dim, Index n, int iters) : curve(static_cast<size_t>(iters) + 1), swarm(dim, n) {}

  // The sizes of a run, checked before anything is allocated: the Swarm's five D x n position
  // blocks and the curve (iterations + 1 values).
  static void check_sizes(Index dim, Index n, int iters) {
    alloc_elements<double>(Checked<Index>(dim) * n * 5, "dim, options['n']");
    alloc_elements<double>(Checked<Index>(iters) + 1, "options['iterations']");
  }
};

template <typename Fitness>
py::dict run(const std::string& algo, py::dict options, Fitness& fitness, Index dim,
             std::uint32_t seed) {
  OptionReader r{options, {}};
  const int n = r.integer("n", 20);
  if (n < 1) value_error("options['n']: must be >= 1");
  Status st = Status::Ok;
  std::unique_ptr<Result> res;
  Rng rng(seed);
  SignalPoll poll;
  if (algo == "boa" || algo == "iboa") {
    IboaOptions io;
    io.boa = boa_options(r);
    if (algo == "iboa") {
      io.clusters = r.integer("clusters", 3);
      io.kmeans_iters = r.integer("kmeans_iters", 10);
      io.phi = r.num("phi", 0.1);
      io.chaos_candidates = r.integer("chaos_candidates", 5);
      const std::string cf = r.str("chaos_form", "convex");
      if (cf == "convex") io.chaos_form = ChaosForm::Convex;
      else if (cf == "additive") io.chaos_form = ChaosForm::Additive;
      else value_error("options['chaos_form']: unknown '" + cf + "'; use 'convex' or 'additive'");
      io.chaos_scale = r.num("chaos_scale", 0.1);
    }
    r.finish(algo);
    if (io.boa.iterations < 0) value_error("options['iterations']: must be >= 0");
    if (io.check(n) != Status::Ok && (algo == "iboa" || io.boa.check(n) != Status::Ok))
      value_error("options: invalid " + algo + " settings (need n >= 2, 0 <= p <= 1, c > 0, "
                  "lb < ub; IBOA: 1 <= clusters <= n, 0 <= chaos_candidates <= n, "
                  "kmeans_iters >= 1, chaos_scale > 0)");
    Result::check_sizes(dim, n, io.boa.iterations);
    res = std::make_unique<Result>(dim, n, io.boa.iterations);
    py::gil_scoped_release nogil;
    if (algo == "boa") {
      Boa<double> boa(io.boa);
      st = boa.run(res->swarm, fitness, rng, res->curve.data(), poll.hook());
    } else {
      Iboa<double> iboa(io);
      st = iboa.run(res->swarm, fitness, rng, res->curve.data(), poll.hook());
    }
  } else if (algo == "cabc") {
    CabcOptions co;
    co.iterations = r.integer("iterations", 50);
    co.limit = r.integer("limit", 20);
    co.lb = r.num("lb", -1.0);
    co.ub = r.num("ub", 1.0);
    co.scout_candidates = r.integer("scout_candidates", 5);
    co.scout_radius = r.num("scout_radius", 0.1);
    r.finish(algo);
    if (co.check(n) != Status::Ok)
      value_error("options: invalid cabc settings (need n >= 4, iterations >= 0, limit >= 0, "
                  "lb < ub, 1 <= scout_candidates <= n, scout_radius > 0)");
    Result::check_sizes(dim, n, co.iterations);
    res = std::make_unique<Result>(dim, n, co.iterations);
    py::gil_scoped_release nogil;
    Cabc<double> cabc(co);
    st = cabc.run(res->swarm, fitness, rng, res->curve.data(), poll.hook());
  } else {
    value_error("algorithm: unknown '" + algo + "'; use 'boa', 'iboa' or 'cabc'");
  }
  poll.raise_if_interrupted();
  if (st == Status::Overflow) value_error("dim: too large for the optimiser (more than 2**32 - 1)");
  check_status(st, "options");
  const Swarm<double>& s = res->swarm;
  const Index live = algo == "cabc" ? n / 2 : n;
  py::dict out;
  py::array_t<double> best(dim), pos({static_cast<Index>(live), dim}), fit(live);
  std::copy(s.best.data(), s.best.data() + dim, best.mutable_data());
  for (Index i = 0; i < live; ++i) {
    std::copy(s.x.col(i).data(), s.x.col(i).data() + dim, pos.mutable_data() + i * dim);
    fit.mutable_at(i) = s.fit[i];
  }
  out["best"] = best;
  out["best_fitness"] = s.best_fit;
  out["curve"] = py::array_t<double>(res->curve.size(), res->curve.data());
  out["evaluations"] = s.evaluations;
  out["positions"] = pos;
  out["fitness"] = fit;
  return out;
}

FitnessPrecision precision_of(const std::string& p) {
  if (p == "float64") return FitnessPrecision::Float64;
  if (p == "float32") return FitnessPrecision::Float32;
  value_error("precision: unknown '" + p + "'; use 'float64' or 'float32'");
}

// float32 precision: a record value beyond the float range cannot be represented (refused).
void check_float_range(FitnessPrecision prec, const double* p, Index n, const char* name) {
  if (prec != FitnessPrecision::Float32) return;
  for (Index k = 0; k < n; ++k)
    if (std::isfinite(p[k]) && std::abs(p[k]) > 3.4028234663852886e38)
      value_error(std::string(name) + ": values beyond the float32 range (3.4e38) with "
                  "precision='float32'");
}

std::uint32_t seed_of(long long seed) {
  if (seed < 0 || seed > 0xFFFFFFFFLL) value_error("seed: must be in 0 .. 2**32 - 1");
  return static_cast<std::uint32_t>(seed);
}

py::dict optimise(const std::string& algo, const std::string& objective, const py::object& X,
                  const py::object& Tt, long long hidden, const std::string& act, long long dim,
                  long long seed, const py::object& options, long long threads_,
                  const std::string& precision) {
  const std::uint32_t sd = seed_of(seed);
  const FitnessPrecision prec = precision_of(precision);
  const int threads = int_arg(threads_, "threads", 1);
  py::dict opts = options.is_none() ? py::dict() : py::dict(options);
  if (objective == "bp") {
    if (X.is_none() || Tt.is_none()) value_error("X, T: the 'bp' objective needs both");
    auto x = matrix<double>(py::array::ensure(X), "X");
    auto t = matrix<double>(py::array::ensure(Tt), "T", -1, x.shape(0));
    mlp_params_or_raise(x.shape(1), hidden, t.shape(1));
    Mlp<double> net(x.shape(1), hidden, t.shape(1), activation_from(act));
    check_float_range(prec, x.data(), static_cast<Index>(x.size()), "X");
    check_float_range(prec, t.data(), static_cast<Index>(t.size()), "T");
    Map Xm(x.data(), x.shape(1), x.shape(0)), Tm(t.data(), t.shape(1), t.shape(0));
    BpFitness<double> fit(net, Xm, Tm, threads, 64, prec);
    return run(algo, opts, fit, net.num_params(), sd);
  }
  check_positive(dim, "dim");
  if (objective == "sphere") {
    auto f = serial_fitness<double>([dim](const double* v) {
      double s = 0;
      for (long d = 0; d < dim; ++d) s += v[d] * v[d];
      return s;
    }, dim);
    return run(algo, opts, f, dim, sd);
  }
  if (objective == "rastrigin") {
    auto f = serial_fitness<double>([dim](const double* v) {
      double s = 10.0 * static_cast<double>(dim);
      for (long d = 0; d < dim; ++d) s += v[d] * v[d] - 10.0 * std::cos(6.283185307179586 * v[d]);
      return s;
    }, dim);
    return run(algo, opts, f, dim, sd);
  }
  value_error("objective: unknown '" + objective + "'; use 'bp', 'sphere' or 'rastrigin'");
}

py::array bp_fitness(const py::array& thetas, const py::array& X, const py::array& Tt,
                     long long hidden, const std::string& act, long long threads_,
                     const std::string& precision) {
  check_positive(hidden, "hidden");
  const FitnessPrecision prec = precision_of(precision);
  const int threads = int_arg(threads_, "threads", 1);
  auto x = matrix<double>(X, "X");
  auto t = matrix<double>(Tt, "T", -1, x.shape(0));
  const Index D = mlp_params_or_raise(x.shape(1), hidden, t.shape(1));
  Mlp<double> net(x.shape(1), hidden, t.shape(1), activation_from(act));
  const bool one = thetas.ndim() == 1;
  auto th = one ? vector<double>(thetas, "thetas", D) : matrix<double>(thetas, "thetas", D);
  const Index n = one ? 1 : th.shape(0);
  check_float_range(prec, x.data(), static_cast<Index>(x.size()), "X");
  check_float_range(prec, t.data(), static_cast<Index>(t.size()), "T");
  check_float_range(prec, th.data(), static_cast<Index>(th.size()), "thetas");
  py::array_t<double> out(n);
  {
    py::gil_scoped_release nogil;
    Map Xm(x.data(), x.shape(1), x.shape(0)), Tm(t.data(), t.shape(1), t.shape(0));
    BpFitness<double> fit(net, Xm, Tm, threads, n, prec);
    fit.batch(th.data(), n, out.mutable_data());
  }
  return out;
}

}  // namespace

void register_optim(py::module_& m) {
  m.def("optimise", &optimise, py::arg("algorithm"), py::arg("objective") = "bp", py::kw_only(),
        py::arg("X") = py::none(), py::arg("T") = py::none(), py::arg("hidden") = 1,
        py::arg("activation") = "tansig", py::arg("dim") = 1, py::arg("seed") = 0,
        py::arg("options") = py::none(), py::arg("threads") = 2, py::arg("precision") = "float64",
        "Run BOA, IBOA or CABC (algorithm 'boa'|'iboa'|'cabc') on the BP fitness (training MSE "
        "of the network given by the individual on X (N, i), T (N, m)) or a test function "
        "('sphere', 'rastrigin' of `dim` variables). Returns a dict: best, best_fitness, curve "
        "(iterations + 1), evaluations, positions (n, D), fitness (n). precision 'float32': the "
        "BP fitness in float (8/16-lane kernel; the swarm itself stays double).");
  m.def("bp_fitness", &bp_fitness, py::arg("thetas"), py::arg("X"), py::arg("T"),
        py::arg("hidden"), py::arg("activation") = "tansig", py::arg("threads") = 2,
        py::arg("precision") = "float64",
        "Training MSE sum((T - Y)^2) / (N m) of each theta (rows of a (n, D) array, or one (D,)); "
        "deterministic for any thread count. precision 'float32': computed in float (agrees to "
        "float rounding).");
}
