// Same result whatever the thread count (issue 24 item 7): NormalEquations' sse / J'e / J'J,
// BpFitness' SSE, train_lm and train_gd give bit-identical results at 1, 2 and 3 threads, for
// records just below and above the size where threading starts (1,023 / 1,024 samples) and
// for longer, uneven ones (5,000, 10,007). Equality is checked bit by bit (memcmp), and the
// 1-thread result is itself checked against an independent per-sample sum (Mlp::forward and
// Mlp::jacobian, J'J = sum Jn' Jn), so a result that is equal because it is wrong fails too.
#include <doctest/doctest.h>

#include <Eigen/Core>
#include <cstring>
#include <vector>

#include "cdam/host/bp_fitness.hpp"
#include "cdam/host/normal_equations.hpp"
#include "cdam/host/training.hpp"
#include "cdam/mlp.hpp"
#include "cdam/optim/mlp_fitness.hpp"
#include "cdam/rng.hpp"

using namespace cdam;
using Map = NormalEquations<double>::ConstMap;

namespace {

const Index kSizes[] = {1023, 1024, 5000, 10007};
const int kThreads[] = {1, 2, 3};

bool same_bits(const double* a, const double* b, Index n) {
  return std::memcmp(a, b, static_cast<size_t>(n) * sizeof(double)) == 0;
}
bool same_bits(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() && same_bits(a.data(), b.data(), static_cast<Index>(a.size()));
}

struct Problem {
  Mlp<double> net;
  Eigen::MatrixXd X, T;
  Eigen::VectorXd theta;
  Problem(Index i, Index h, Index m, Index n, std::uint32_t seed) : net(i, h, m), X(i, n), T(m, n) {
    Rng rng(seed);
    for (Index k = 0; k < X.size(); ++k) X.data()[k] = rng.uniform(-1.0, 1.0);
    for (Index k = 0; k < T.size(); ++k) T.data()[k] = rng.uniform(-1.0, 1.0);
    theta.resize(net.num_params());
    for (Index k = 0; k < theta.size(); ++k) theta[k] = rng.uniform(-1.0, 1.0);
  }
  Map Xm() const { return Map(X.data(), X.rows(), X.cols()); }
  Map Tm() const { return Map(T.data(), T.rows(), T.cols()); }
};

struct Normal {
  double sse, sse_only;
  Eigen::VectorXd jte;
  Eigen::MatrixXd jtj;
};

Normal normal_at(const Problem& p, int threads) {
  NormalEquations<double> ne(p.net, 256, threads);
  Normal r;
  r.sse = ne.evaluate(p.theta.data(), p.Xm(), p.Tm(), &r.jte, &r.jtj);
  r.sse_only = ne.evaluate(p.theta.data(), p.Xm(), p.Tm(), nullptr, nullptr);
  return r;
}

}  // namespace

TEST_CASE("NormalEquations: sse, J'e and J'J bit-identical at 1, 2 and 3 threads") {
  for (Index n : kSizes) {
    CAPTURE(n);
    const Problem p(4, 6, 3, n, 11);
    const Normal r1 = normal_at(p, 1);
    // the 1-thread result against the per-sample sums (long double accumulation)
    const Index D = p.net.num_params();
    Eigen::MatrixXd Jn(3, D);
    Eigen::Matrix<long double, Eigen::Dynamic, Eigen::Dynamic> JtJ = decltype(JtJ)::Zero(D, D);
    Eigen::Matrix<long double, Eigen::Dynamic, 1> Jte = decltype(Jte)::Zero(D);
    Eigen::VectorXd hid(6), y(3);
    long double sse = 0;
    for (Index s = 0; s < n; ++s) {
      p.net.jacobian(p.theta.data(), p.X.col(s).data(), hid.data(), Jn.data());
      p.net.forward(p.theta.data(), p.X.col(s).data(), hid.data(), y.data());
      const Eigen::VectorXd e = p.T.col(s) - y;
      JtJ += (Jn.transpose() * Jn).cast<long double>();
      Jte += (Jn.transpose() * e).cast<long double>();
      sse += static_cast<long double>(e.squaredNorm());
    }
    const Eigen::MatrixXd JtJd = JtJ.cast<double>();
    const Eigen::VectorXd Jted = Jte.cast<double>();
    CHECK(r1.sse == doctest::Approx(static_cast<double>(sse)).epsilon(1e-12));
    // the SSE-only pass (double) is the vectorised kernel: its own summation order
    CHECK(r1.sse_only == doctest::Approx(static_cast<double>(sse)).epsilon(1e-12));
    CHECK((r1.jtj - JtJd).cwiseAbs().maxCoeff() <= 1e-11 * JtJd.cwiseAbs().maxCoeff());
    CHECK((r1.jte - Jted).cwiseAbs().maxCoeff() <= 1e-11 * Jted.cwiseAbs().maxCoeff());
    for (int t : kThreads) {
      CAPTURE(t);
      const Normal r = normal_at(p, t);
      CHECK(same_bits(&r.sse, &r1.sse, 1));
      CHECK(same_bits(&r.sse_only, &r1.sse_only, 1));
      REQUIRE(r.jte.size() == D);
      REQUIRE(r.jtj.rows() == D);
      CHECK(same_bits(r.jte.data(), r1.jte.data(), D));
      CHECK(same_bits(r.jtj.data(), r1.jtj.data(), D * D));
    }
  }
}

