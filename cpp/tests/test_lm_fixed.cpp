// The one Levenberg-Marquardt loop (cdam/levenberg_marquardt.hpp) with its two policies: the
// fixed-size, heap-free LmFixed (cdam/lm_fixed.hpp) against the host's train_lm (LmDynamic in
// cdam/host/training.hpp: NormalEquations' structured J'J, Eigen's LLT) on the same 4-8-2
// problem, and LmFixed's Cholesky against Eigen's LLT.
#include <doctest/doctest.h>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <cmath>

#include "cdam/host/training.hpp"
#include "cdam/lm_fixed.hpp"
#include "cdam/rng.hpp"

using namespace cdam;

namespace {

constexpr int kI = 4, kH = 8, kM = 2, kS = 200;

// 200 samples of a known 4-8-2 tansig teacher on uniform inputs, plus a start point.
template <typename Scalar>
void lm_problem(Scalar* X, Scalar* T, Scalar* theta0) {
  constexpr int D = mlp_params(kI, kH, kM);
  Rng rng(11);
  double teacher[D];
  for (double& v : teacher) v = rng.uniform(-1.5, 1.5);
  for (int k = 0; k < kS * kI; ++k) X[k] = static_cast<Scalar>(rng.uniform(-1.0, 1.0));
  const Mlp<double, kI, kH, kM> net;
  for (int s = 0; s < kS; ++s) {
    double x[kI], a[kH], y[kM];
    for (int l = 0; l < kI; ++l) x[l] = static_cast<double>(X[s * kI + l]);
    net.forward(teacher, x, a, y);
    for (int k = 0; k < kM; ++k) T[s * kM + k] = static_cast<Scalar>(y[k]);
  }
  for (int k = 0; k < D; ++k) theta0[k] = static_cast<Scalar>(rng.uniform(-0.5, 0.5));
}

}  // namespace

TEST_CASE("lm_fixed: Cholesky solve equals Eigen's LLT on a random SPD matrix") {
  using Net = Mlp<double, kI, kH, kM>;
  using Lm = LmFixed<Net>;
  Rng rng(5);
  Lm::Square B, A, L;
  for (Index k = 0; k < B.size(); ++k) B.data()[k] = rng.uniform(-1.0, 1.0);
  A = B * B.transpose();
  A.diagonal().array() += 0.5;
  Lm::Vec b, x;
  for (Index k = 0; k < b.size(); ++k) b[k] = rng.uniform(-1.0, 1.0);
  L = A;
  L.triangularView<Eigen::StrictlyUpper>().setConstant(1e300);  // the upper part is not read
  REQUIRE(Lm::cholesky_inplace(L));
  x = b;
  Lm::cholesky_solve(L, x);
  const Lm::Vec want = Eigen::LLT<Lm::Square>(A).solve(b);
  CHECK((x - want).cwiseAbs().maxCoeff() <= 1e-9 * want.cwiseAbs().maxCoeff());
  CHECK((A * x - b).cwiseAbs().maxCoeff() < 1e-9);
  Lm::Square bad = A;
  bad(3, 3) = -1.0;
  CHECK_FALSE(Lm::cholesky_inplace(bad));
}

TEST_CASE("lm_fixed: J'e and J'J equal NormalEquations' on the same data") {
  using Net = Mlp<double, kI, kH, kM>;
  constexpr int D = Net::kParams;
  static double X[kS * kI], T[kS * kM], theta[D];
  lm_problem(X, T, theta);
  static LmFixed<Net> lm;
  const double sse = lm.evaluate(theta, X, T, kS, true);
  const Mlp<double> dyn(kI, kH, kM);
  NormalEquations<double> ne(dyn, 64, 1);
  NormalEquations<double>::ConstMap Xm(X, kI, kS), Tm(T, kM, kS);
  NormalEquations<double>::Vec jte(D);
  NormalEquations<double>::Mat jtj(D, D);
  const double sse_ne = ne.evaluate(theta, Xm, Tm, &jte, &jtj);
  CHECK(sse == doctest::Approx(sse_ne).epsilon(1e-13));
  CHECK((lm.jte() - jte).cwiseAbs().maxCoeff() <= 1e-11 * jte.cwiseAbs().maxCoeff());
  const Eigen::MatrixXd lo = lm.jtj().triangularView<Eigen::Lower>();
  const Eigen::MatrixXd lo_ne = jtj.triangularView<Eigen::Lower>();
  CHECK((lo - lo_ne).cwiseAbs().maxCoeff() <= 1e-11 * jtj.cwiseAbs().maxCoeff());
}

