// Hidden-layer activations of the BP network and their derivatives written in terms of the
// activation value a: tansig a = tanh(n), da/dn = 1 - a^2; logsig a = 1 / (1 + exp(-n)),
// da/dn = a (1 - a).
#pragma once
#include <cmath>

namespace cdam {

enum class Activation { Tansig = 0, Logsig = 1 };

template <typename Scalar>
inline Scalar activate(Activation act, Scalar n) {
  return act == Activation::Tansig ? std::tanh(n) : Scalar(1) / (Scalar(1) + std::exp(-n));
}

// Activation policy of Mlp (its ActFn template parameter): the exact functions above. Other
// policies (cdam/fast_math.hpp: FastActivation) provide the same static apply(act, n).
struct ExactActivation {
  template <typename Scalar>
  static Scalar apply(Activation act, Scalar n) { return activate(act, n); }
};

template <typename Scalar>
inline Scalar activation_slope(Activation act, Scalar a) {
  return act == Activation::Tansig ? Scalar(1) - a * a : a * (Scalar(1) - a);
}

}  // namespace cdam
