// C++ tests of the optimisers (BOA, IBOA, CABC), k-means, the logistic map and the BP fitness.
// Expected values come from closed forms (sphere minimum, separated clusters), from an
// independent per-sample evaluation (MlpFitness against the blocked threaded BpFitness), and
// from properties (monotone best curve, same seed same run, no heap in the iterations).
#include <doctest/doctest.h>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <vector>

#include "cdam/host/bp_fitness.hpp"
#include "cdam/optim/boa.hpp"
#include "cdam/optim/cabc.hpp"
#include "cdam/optim/chaos.hpp"
#include "cdam/optim/iboa.hpp"
#include "cdam/optim/kmeans.hpp"

using namespace cdam;
using namespace cdam::optim;
using cdam::host::activate_inplace;
using cdam::host::syrk_lower;

namespace {
double sphere(const double* x, Index n) {
  double s = 0;
  for (Index d = 0; d < n; ++d) s += (x[d] - 0.3) * (x[d] - 0.3);
  return s;
}
template <typename Vec>
bool non_increasing(const Vec& v) {
  for (size_t k = 1; k < v.size(); ++k)
    if (v[k] > v[k - 1]) return false;
  return true;
}
}  // namespace

TEST_CASE("logistic map stays in (0, 1) and avoids its fixed points") {
  LogisticMap<double> m;
  Rng rng(3);
  m.seed(rng);
  CHECK(m.z >= 0.05);
  CHECK(m.z < 0.95);
  const double z0 = m.z;
  CHECK(m.next() == doctest::Approx(4 * z0 * (1 - z0)).epsilon(1e-15));
  for (int k = 0; k < 10000; ++k) {
    const double z = m.next();
    REQUIRE(z > 0.0);
    REQUIRE(z < 1.0);
  }
  CHECK(LogisticMap<double>::guard(0.75) == doctest::Approx(0.123456789));
  CHECK(LogisticMap<double>::guard(0.0) == doctest::Approx(0.123456789));
  LogisticMap<float> f;
  f.z = 0.5f;  // 0.5 -> 1 -> 0 without the guard
  for (int k = 0; k < 100; ++k) REQUIRE(f.next() > 0.0f);
}

TEST_CASE("k-means separates two distant blobs") {
  Eigen::MatrixXd x(2, 10), centres(2, 10);
  Eigen::VectorXi label(10), count(10), perm(10);
  for (int i = 0; i < 10; ++i) {
    const double off = i % 2 ? 10.0 : -10.0;
    x(0, i) = off + 0.01 * i;
    x(1, i) = -off + 0.02 * i;
  }
  for (std::uint32_t seed = 0; seed < 20; ++seed) {
    Rng rng(seed);
    kmeans(x, 2, 10, rng, centres, label, count, perm);
    for (int i = 2; i < 10; ++i) CHECK(label[i] == label[i % 2]);
    CHECK(label[0] != label[1]);
    // centre of the even points: mean computed here independently
    double mx = 0;
    for (int i = 0; i < 10; i += 2) mx += x(0, i);
    CHECK(centres(0, label[0]) == doctest::Approx(mx / 5).epsilon(1e-12));
  }
}

TEST_CASE("BOA, IBOA and CABC reduce a shifted sphere; curves never rise; seeds repeat") {
  const Index D = 6;
  auto f = serial_fitness<double>([](const double* x) { return sphere(x, 6); }, D);
  BoaOptions bo;
  bo.iterations = 60;
  for (BoaForm form : {BoaForm::Author, BoaForm::Paper}) {
    bo.form = form;
    Swarm<double> s(D, 20);
    Rng rng(11);
    std::vector<double> curve(61);
    REQUIRE(Boa<double>(bo).run(s, f, rng, curve.data()) == Status::Ok);
    CHECK(non_increasing(curve));
    CHECK(curve.back() < curve.front());
    CHECK(s.best_fit == doctest::Approx(sphere(s.best.data(), D)).epsilon(1e-15));
  }
  IboaOptions io;
  io.boa.iterations = 60;
  Swarm<double> s1(D, 20), s2(D, 20);
  Rng r1(5), r2(5);
  std::vector<double> c1(61), c2(61);
  REQUIRE(Iboa<double>(io).run(s1, f, r1, c1.data()) == Status::Ok);
  REQUIRE(Iboa<double>(io).run(s2, f, r2, c2.data()) == Status::Ok);
  CHECK(c1 == c2);
  CHECK(non_increasing(c1));
  CHECK(c1.back() < 1e-2 * c1.front());
  CHECK(s1.best_fit == doctest::Approx(sphere(s1.best.data(), D)).epsilon(1e-15));
  CabcOptions co;
  co.iterations = 200;
  co.limit = 10;
  Swarm<double> s3(D, 20);
  Rng r3(9);
  std::vector<double> c3(201);
  REQUIRE(Cabc<double>(co).run(s3, f, r3, c3.data()) == Status::Ok);
  CHECK(non_increasing(c3));
  CHECK(c3.back() < 1e-1 * c3.front());
  CHECK(s3.evaluations >= 10 + 200 * 20);
}

