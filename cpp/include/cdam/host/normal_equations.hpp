// Batch evaluation of the BP network on a record: sum of squared errors, J'e and J'J, computed in
// blocks of samples so that memory does not grow with the record length, and without forming J.
//
// Structure used (z = [x; 1], a' = [a; 1], d = f'(a), Q = W2' W2, hidden parameters ordered
// l h + j for [W1 b1](j, l), output parameters j m + k for [W2 b2](k, j)):
//   J'J hidden-hidden  (l h + j, l' h + j') = Q(j, j') * S(l h + j, l' h + j'),  S = sum_n v v',
//                      v = kron(z, d)                                     (h(i+1))^2 per sample
//   J'J output-output  (j m + k, j' m + k') = delta(k, k') R(j, j'),      R = sum_n a' a'^T
//   J'J output-hidden  (j'' m + k, l h + j) = W2(k, j) C(j'', l h + j),   C = sum_n a' v'
//   J'e hidden = vec(sum_n ((W2' e) .* d) z'),  J'e output = vec(sum_n e a'^T),  e = t - y.
// Per sample this costs about (h(i+1))^2 / 2 + (h+1) h (i+1) multiply-adds instead of the
// m D^2 of forming J'J from J: for 6-20-8 about 12,700 against 759,000.
//
// On a CPU with AVX2 + FMA (double), S, C and R come from one fused rank update of the stacked
// [v; a] (host/kernels.hpp syrk_lower, about three times Eigen's SSE2 rankUpdate);
// otherwise from Eigen's rankUpdate and product, as written above.
// The hidden activation (double) is the vectorised one of host/kernels.hpp (within 5e-16 of
// std::tanh / the logistic function; about ten times faster than the scalar libm call).
// This is host code: the workspace is allocated once, in the constructor (the one place that
// allocates); evaluate() allocates nothing.
#ifdef CDAM_TARGET_EMBEDDED
#error "cdam/host/normal_equations.hpp is host-only (allocates, std::thread, AVX2 kernels)"
#endif
#pragma once
#include <Eigen/Core>
#include <algorithm>
#include <thread>
#include <type_traits>
#include <vector>

#include "../mlp.hpp"
#include "kernels.hpp"

namespace cdam {

template <typename Scalar>
class NormalEquations {
 public:
  using Mat = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;
  using Vec = Eigen::Matrix<Scalar, Eigen::Dynamic, 1>;
  using ConstMap = Eigen::Map<const Mat>;
  using Net = Mlp<Scalar>;

  explicit NormalEquations(const Net& net, Index block = 256, int threads = 1)
      : net_(net), block_(block), threads_(std::max(1, threads)) {
    workers_.reserve(threads_);
    for (int t = 0; t < threads_; ++t) workers_.emplace_back(net_, block_);
  }

  int threads() const { return threads_; }

  // X: i x N, T: m x N (column = sample). Returns the sum of squared errors; fills Jte (D) when
  // jte is non-null and JtJ (D x D) when jtj is non-null.
  double evaluate(const Scalar* theta, const ConstMap& X, const ConstMap& T, Vec* jte, Mat* jtj) {
    const Index n = X.cols();
    const int nt = n >= 4 * block_ ? threads_ : 1;
    const int mode = jtj ? 2 : (jte ? 1 : 0);
    auto run = [&](int t) {
      const Index lo = n * t / nt, hi = n * (t + 1) / nt;
      workers_[t].run(theta, X, T, lo, hi, mode);
    };
    if (nt == 1) {
      run(0);
    } else {
      std::vector<std::thread> pool;
      for (int t = 1; t < nt; ++t) pool.emplace_back(run, t);
      run(0);
      for (auto& th : pool) th.join();
    }
    for (int t = 1; t < nt; ++t) workers_[0].add(workers_[t], mode);
    Worker& w = workers_[0];
    if (mode >= 1) assemble_gradient(w, *jte);
    if (mode == 2) assemble_jtj(theta, w, *jtj);
    return w.sse;
  }

  // Network outputs Y (m x N) for inputs X (i x N).
  void predict(const Scalar* theta, const ConstMap& X, Eigen::Map<Mat> Y) {
    Worker& w = workers_[0];
    for (Index b0 = 0; b0 < X.cols(); b0 += block_) {
      const Index nb = std::min(block_, X.cols() - b0);
      w.forward(theta, X, b0, nb);
      Y.middleCols(b0, nb) = w.Y.leftCols(nb);
    }
  }

 private:
  struct Worker {
    const Net& net;
    Index i, h, m;
    Mat A, D, Y, E, G, V;      // h x B, h x B, m x B, m x B, h x B, (h(i+1) + h) x B
    Mat S, R, C, gH, gO;       // h(i+1) sq, (h+1) sq, (h+1) x h(i+1), h x (i+1), m x (h+1)
    Mat K;                     // (h(i+1) + h) sq: [v; a] [v; a]' (the fused AVX2 path)
    bool fused;                // double on an AVX2 + FMA CPU: one SYRK gives S, C and R
    double sse = 0.0;

    Worker(const Net& n_, Index B)
        : net(n_), i(n_.inputs()), h(n_.hidden()), m(n_.outputs()),
          A(h, B), D(h, B), Y(m, B), E(m, B), G(h, B), V(h * (i + 1) + h, B),
          S(h * (i + 1), h * (i + 1)), R(h + 1, h + 1), C(h + 1, h * (i + 1)), gH(h, i + 1),
          gO(m, h + 1) {
      if constexpr (std::is_same<Scalar, double>::value) fused = host::avx2_path(host::KernelPath::Auto);
      else fused = false;
      if (fused) K.resize(h * (i + 2), h * (i + 2));
    }

