// C++ unit tests of the core kernels. Expected values come from the published 9-point vector
// (ALGORITHMS.md), closed forms, finite differences, or an explicit J'J formed from J.
#include <doctest/doctest.h>

#include <Eigen/Core>
#include <array>
#include <cmath>

#include "cdam/host/normal_equations.hpp"
#include "cdam/host/training.hpp"
#include "cdam/mlp.hpp"
#include "cdam/narx.hpp"
#include "cdam/rng.hpp"
#include "cdam/scaling.hpp"
#include "cdam/smoothing.hpp"

using namespace cdam;

TEST_CASE("five-point cubic smoothing matches the published 9-point vector") {
  double y[9] = {54, 145, 227, 359, 401, 342, 259, 112, 65};
  const double expect[9] = {56.842857, 133.628571, 244.057143, 347.942857, 393.457143,
                            352.028571, 241.514286, 123.657143, 62.085714};
  REQUIRE(five_point_cubic_smooth_inplace(y, 9, 1, 1) == Status::Ok);
  for (int k = 0; k < 9; ++k) CHECK(y[k] == doctest::Approx(expect[k]).epsilon(1e-7));
  double few[4] = {1, 2, 3, 4};
  CHECK(five_point_cubic_smooth_inplace(few, 4, 1, 1) == Status::TooFewSamples);
  CHECK(five_point_cubic_smooth_inplace(y, 9, 1, -1) == Status::InvalidArgument);
}

TEST_CASE("smoothing keeps a cubic exactly (least-squares cubic fit)") {
  double y[12];
  for (int k = 0; k < 12; ++k) y[k] = 0.5 * k * k * k - 2.0 * k * k + k - 3.0;
  double orig[12];
  std::copy(y, y + 12, orig);
  REQUIRE(five_point_cubic_smooth_inplace(y, 12, 1, 3) == Status::Ok);
  for (int k = 0; k < 12; ++k) CHECK(y[k] == doctest::Approx(orig[k]).epsilon(1e-12));
}

TEST_CASE("min-max scaling round trip and constant column") {
  double x[6] = {1, 5, 3, 5, 2, 5};  // 3 samples x 2 channels; channel 1 constant
  double lo[2], hi[2];
  REQUIRE(minmax_fit(x, 3, 2, lo, hi) == Status::Ok);
  CHECK(lo[0] == 1);
  CHECK(hi[0] == 3);
  minmax_apply(x, 3, 2, lo, hi, false);
  CHECK(x[0] == -1);
  CHECK(x[2] == 1);
  CHECK(x[4] == 0);
  CHECK(x[1] == 0);
  minmax_apply(x, 3, 2, lo, hi, true);
  CHECK(x[4] == doctest::Approx(2));
  CHECK(x[5] == 5);
}

TEST_CASE("rng: xoshiro128** recurrence and ranges") {
  Rng a(7), b(7), c(8);
  CHECK(a.next_u32() == b.next_u32());
  CHECK(a.next_u32() != c.next_u32());
  for (int k = 0; k < 1000; ++k) {
    const double u = a.uniform<double>();
    CHECK((u >= 0.0 && u < 1.0));
    CHECK(a.index(7) < 7u);
  }
}

namespace {
template <typename Net>
void finite_difference_jacobian_check(const Net& net, std::vector<double> theta, const double* x) {
  const Index m = net.outputs(), D = net.num_params();
  std::vector<double> J(m * D), hid(net.hidden()), yp(m), ym(m);
  net.jacobian(theta.data(), x, hid.data(), J.data());
  for (Index p = 0; p < D; ++p) {
    const double h = 1e-6, keep = theta[p];
    theta[p] = keep + h;
    net.forward(theta.data(), x, hid.data(), yp.data());
    theta[p] = keep - h;
    net.forward(theta.data(), x, hid.data(), ym.data());
    theta[p] = keep;
    for (Index k = 0; k < m; ++k)
      CHECK(J[p * m + k] == doctest::Approx((yp[k] - ym[k]) / (2 * h)).epsilon(1e-6).scale(1.0));
  }
}
}  // namespace