TEST_CASE("optimiser options are checked") {
  auto f = serial_fitness<double>([](const double* x) { return x[0]; }, 1);
  Swarm<double> s(1, 1);
  Rng rng(0);
  CHECK(Boa<double>().run(s, f, rng, nullptr) == Status::InvalidArgument);  // n < 2
  IboaOptions io;
  io.clusters = 5;
  Swarm<double> s4(1, 4);
  CHECK(Iboa<double>(io).run(s4, f, rng, nullptr) == Status::InvalidArgument);
  CabcOptions co;
  co.lb = 1;
  co.ub = -1;
  CHECK(Cabc<double>(co).run(s4, f, rng, nullptr) == Status::InvalidArgument);
}

TEST_CASE("BpFitness: independent of the thread count and equal to per-sample forward") {
  const Index i = 3, h = 5, m = 2, N = 3000;
  Mlp<double> net(i, h, m);
  Rng rng(1);
  Eigen::MatrixXd X(i, N), T(m, N), thetas(net.num_params(), 7);
  for (Index k = 0; k < X.size(); ++k) X.data()[k] = rng.uniform(-1.0, 1.0);
  for (Index k = 0; k < T.size(); ++k) T.data()[k] = rng.uniform(-1.0, 1.0);
  for (Index k = 0; k < thetas.size(); ++k) thetas.data()[k] = rng.uniform(-1.0, 1.0);
  NormalEquations<double>::ConstMap Xm(X.data(), i, N), Tm(T.data(), m, N);
  BpFitness<double> f1(net, Xm, Tm, 1), f2(net, Xm, Tm, 2), f3(net, Xm, Tm, 3);
  double o1[7], o2[7], o3[7];
  f1.batch(thetas.data(), 7, o1);
  f2.batch(thetas.data(), 7, o2);
  f3.batch(thetas.data(), 7, o3);
  MlpFitness<Mlp<double>> ref(net, X.data(), T.data(), N);
  for (int k = 0; k < 7; ++k) {
    CHECK(o1[k] == o2[k]);  // bit-identical
    CHECK(o1[k] == o3[k]);
    CHECK(f2(thetas.col(k).data()) == o1[k]);
    CHECK(o1[k] == doctest::Approx(ref(thetas.col(k).data())).epsilon(1e-12));
  }
}

TEST_CASE("vectorised activations agree with std::tanh and the logistic function") {
  // dense grid plus tiny, huge and exactly-zero arguments; both compiled paths
  std::vector<double> grid;
  for (int k = -400000; k <= 400000; ++k) grid.push_back(k * 1e-4);
  for (double v : {1e-300, -1e-200, 1e-12, -3e-9, 0.0, 710.0, -710.0, 1e300, -1e300})
    grid.push_back(v);
  for (KernelPath p : {KernelPath::Auto, KernelPath::Generic}) {
    std::vector<double> t = grid, l = grid;
    activate_inplace(t.data(), static_cast<Index>(t.size()), Activation::Tansig, p);
    activate_inplace(l.data(), static_cast<Index>(l.size()), Activation::Logsig, p);
    double abs_t = 0, rel_t = 0, rel_l = 0;
    for (size_t k = 0; k < grid.size(); ++k) {
      const double et = std::tanh(grid[k]), el = 1.0 / (1.0 + std::exp(-grid[k]));
      abs_t = std::max(abs_t, std::abs(t[k] - et));
      if (et != 0) rel_t = std::max(rel_t, std::abs(t[k] - et) / std::abs(et));
      if (el > 1e-290) rel_l = std::max(rel_l, std::abs(l[k] - el) / el);
      REQUIRE(std::isfinite(t[k]));
      REQUIRE(std::isfinite(l[k]));
    }
    CHECK(abs_t < 5e-16);
    CHECK(rel_t < 2e-15);
    CHECK(rel_l < 2e-15);
  }
}

