// Check (3), second half: a small IBOA-BP run with fixed sizes, the same code on the board and
// on the host. 20 butterflies (cdam/optim/iboa.hpp, Swarm<float, 58, 20>) search the weights of
// a 4-8-2 tansig network (cdam::Mlp with FastActivation, pure float arithmetic) on the 200
// samples of generated/optim_data.hpp (flash on the target); the best butterfly then seeds
// kLmEpochs Levenberg-Marquardt epochs (the core's one LM loop, cdam/levenberg_marquardt.hpp,
// with its fixed-size policy cdam/lm_fixed.hpp). Shared random generator seed kSeed. The
// fitness is the core's cdam::optim::MlpFitness (cdam/optim/mlp_fitness.hpp). Nothing
// allocates: the Swarm and the LM workspace live in a caller-owned Workspace (static).
#pragma once
#include <cstdint>

#include "cdam/fast_math.hpp"
#include "cdam/lm_fixed.hpp"
#include "cdam/optim/iboa.hpp"
#include "cdam/optim/mlp_fitness.hpp"
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
  cdam::optim::MlpFitness<Net> fitness(net, cdam_optim_data::kX, cdam_optim_data::kT,
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