TEST_CASE("lm_fixed: double run follows train_lm epoch by epoch, heap-free") {
  using Net = Mlp<double, kI, kH, kM>;
  constexpr int D = Net::kParams, E = 12;
  static double X[kS * kI], T[kS * kM], theta0[D];
  lm_problem(X, T, theta0);
  double th_fixed[D], th_host[D];
  for (int k = 0; k < D; ++k) th_fixed[k] = th_host[k] = theta0[k];

  LmOptions ho;
  ho.epochs = E;
  TrainHistory hist;
  const Mlp<double> dyn(kI, kH, kM);
  NormalEquations<double>::ConstMap Xm(X, kI, kS), Tm(T, kM, kS);
  REQUIRE(train_lm<double>(dyn, th_host, Xm, Tm, nullptr, nullptr, ho, hist) == Status::Ok);

  LmOptions fo;
  fo.epochs = E;
  static LmFixed<Net> lm;
  double mse[E + 1], mu[E + 1];
  int rec = 0;
  LmStop stop = LmStop::Goal;
  Eigen::internal::set_is_malloc_allowed(false);
  const Status st = lm.train(th_fixed, X, T, kS, fo, mse, mu, &rec, &stop);
  Eigen::internal::set_is_malloc_allowed(true);
  REQUIRE(st == Status::Ok);
  REQUIRE(rec == static_cast<int>(hist.mse.size()));
  CHECK(static_cast<int>(stop) == static_cast<int>(hist.stop));
  for (int e = 0; e < rec; ++e) {
    CHECK(mse[e] == doctest::Approx(hist.mse[e]).epsilon(1e-9));
    CHECK(mu[e] == doctest::Approx(hist.mu[e]).epsilon(1e-12));
  }
  CHECK(mse[rec - 1] < 0.05 * mse[0]);  // it learns
  for (int k = 0; k < D; ++k) CHECK(th_fixed[k] == doctest::Approx(th_host[k]).epsilon(1e-7));
}

TEST_CASE("lm_fixed: float run stays close to the double train_lm over a few epochs") {
  using NetF = Mlp<float, kI, kH, kM>;
  constexpr int D = NetF::kParams, E = 5;
  static float Xf[kS * kI], Tf[kS * kM], thf[D];
  static double X[kS * kI], T[kS * kM], thd[D];
  lm_problem(Xf, Tf, thf);
  lm_problem(X, T, thd);
  for (int k = 0; k < kS * kI; ++k) X[k] = Xf[k];  // the same float inputs and targets
  for (int k = 0; k < kS * kM; ++k) T[k] = Tf[k];
  for (int k = 0; k < D; ++k) thd[k] = thf[k];
  LmOptions ho;
  ho.epochs = E;
  TrainHistory hist;
  const Mlp<double> dyn(kI, kH, kM);
  NormalEquations<double>::ConstMap Xm(X, kI, kS), Tm(T, kM, kS);
  REQUIRE(train_lm<double>(dyn, thd, Xm, Tm, nullptr, nullptr, ho, hist) == Status::Ok);
  LmOptions fo;
  fo.epochs = E;
  static LmFixed<NetF> lm;
  double mse[E + 1];
  int rec = 0;
  REQUIRE(lm.train(thf, Xf, Tf, kS, fo, mse, nullptr, &rec, nullptr) == Status::Ok);
  REQUIRE(rec == E + 1);
  for (int e = 0; e < rec; ++e) CHECK(mse[e] == doctest::Approx(hist.mse[e]).epsilon(1e-3));
}

TEST_CASE("lm_fixed: bad arguments") {
  using Net = Mlp<double, kI, kH, kM>;
  static LmFixed<Net> lm;
  double theta[Net::kParams] = {}, X[kI] = {}, T[kM] = {};
  LmOptions o;
  int rec = -1;
  CHECK(lm.train(theta, X, T, 0, o, nullptr, nullptr, &rec, nullptr) == Status::Empty);
  CHECK(rec == 0);
  o.mu_dec = 2.0;
  CHECK(lm.train(theta, X, T, 1, o, nullptr, nullptr, nullptr, nullptr) ==
        Status::InvalidArgument);
}