TEST_CASE("BpFitness: the AVX2 and the generic kernel agree; odd sizes and logsig") {
  const Index i = 7, h = 13, m = 3, N = 1001;  // sizes that leave vector remainders
  for (Activation act : {Activation::Tansig, Activation::Logsig}) {
    Mlp<double> net(i, h, m, act);
    Rng rng(9);
    Eigen::MatrixXd X(i, N), T(m, N), thetas(net.num_params(), 3);
    for (Index k = 0; k < X.size(); ++k) X.data()[k] = rng.uniform(-2.0, 2.0);
    for (Index k = 0; k < T.size(); ++k) T.data()[k] = rng.uniform(-1.0, 1.0);
    for (Index k = 0; k < thetas.size(); ++k) thetas.data()[k] = rng.uniform(-3.0, 3.0);
    NormalEquations<double>::ConstMap Xm(X.data(), i, N), Tm(T.data(), m, N);
    BpFitness<double> fa(net, Xm, Tm, 2), fg(net, Xm, Tm, 1);
    fg.set_path(KernelPath::Generic);
    MlpFitness<Mlp<double>> ref(net, X.data(), T.data(), N);
    double oa[3], og[3];
    fa.batch(thetas.data(), 3, oa);
    fg.batch(thetas.data(), 3, og);
    for (int k = 0; k < 3; ++k) {
      const double r = ref(thetas.col(k).data());
      CHECK(oa[k] == doctest::Approx(r).epsilon(1e-13));
      CHECK(og[k] == doctest::Approx(r).epsilon(1e-13));
    }
  }
}

TEST_CASE("syrk_lower equals Eigen's rank update on and below the diagonal") {
  for (Index P : {3, 13, 160})
    for (Index nb : {1, 37, 256}) {
      Eigen::MatrixXd V(P + 2, nb), K0 = Eigen::MatrixXd::Zero(P, P);
      Rng rng(static_cast<std::uint32_t>(P * 1000 + nb));
      for (Index k = 0; k < V.size(); ++k) V.data()[k] = rng.uniform(-2.0, 2.0);
      // leading dimension P + 2: the kernel must honour ldv
      K0.selfadjointView<Eigen::Lower>().rankUpdate(V.topRows(P));
      for (KernelPath p : {KernelPath::Auto, KernelPath::Generic}) {
        Eigen::MatrixXd K = Eigen::MatrixXd::Constant(P + 1, P, 1.0);  // ldg P + 1, start at 1
        syrk_lower(K.data(), P + 1, V.data(), P + 2, P, nb, p);
        for (Index c = 0; c < P; ++c)
          for (Index r = c; r < P; ++r)
            REQUIRE(K(r, c) - 1.0 == doctest::Approx(K0(r, c)).epsilon(1e-13).scale(nb * 4.0));
        for (Index c = 0; c < P; ++c) CHECK(K(P, c) == 1.0);  // padding row untouched
      }
    }
}

TEST_CASE("jtj_blocks: the blocks of [v; a; 1][v; a; 1]' that J'J reads, against Eigen") {
  // v_l = z_l d with z = [x; 1] (so each block of v v' is symmetric), a, then a row of ones.
  for (Index h : {3, 20})
    for (Index nb : {1, 37, 256}) {
      const Index i = 2, nz = i + 1, P = nz * h, rows = P + h + 1;
      Rng rng(static_cast<std::uint32_t>(h * 1000 + nb));
      Eigen::MatrixXd V(rows + 1, nb);   // leading dimension rows + 1
      for (Index s = 0; s < nb; ++s) {
        Eigen::VectorXd d(h), a(h);
        for (Index j = 0; j < h; ++j) { d[j] = rng.uniform(0.0, 1.0); a[j] = rng.uniform(-1.0, 1.0); }
        for (Index l = 0; l < nz; ++l)
          V.col(s).segment(l * h, h) = (l < i ? rng.uniform(-2.0, 2.0) : 1.0) * d;
        V.col(s).segment(P, h) = a;
        V(P + h, s) = 1.0;
        V(rows, s) = 99.0;   // beyond the rows: never read
      }
      const Eigen::MatrixXd full = V.topRows(rows) * V.topRows(rows).transpose();
      for (KernelPath p : {KernelPath::Auto, KernelPath::Generic}) {
        Eigen::MatrixXd K = Eigen::MatrixXd::Zero(rows, rows);
        cdam::host::jtj_blocks(K.data(), rows, V.data(), rows + 1, h, nz, nb, p);
        const auto near = [&](Index r, Index c) {
          return K(r, c) == doctest::Approx(full(r, c)).epsilon(1e-13).scale(nb * 4.0);
        };
        for (Index l = 0; l < nz; ++l)         // S: the lower triangle of each block l >= l2
          for (Index l2 = 0; l2 <= l; ++l2)
            for (Index j2 = 0; j2 < h; ++j2)
              for (Index j = j2; j < h; ++j) REQUIRE(near(l * h + j, l2 * h + j2));
        for (Index r = P; r < rows; ++r)       // C (with the sums of v) and R (lower)
          for (Index c = 0; c < rows; ++c)
            if (c < P || c <= r) REQUIRE(near(r, c));
        CHECK(K(rows - 1, rows - 1) == double(nb));
      }
    }
}