TEST_CASE("network Jacobian equals central finite differences") {
  Rng rng(3);
  for (Activation act : {Activation::Tansig, Activation::Logsig}) {
    Mlp<double> net(3, 4, 2, act);
    std::vector<double> theta(net.num_params());
    for (auto& v : theta) v = rng.uniform(-1.0, 1.0);
    const double x[3] = {0.3, -0.7, 0.2};
    finite_difference_jacobian_check(net, theta, x);
  }
}

TEST_CASE("structured J'J and J'e equal those formed from the explicit Jacobian") {
  Rng rng(11);
  // n > 2 blocks of 256 and two threads; h = 10 and 13 pad the fused blocks to 12 and 16 rows;
  // the reduced J'J (host::jtj_reduced) and the gradient pass (host::grad_block) at sizes whose
  // pair counts and outputs are not multiples of 4 or 8, both activations
  struct Size { Index i, m; Activation act; };
  for (const Index h : {1, 5, 10, 13, 20})
  for (const Size sz : {Size{3, 2, Activation::Tansig}, Size{1, 5, Activation::Logsig},
                        Size{6, 1, Activation::Tansig}, Size{2, 8, Activation::Logsig}}) {
    const Index i = sz.i, m = sz.m, n = 700;
    CAPTURE(h);
    CAPTURE(i);
    CAPTURE(m);
    Mlp<double> net(i, h, m, sz.act);
    const Index D = net.num_params();
    Eigen::MatrixXd X(i, n), T(m, n);
    for (Index k = 0; k < X.size(); ++k) X.data()[k] = rng.uniform(-1.0, 1.0);
    for (Index k = 0; k < T.size(); ++k) T.data()[k] = rng.uniform(-1.0, 1.0);
    Eigen::VectorXd theta(D);
    for (Index k = 0; k < D; ++k) theta[k] = rng.uniform(-1.0, 1.0);
    Eigen::MatrixXd Jn(m, D), JtJ = Eigen::MatrixXd::Zero(D, D);
    Eigen::VectorXd Jte = Eigen::VectorXd::Zero(D), hid(h), y(m);
    Eigen::MatrixXd Yref(m, n);
    double sse = 0;
    for (Index s = 0; s < n; ++s) {
      net.jacobian(theta.data(), X.col(s).data(), hid.data(), Jn.data());
      net.forward(theta.data(), X.col(s).data(), hid.data(), y.data());
      Yref.col(s) = y;
      const Eigen::VectorXd e = T.col(s) - y;
      JtJ += Jn.transpose() * Jn;
      Jte += Jn.transpose() * e;
      sse += e.squaredNorm();
    }
    for (int threads : {1, 2}) {
      NormalEquations<double> ne(net, 256, threads);
      Eigen::VectorXd jte;
      Eigen::MatrixXd jtj;
      NormalEquations<double>::ConstMap Xm(X.data(), i, n), Tm(T.data(), m, n);
      const double s2 = ne.evaluate(theta.data(), Xm, Tm, &jte, &jtj);
      CHECK(s2 == doctest::Approx(sse).epsilon(1e-12));
      CHECK((jtj - JtJ).cwiseAbs().maxCoeff() <= 1e-11 * JtJ.cwiseAbs().maxCoeff());
      CHECK((jte - Jte).cwiseAbs().maxCoeff() <= 1e-11 * Jte.cwiseAbs().maxCoeff());
      Eigen::MatrixXd Y(m, n);
      ne.predict(theta.data(), Xm, Eigen::Map<Eigen::MatrixXd>(Y.data(), m, n));
      CHECK((Y - Yref).cwiseAbs().maxCoeff() <= 1e-13);
    }
  }
}

