// The identified model on the target: min-max scaling (cdam/scaling.hpp), the core's fixed-size
// cdam::Mlp forward with the fast activation (cdam/mlp.hpp + cdam/fast_math.hpp), back-scaling.
// The weights come from generated/model.hpp (`cdam export-firmware`). No heap, no libm.
#pragma once
#include <cstdint>

#include "cdam/fast_math.hpp"
#include "cdam/mlp.hpp"
#include "cdam/scaling.hpp"
#include "model.hpp"

namespace fw {

constexpr int kIn = cdam_model::kInputs;
constexpr int kHid = cdam_model::kHidden;
constexpr int kOut = cdam_model::kOutputs;
// CDAM_FW_EXACT_ACTIVATION (the fw_check_exact reference image of the benchmark): std::tanh /
// std::exp from newlib instead of the fast rational activation.
#ifdef CDAM_FW_EXACT_ACTIVATION
using Activation = cdam::ExactActivation;
#else
using Activation = cdam::FastActivation;
#endif
using Net = cdam::Mlp<float, kIn, kHid, kOut, Activation>;
static_assert(Net::kParams == cdam_model::kParams, "generated model: parameter count mismatch");

// Normalised in, normalised out: the network alone.
inline void infer_normalised(const float* xn, float* yn) {
  const Net net(kIn, kHid, kOut,
                cdam_model::kTansig ? cdam::Activation::Tansig : cdam::Activation::Logsig);
  float hidden[kHid];
  net.forward(cdam_model::kTheta, xn, hidden, yn);
}

// Physical in, physical out.
inline void predict(const float* x, float* y) {
  float xn[kIn], yn[kOut];
  for (int k = 0; k < kIn; ++k)
    xn[k] = cdam::minmax_forward(x[k], cdam_model::kXMin[k], cdam_model::kXMax[k]);
  infer_normalised(xn, yn);
  for (int k = 0; k < kOut; ++k)
    y[k] = cdam::minmax_inverse(yn[k], cdam_model::kYMin[k], cdam_model::kYMax[k]);
}

// FNV-1a of the weights as stored in flash (equals cdam_model::kThetaFnv1a when intact).
inline std::uint32_t theta_fnv1a() {
  std::uint32_t h = 0x811C9DC5u;
  const auto* p = reinterpret_cast<const unsigned char*>(cdam_model::kTheta);
  for (unsigned k = 0; k < sizeof(cdam_model::kTheta); ++k) h = (h ^ p[k]) * 0x01000193u;
  return h;
}

}  // namespace fw