TEST_CASE("cholesky_lower / cholesky_solve solve an SPD system as Eigen's LLT does") {
  for (Index n : {1, 5, 33, 70, 308}) {
    Rng rng(static_cast<std::uint32_t>(n));
    Eigen::MatrixXd B(n, n + 3);
    for (Index k = 0; k < B.size(); ++k) B.data()[k] = rng.uniform(-1.0, 1.0);
    const Eigen::MatrixXd A = B * B.transpose() + 1e-2 * Eigen::MatrixXd::Identity(n, n);
    Eigen::VectorXd b(n);
    for (Index k = 0; k < n; ++k) b[k] = rng.uniform(-1.0, 1.0);
    const Eigen::VectorXd want = A.llt().solve(b);
    for (KernelPath p : {KernelPath::Auto, KernelPath::Generic}) {
      Eigen::MatrixXd L = A;
      Eigen::VectorXd x = b;
      REQUIRE(cdam::host::cholesky_lower(L.data(), n, n, p));
      const Eigen::MatrixXd Lt = L.triangularView<Eigen::Lower>();
      CHECK((Lt * Lt.transpose() - A).norm() <= 1e-12 * A.norm());
      cdam::host::cholesky_solve(L.data(), n, n, x.data(), p);
      CHECK((x - want).norm() <= 1e-9 * want.norm());
      Eigen::MatrixXd bad = A;   // an indefinite matrix and a NaN are refused
      bad(n - 1, n - 1) = -1.0 - bad.row(n - 1).squaredNorm();
      CHECK_FALSE(cdam::host::cholesky_lower(bad.data(), n, n, p));
      bad = A;
      bad(0, 0) = std::nan("");
      CHECK_FALSE(cdam::host::cholesky_lower(bad.data(), n, n, p));
    }
  }
}

TEST_CASE("target build: fixed-size IBOA-BP (4-8-2, 20 butterflies) allocates nothing") {
  using Net = Mlp<float, 4, 8, 2>;
  constexpr int D = Net::kParams, N = 20, S = 200;
  static float X[4 * S], T[2 * S];
  Rng data(2);
  for (int k = 0; k < S; ++k) {
    for (int c = 0; c < 4; ++c) X[k * 4 + c] = data.uniform(-1.0f, 1.0f);
    T[k * 2] = 0.5f * X[k * 4] - 0.3f * X[k * 4 + 1] * X[k * 4 + 2];
    T[k * 2 + 1] = std::tanh(X[k * 4 + 3]);
  }
  Net net;
  MlpFitness<Net> fit(net, X, T, S);
  static Swarm<float, D, N> swarm;
  IboaOptions io;
  io.boa.iterations = 10;
  Iboa<float, D, N> iboa(io);
  Rng rng(4);
  double curve[11];
  Eigen::internal::set_is_malloc_allowed(false);
  const Status st = iboa.run(swarm, fit, rng, curve);
  CabcOptions co;
  co.iterations = 10;
  static Swarm<float, D, N> swarm2;
  const Status st2 = Cabc<float, D, N>(co).run(swarm2, fit, rng, curve);
  Eigen::internal::set_is_malloc_allowed(true);
  REQUIRE(st == Status::Ok);
  REQUIRE(st2 == Status::Ok);
  CHECK(curve[10] <= curve[0]);
}

TEST_CASE("fixed and dynamic sizes give the same IBOA run in double") {
  constexpr int D = 5, N = 8;
  auto f = serial_fitness<double>([](const double* x) { return sphere(x, 5); }, D);
  IboaOptions io;
  io.boa.iterations = 20;
  io.clusters = 2;
  io.chaos_candidates = 3;
  Swarm<double, D, N> sf;
  Swarm<double> sd(D, N);
  Rng a(17), b(17);
  double cf[21], cd[21];
  REQUIRE(Iboa<double, D, N>(io).run(sf, f, a, cf) == Status::Ok);
  REQUIRE(Iboa<double>(io).run(sd, f, b, cd) == Status::Ok);
  for (int t = 0; t <= 20; ++t) CHECK(cf[t] == doctest::Approx(cd[t]).epsilon(1e-14));
}