    void forward(const Scalar* theta, const ConstMap& X, Index b0, Index nb) {
      auto a = A.leftCols(nb);
      a.noalias() = net.W1(theta) * X.middleCols(b0, nb);
      a.colwise() += net.b1(theta);
      const Activation act = net.activation();
      if constexpr (std::is_same<Scalar, double>::value)
        host::activate_inplace(a.data(), h * nb, act);  // vectorised, within 5e-16 of std::tanh
      else
        a = a.unaryExpr([act](Scalar v) { return activate(act, v); });
      auto y = Y.leftCols(nb);
      y.noalias() = net.W2(theta) * a;
      y.colwise() += net.b2(theta);
    }

    void run(const Scalar* theta, const ConstMap& X, const ConstMap& T, Index lo, Index hi,
             int mode) {
      sse = 0.0;
      if (mode >= 1) { gH.setZero(); gO.setZero(); }
      if (mode == 2) { S.setZero(); R.setZero(); C.setZero(); if (fused) K.setZero(); }
      const Index P = h * (i + 1);
      const Index B = A.cols();
      const Activation act = net.activation();
      for (Index b0 = lo; b0 < hi; b0 += B) {
        const Index nb = std::min(B, hi - b0);
        forward(theta, X, b0, nb);
        auto e = E.leftCols(nb);
        e = T.middleCols(b0, nb) - Y.leftCols(nb);
        sse += static_cast<double>(e.squaredNorm());
        if (mode == 0) continue;
        auto a = A.leftCols(nb);
        auto d = D.leftCols(nb);
        d = a.unaryExpr([act](Scalar v) { return activation_slope(act, v); });
        auto g = G.leftCols(nb);
        g.noalias() = net.W2(theta).transpose() * e;
        g.array() *= d.array();
        const auto xb = X.middleCols(b0, nb);
        gH.leftCols(i).noalias() += g * xb.transpose();
        gH.col(i) += g.rowwise().sum();
        gO.leftCols(h).noalias() += e * a.transpose();
        gO.col(h) += e.rowwise().sum();
        if (mode < 2) continue;
        auto v = V.topLeftCorner(P, nb);
        for (Index l = 0; l < i; ++l)
          v.middleRows(l * h, h).array() = d.array().rowwise() * xb.row(l).array();
        v.middleRows(i * h, h) = d;
        if constexpr (std::is_same<Scalar, double>::value) {
          if (fused) {
            V.block(P, 0, h, nb) = a;
            host::syrk_lower(K.data(), K.rows(), V.data(), V.rows(), P + h, nb);
          }
        }
        if (!fused) {
          S.template selfadjointView<Eigen::Lower>().rankUpdate(v);
          R.topLeftCorner(h, h).template selfadjointView<Eigen::Lower>().rankUpdate(a);
          C.topRows(h).noalias() += a * v.transpose();
        }
        R.row(h).head(h) += a.rowwise().sum().transpose();
        R(h, h) += Scalar(nb);
        C.row(h) += v.rowwise().sum().transpose();
      }
      if (mode == 2 && fused) {
        S.template triangularView<Eigen::Lower>() = K.topLeftCorner(P, P);
        C.topRows(h) = K.block(P, 0, h, P);
        R.topLeftCorner(h, h).template triangularView<Eigen::Lower>() = K.block(P, P, h, h);
      }
    }

    void add(const Worker& o, int mode) {
      sse += o.sse;
      if (mode >= 1) { gH += o.gH; gO += o.gO; }
      if (mode == 2) { S += o.S; R += o.R; C += o.C; }
    }
  };

  void assemble_gradient(const Worker& w, Vec& jte) const {
    const Index ph = w.h * (w.i + 1), po = w.m * (w.h + 1);
    jte.resize(ph + po);
    jte.head(ph) = Eigen::Map<const Vec>(w.gH.data(), ph);
    jte.tail(po) = Eigen::Map<const Vec>(w.gO.data(), po);
  }

  void assemble_jtj(const Scalar* theta, const Worker& w, Mat& jtj) const {
    const Index i = w.i, h = w.h, m = w.m, ph = h * (i + 1), po = m * (h + 1);
    jtj.resize(ph + po, ph + po);
    const auto W2 = net_.W2(theta);
    const Mat Q = W2.transpose() * W2;  // h x h
    // hidden-hidden (lower triangle of S is valid)
    for (Index c = 0; c < ph; ++c)
      for (Index r = c; r < ph; ++r) {
        const Scalar v = w.S(r, c) * Q(r % h, c % h);
        jtj(r, c) = v;
        jtj(c, r) = v;
      }
    // output-output
    jtj.bottomRightCorner(po, po).setZero();
    for (Index j = 0; j <= h; ++j)
      for (Index j2 = 0; j2 <= h; ++j2) {
        const Scalar v = j >= j2 ? w.R(j, j2) : w.R(j2, j);
        for (Index k = 0; k < m; ++k) jtj(ph + j * m + k, ph + j2 * m + k) = v;
      }
    // output-hidden and its transpose
    for (Index c = 0; c < ph; ++c) {
      const Index jh = c % h;
      for (Index j = 0; j <= h; ++j)
        for (Index k = 0; k < m; ++k) {
          const Scalar v = W2(k, jh) * w.C(j, c);
          jtj(ph + j * m + k, c) = v;
          jtj(c, ph + j * m + k) = v;
        }
    }
  }

  Net net_;
  Index block_;
  int threads_;
  std::vector<Worker> workers_;
};

}  // namespace cdam
