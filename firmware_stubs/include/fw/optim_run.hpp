// Check (3), second half: a small IBOA-BP run with fixed sizes, the same code on the board and
// on the host. 20 butterflies (cdam/optim/iboa.hpp, Swarm<float, 58, 20>) search the weights of
// a 4-8-2 tansig network (cdam::Mlp with FastActivation, pure float arithmetic) on the 200
// samples of generated/optim_data.hpp (flash on the target); the best butterfly then seeds
// kLmEpochs Levenberg-Marquardt epochs (cdam/lm_fixed.hpp). Shared random generator seed kSeed.
// Nothing allocates: the Swarm and the LM workspace live in a caller-owned Workspace (static).
//
// The fitness is MseFitness below: the semantics of cdam::optim::MlpFitness
// (cdam/optim/bp_fitness.hpp; MSE = sum over samples of Mlp::forward's squared errors, in Scalar,
// divided by n m). It is not taken from bp_fitness.hpp because that header also holds the host's
// threaded BpFitness and includes <mutex>, <condition_variable> and <thread>; arm-none-eabi's
// newlib has no gthreads, so std::mutex is undeclared there and the include fails to compile.
#pragma once
#include <cstdint>

#include "cdam/fast_math.hpp"
#include "cdam/lm_fixed.hpp"
#include "cdam/optim/iboa.hpp"
#include "optim_data.hpp"

namespace fw::optim_run {

using Net = cdam::Mlp<float, 4, 8, 2, cdam::FastActivation>;
constexpr int kD = Net::kParams;  // 58
constexpr int kPop = 20;
constexpr int kIterations = 20;
constexpr int kLmEpochs = 5;
constexpr std::uint32_t kSeed = 7;
constexpr int kCurveMax = kIterations + 1 + kLmEpochs + 1;
static_assert(cdam_optim_data::kInputs == Net::kInputs && cdam_optim_data::kOutputs ==
              Net::kOutputs, "generated/optim_data.hpp: sizes differ from the network");

// Fitness concept of cdam/optim/swarm.hpp on caller-owned data (X: i x n, T: m x n, one sample
// per column), no heap.
template <typename NetT>
class MseFitness {
 public:
  using Scalar = typename NetT::Scalar;
  MseFitness(const NetT& net, const Scalar* X, const Scalar* T, cdam::Index n)
      : net_(net), X_(X), T_(T), n_(n) {}
  Scalar operator()(const Scalar* theta) {
    Scalar sse = 0;
    for (cdam::Index s = 0; s < n_; ++s) {
      net_.forward(theta, X_ + s * NetT::kInputs, a_, y_);
      for (int k = 0; k < NetT::kOutputs; ++k) {
        const Scalar e = T_[s * NetT::kOutputs + k] - y_[k];
        sse += e * e;
      }
    }
    return sse / static_cast<Scalar>(n_ * NetT::kOutputs);
  }
  void batch(const Scalar* thetas, cdam::Index count, Scalar* out) {
    for (cdam::Index k = 0; k < count; ++k) out[k] = (*this)(thetas + k * NetT::kParams);
  }

 private:
  NetT net_;
  const Scalar* X_;
  const Scalar* T_;
  cdam::Index n_;
  Scalar a_[NetT::kHidden], y_[NetT::kOutputs];
};

struct Workspace {
  cdam::optim::Swarm<float, kD, kPop> swarm;
  cdam::LmFixed<Net> lm;
  float theta[kD];  // the trained weights at the end of run()
};

struct Result {
  cdam::Status status = cdam::Status::Ok;
  int curve_len = 0;     // kIterations + 1 IBOA values, then the recorded LM epochs
  long evaluations = 0;  // fitness evaluations of the IBOA part
  int lm_epochs = 0;     // LM epochs recorded (kLmEpochs + 1 unless it stopped early)
};

// curve: kCurveMax values. curve[0..kIterations] = the IBOA best MSE after initialisation and
// after each iteration; then the LM MSE at each recorded epoch (the first is the IBOA best,
// re-evaluated in double by the LM).
inline Result run(Workspace& w, double* curve) {
  Result res;
  const Net net;
  MseFitness<Net> fitness(net, cdam_optim_data::kX, cdam_optim_data::kT,
                                       cdam_optim_data::kSamples);
  cdam::optim::IboaOptions opt;
  opt.boa.iterations = kIterations;
  cdam::optim::Iboa<float, kD, kPop> iboa(opt);
  cdam::Rng rng(kSeed);
  res.status = iboa.run(w.swarm, fitness, rng, curve);
  if (res.status != cdam::Status::Ok) return res;
  res.evaluations = w.swarm.evaluations;
  res.curve_len = kIterations + 1;
  cdam::LmOptions lo;
  lo.epochs = kLmEpochs;
  for (int k = 0; k < kD; ++k) w.theta[k] = w.swarm.best[k];
  res.status = w.lm.train(w.theta, cdam_optim_data::kX, cdam_optim_data::kT,
                          cdam_optim_data::kSamples, lo, curve + res.curve_len, nullptr,
                          &res.lm_epochs, nullptr);
  res.curve_len += res.lm_epochs;
  return res;
}

}  // namespace fw::optim_run
