// The BP network: one hidden layer (tansig or logsig), linear output, one flat parameter vector
// theta = [W1(:); b1; W2(:); b2] in MATLAB's column-major order (W1: h x i, W2: m x h),
// D = i h + h + h m + m.
//
// Sizes are template parameters: Eigen::Dynamic for Python, fixed for the target. Every method
// here works on caller-owned buffers and allocates nothing (checked by a test with
// EIGEN_RUNTIME_NO_MALLOC and by the firmware link).
#pragma once
#include <Eigen/Core>
#include <cstddef>

#include "activation.hpp"
#include "safe_size.hpp"
#include "status.hpp"

namespace cdam {

using Index = Eigen::Index;

constexpr int mlp_params(int i, int h, int m) {
  return (i == Eigen::Dynamic || h == Eigen::Dynamic || m == Eigen::Dynamic)
             ? Eigen::Dynamic
             : i * h + h + h * m + m;
}

// D = i h + h + h m + m for run-time sizes, checked (safe_size.hpp): InvalidArgument when a size
// is below 1, Overflow when D does not fit in Index. Run-time sizes given to an Mlp must have
// passed this; Mlp::num_params() itself does not check.
inline Status mlp_num_params(Index i, Index h, Index m, Index* D) {
  if (i < 1 || h < 1 || m < 1) return Status::InvalidArgument;
  using C = Checked<Index>;
  return (C(i) * h + h + C(h) * m + m).get(D);
}

// ActFn: the activation policy (static Scalar apply(Activation, Scalar)); ExactActivation uses
// std::tanh / std::exp, the target may pass cdam::FastActivation (fast_math.hpp).
template <typename Scalar_, int I = Eigen::Dynamic, int H = Eigen::Dynamic, int O = Eigen::Dynamic,
          typename ActFn = ExactActivation>
class Mlp {
 public:
  using Scalar = Scalar_;
  static constexpr int kInputs = I, kHidden = H, kOutputs = O, kParams = mlp_params(I, H, O);
  using W1Map = Eigen::Map<const Eigen::Matrix<Scalar, H, I>>;  // h x i
  using B1Map = Eigen::Map<const Eigen::Matrix<Scalar, H, 1>>;  // h
  using W2Map = Eigen::Map<const Eigen::Matrix<Scalar, O, H>>;  // m x h
  using B2Map = Eigen::Map<const Eigen::Matrix<Scalar, O, 1>>;  // m

  Mlp(Index inputs = I, Index hidden = H, Index outputs = O, Activation act = Activation::Tansig)
      : i_(inputs), h_(hidden), m_(outputs), act_(act) {}

  Index inputs() const { return i_; }
  Index hidden() const { return h_; }
  Index outputs() const { return m_; }
  Index num_params() const { return i_ * h_ + h_ + h_ * m_ + m_; }
  Activation activation() const { return act_; }

  // Offsets of the four blocks inside theta.
  Index off_b1() const { return i_ * h_; }
  Index off_w2() const { return i_ * h_ + h_; }
  Index off_b2() const { return i_ * h_ + h_ + h_ * m_; }

  W1Map W1(const Scalar* theta) const { return W1Map(theta, h_, i_); }
  B1Map b1(const Scalar* theta) const { return B1Map(theta + off_b1(), h_); }
  W2Map W2(const Scalar* theta) const { return W2Map(theta + off_w2(), m_, h_); }
  B2Map b2(const Scalar* theta) const { return B2Map(theta + off_b2(), m_); }

  // One sample. x: i values; a: h values of caller storage (receives the hidden activations);
  // y: m values.
  void forward(const Scalar* theta, const Scalar* x, Scalar* a, Scalar* y) const {
    Eigen::Map<const Eigen::Matrix<Scalar, I, 1>> xv(x, i_);
    Eigen::Map<Eigen::Matrix<Scalar, H, 1>> av(a, h_);
    Eigen::Map<Eigen::Matrix<Scalar, O, 1>> yv(y, m_);
    av.noalias() = W1(theta).lazyProduct(xv);
    av += b1(theta);
    for (Index j = 0; j < h_; ++j) av[j] = ActFn::apply(act_, av[j]);
    yv.noalias() = W2(theta).lazyProduct(av);
    yv += b2(theta);
  }

  // Jacobian of the m outputs of one sample with respect to theta, written column-major into
  // J (m x D, leading dimension m). a: h values of caller storage.
  void jacobian(const Scalar* theta, const Scalar* x, Scalar* a, Scalar* J) const {
    Eigen::Map<const Eigen::Matrix<Scalar, I, 1>> xv(x, i_);
    Eigen::Map<Eigen::Matrix<Scalar, H, 1>> av(a, h_);
    av.noalias() = W1(theta).lazyProduct(xv);
    av += b1(theta);
    for (Index j = 0; j < h_; ++j) av[j] = ActFn::apply(act_, av[j]);
    const W2Map w2 = W2(theta);
    Eigen::Map<Eigen::Matrix<Scalar, O, Eigen::Dynamic>> Jm(J, m_, num_params());
    // hidden block: dy_k / d[W1 b1](j, l) = W2(k, j) f'(a_j) z_l, z = [x; 1], index l h + j
    for (Index l = 0; l <= i_; ++l) {
      const Scalar zl = l < i_ ? xv[l] : Scalar(1);
      const Index col0 = l < i_ ? l * h_ : off_b1();
      for (Index j = 0; j < h_; ++j) {
        const Scalar dj = activation_slope(act_, av[j]) * zl;
        for (Index k = 0; k < m_; ++k) Jm(k, col0 + j) = w2(k, j) * dj;
      }
    }
    // output block: dy_k / d[W2 b2](k', j) = delta_kk' a'_j, a' = [a; 1], index j m + k'
    for (Index j = 0; j <= h_; ++j) {
      const Scalar aj = j < h_ ? av[j] : Scalar(1);
      const Index col0 = j < h_ ? off_w2() + j * m_ : off_b2();
      for (Index k2 = 0; k2 < m_; ++k2)
        for (Index k = 0; k < m_; ++k) Jm(k, col0 + k2) = k == k2 ? aj : Scalar(0);
    }
  }

 private:
  Index i_, h_, m_;
  Activation act_;
};

}  // namespace cdam