TEST_CASE("NormalEquations: the paper's 6-20-8 network, bit-identical J'J at 1, 2 and 3 threads") {
  for (Index n : {Index(1024), Index(10007)}) {
    CAPTURE(n);
    const Problem p(6, 20, 8, n, 12);
    const Normal r1 = normal_at(p, 1);
    const Index D = p.net.num_params();
    for (int t : {2, 3}) {
      CAPTURE(t);
      const Normal r = normal_at(p, t);
      CHECK(same_bits(&r.sse, &r1.sse, 1));
      CHECK(same_bits(r.jte.data(), r1.jte.data(), D));
      CHECK(same_bits(r.jtj.data(), r1.jtj.data(), D * D));
    }
  }
}

TEST_CASE("BpFitness: SSE bit-identical at 1, 2 and 3 threads and equal to the per-sample MSE") {
  for (Index n : kSizes) {
    CAPTURE(n);
    const Problem p(4, 6, 3, n, 13);
    const Index D = p.net.num_params();
    Eigen::MatrixXd thetas(D, 5);
    Rng rng(14);
    for (Index k = 0; k < thetas.size(); ++k) thetas.data()[k] = rng.uniform(-1.0, 1.0);
    optim::MlpFitness<Mlp<double>> ref(p.net, p.X.data(), p.T.data(), n);
    double o1[5];
    {
      optim::BpFitness<double> f(p.net, p.Xm(), p.Tm(), 1);
      f.batch(thetas.data(), 5, o1);
    }
    for (int k = 0; k < 5; ++k)
      CHECK(o1[k] == doctest::Approx(ref(thetas.col(k).data())).epsilon(1e-12));
    for (int t : kThreads) {
      CAPTURE(t);
      optim::BpFitness<double> f(p.net, p.Xm(), p.Tm(), t);
      double o[5];
      f.batch(thetas.data(), 5, o);
      CHECK(same_bits(o, o1, 5));
      const double one = f(thetas.col(2).data());
      CHECK(same_bits(&one, &o1[2], 1));
    }
  }
}

TEST_CASE("train_lm and train_gd: weights and histories bit-identical at 1, 2 and 3 threads") {
  for (Index n : kSizes) {
    CAPTURE(n);
    const Problem p(4, 6, 3, n, 15);
    const Index D = p.net.num_params();
    // a validation set of its own size, so that val_mse is threaded too
    const Problem v(4, 6, 3, n, 16);
    const Map Xv = v.Xm(), Tv = v.Tm();
    LmOptions o;
    o.epochs = 6;
    o.min_grad = 0;
    std::vector<double> theta1;
    TrainHistory h1, g1;
    std::vector<double> gtheta1;
    for (int t : kThreads) {
      CAPTURE(t);
      o.threads = t;
      std::vector<double> theta(p.theta.data(), p.theta.data() + D);
      TrainHistory h;
      REQUIRE(train_lm<double>(p.net, theta.data(), p.Xm(), p.Tm(), &Xv, &Tv, o, h) == Status::Ok);
      std::vector<double> gtheta(p.theta.data(), p.theta.data() + D);
      TrainHistory g;
      REQUIRE(train_gd<double>(p.net, gtheta.data(), p.Xm(), p.Tm(), 1e-3, 5, 0.0, g, t) ==
              Status::Ok);
      if (t == 1) {
        // the run did something: 7 recorded epochs, a decreasing training MSE
        REQUIRE(h.mse.size() == 7);
        CHECK(h.mse.back() < h.mse.front());
        CHECK(g.mse.back() < g.mse.front());
        theta1 = theta;
        h1 = h;
        gtheta1 = gtheta;
        g1 = g;
        continue;
      }
      CHECK(same_bits(theta, theta1));
      CHECK(same_bits(h.mse, h1.mse));
      CHECK(same_bits(h.mu, h1.mu));
      CHECK(same_bits(h.grad_norm, h1.grad_norm));
      CHECK(same_bits(h.val_mse, h1.val_mse));
      CHECK(h.best_epoch == h1.best_epoch);
      CHECK(h.stop == h1.stop);
      CHECK(same_bits(gtheta, gtheta1));
      CHECK(same_bits(g.mse, g1.mse));
    }
  }
}

TEST_CASE("NormalEquations<float> (the float kernels on AVX2 + FMA, Eigen's products otherwise): bit-identical") {
  for (Index n : kSizes) {
    CAPTURE(n);
    const Problem p(4, 6, 3, n, 17);
    const Eigen::MatrixXf X = p.X.cast<float>(), T = p.T.cast<float>();
    const Eigen::VectorXf theta = p.theta.cast<float>();
    NormalEquations<float>::ConstMap Xm(X.data(), X.rows(), n), Tm(T.data(), T.rows(), n);
    const Index D = p.net.num_params();
    Mlp<float> net(4, 6, 3);
    double s1 = 0;
    Eigen::VectorXf jte1;
    Eigen::MatrixXf jtj1;
    for (int t : kThreads) {
      CAPTURE(t);
      NormalEquations<float> ne(net, 256, t);
      Eigen::VectorXf jte;
      Eigen::MatrixXf jtj;
      const double s = ne.evaluate(theta.data(), Xm, Tm, &jte, &jtj);
      REQUIRE(jtj.rows() == D);
      if (t == 1) {
        // against the double result of the same data (float rounding only)
        const Normal r = normal_at(p, 1);
        CHECK(s == doctest::Approx(r.sse).epsilon(1e-4));
        CHECK((jtj.cast<double>() - r.jtj).cwiseAbs().maxCoeff() <= 1e-4 * r.jtj.cwiseAbs().maxCoeff());
        s1 = s;
        jte1 = jte;
        jtj1 = jtj;
        continue;
      }
      CHECK(std::memcmp(&s, &s1, sizeof s) == 0);
      CHECK(std::memcmp(jte.data(), jte1.data(), sizeof(float) * D) == 0);
      CHECK(std::memcmp(jtj.data(), jtj1.data(), sizeof(float) * D * D) == 0);
    }
  }
}