TEST_CASE("LM fits a network to data made by a known network") {
  Rng rng(5);
  const Index i = 2, h = 3, m = 1, n = 400;
  Mlp<double> net(i, h, m);
  Eigen::VectorXd truth(net.num_params()), theta(net.num_params());
  for (Index k = 0; k < truth.size(); ++k) truth[k] = rng.uniform(-1.0, 1.0);
  for (Index k = 0; k < theta.size(); ++k) theta[k] = truth[k] + 0.3 * rng.uniform(-1.0, 1.0);
  Eigen::MatrixXd X(i, n), T(m, n);
  Eigen::VectorXd hid(h);
  for (Index k = 0; k < X.size(); ++k) X.data()[k] = rng.uniform(-1.0, 1.0);
  for (Index s = 0; s < n; ++s) net.forward(truth.data(), X.col(s).data(), hid.data(), T.col(s).data());
  NormalEquations<double>::ConstMap Xm(X.data(), i, n), Tm(T.data(), m, n);
  LmOptions o;
  o.epochs = 200;
  o.goal = 1e-20;
  TrainHistory hist;
  REQUIRE(train_lm<double>(net, theta.data(), Xm, Tm, nullptr, nullptr, o, hist) == Status::Ok);
  CHECK(hist.mse.back() < 1e-12);
  for (size_t e = 1; e < hist.mse.size(); ++e) CHECK(hist.mse[e] <= hist.mse[e - 1]);
}

TEST_CASE("fixed-size forward, Jacobian, smoothing and NARX allocate nothing") {
  using Net = Mlp<float, 6, 20, 8>;
  Net net;
  std::array<float, Net::kParams> theta{};
  Rng rng(1);
  for (auto& v : theta) v = rng.uniform(-1.0f, 1.0f);
  std::array<float, 6> x{0.1f, -0.2f, 0.3f, -0.4f, 0.5f, -0.6f};
  std::array<float, 20> hid{};
  std::array<float, 8> y{};
  std::array<float, 8 * Net::kParams> J{};
  std::array<float, 64> sig{};
  for (size_t k = 0; k < sig.size(); ++k) sig[k] = std::sin(0.1f * k);
  Mlp<float, 4, 8, 2> narx_net;  // na = 1, nb = 1 with 2 inputs and 2 outputs
  std::array<float, Mlp<float, 4, 8, 2>::kParams> th2{};
  for (auto& v : th2) v = rng.uniform(-0.3f, 0.3f);
  std::array<float, 2 * 32> U{}, Y{};
  std::array<float, 4> reg{};
  std::array<float, 8> hid2{};
  Eigen::internal::set_is_malloc_allowed(false);
  net.forward(theta.data(), x.data(), hid.data(), y.data());
  net.jacobian(theta.data(), x.data(), hid.data(), J.data());
  const Status s = five_point_cubic_smooth_inplace(sig.data(), 64, 1, 5);
  const Status s2 = narx_simulate(narx_net, th2.data(), U.data(), Y.data(), 32, 2, NarxOrders{1, 1, 0},
                                  reg.data(), hid2.data());
  Eigen::internal::set_is_malloc_allowed(true);
  CHECK(s == Status::Ok);
  CHECK(s2 == Status::Ok);
  CHECK(std::isfinite(y[0]));
}

TEST_CASE("multi-channel smoothing equals per-channel smoothing, heap-free") {
  constexpr int n = 23, C = 3;
  std::array<double, n * C> rows{}, cols{};
  for (int k = 0; k < n * C; ++k) rows[k] = cols[k] = std::sin(0.37 * k) * (k % 7);
  std::array<double, 3 * C> work{};
  Eigen::internal::set_is_malloc_allowed(false);
  const Status s = five_point_cubic_smooth_rows(rows.data(), n, C, 4, work.data());
  Eigen::internal::set_is_malloc_allowed(true);
  REQUIRE(s == Status::Ok);
  for (int c = 0; c < C; ++c) REQUIRE(five_point_cubic_smooth_inplace(cols.data() + c, n, C, 4) == Status::Ok);
  for (int k = 0; k < n * C; ++k) CHECK(rows[k] == cols[k]);
}
