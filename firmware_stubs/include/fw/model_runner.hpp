// The identified model on the target: min-max scaling with precomputed factors, the network on
// weights packed at compile time for one pass in storage order with the fast tanh
// (fw/packed_mlp.hpp: VLDM + VFMA on a Cortex-M4F), back-scaling. The weights come from
// generated/model.hpp (`cdam export-firmware`). No heap, no libm.
#pragma once
#include <cstdint>

#include "cdam/fast_math.hpp"
#include "cdam/mlp.hpp"
#include "fw/packed_mlp.hpp"
#include "model.hpp"

namespace fw {

constexpr int kIn = cdam_model::kInputs;
constexpr int kHid = cdam_model::kHidden;
constexpr int kOut = cdam_model::kOutputs;
static_assert(PackedMlp<kIn, kHid, kOut>::kParams == cdam_model::kParams,
              "generated model: parameter count mismatch");

// CDAM_FW_EXACT_ACTIVATION (the fw_check_exact reference image of the benchmark): the core's
// cdam::Mlp on theta as exported, with std::tanh / std::exp from newlib.
#ifdef CDAM_FW_EXACT_ACTIVATION
using Net = cdam::Mlp<float, kIn, kHid, kOut, cdam::ExactActivation>;
#else
// The packed weights (flash); check_packed() compares them with theta at run time.
inline constexpr PackedMlp<kIn, kHid, kOut> kPacked =
    pack_mlp<kIn, kHid, kOut>(cdam_model::kTheta, !cdam_model::kTansig);
#endif

// Normalised in, normalised out: the network alone.
inline void infer_normalised(const float* xn, float* yn) {
#ifdef CDAM_FW_EXACT_ACTIVATION
  const Net net(kIn, kHid, kOut,
                cdam_model::kTansig ? cdam::Activation::Tansig : cdam::Activation::Logsig);
  float hidden[kHid];
  net.forward(cdam_model::kTheta, xn, hidden, yn);
#else
  forward_packed(kPacked, xn, yn);
#endif
}

// Min-max scaling factors (cdam/scaling.hpp's mapping with the division done once, at compile
// time): xn = (x - lo) * 2 / (hi - lo) - 1 and y = (yn + 1) * (hi - lo) / 2 + lo; a constant
// channel (hi == lo) maps to 0 and back to its constant.
struct Scaling {
  float in_lo[kIn], in_gain[kIn], in_off[kIn], out_gain[kOut], out_off[kOut];
};
constexpr Scaling make_scaling() {
  Scaling s{};
  for (int k = 0; k < kIn; ++k) {
    const double lo = cdam_model::kXMin[k], hi = cdam_model::kXMax[k];
    s.in_lo[k] = cdam_model::kXMin[k];
    s.in_gain[k] = hi > lo ? static_cast<float>(2.0 / (hi - lo)) : 0.0f;
    s.in_off[k] = hi > lo ? -1.0f : 0.0f;
  }
  for (int k = 0; k < kOut; ++k) {
    const double lo = cdam_model::kYMin[k], hi = cdam_model::kYMax[k];
    s.out_gain[k] = hi > lo ? static_cast<float>((hi - lo) / 2.0) : 0.0f;
    s.out_off[k] = hi > lo ? static_cast<float>(lo + (hi - lo) / 2.0) : cdam_model::kYMin[k];
  }
  return s;
}
inline constexpr Scaling kScaling = make_scaling();

// Physical in, physical out.
inline void predict(const float* x, float* y) {
  float xn[kIn], yn[kOut];
  for (int k = 0; k < kIn; ++k)
    // a constant channel is 0 whatever x (a test the compiler resolves: kScaling is constexpr)
    xn[k] = kScaling.in_gain[k] != 0.0f
                ? (x[k] - kScaling.in_lo[k]) * kScaling.in_gain[k] + kScaling.in_off[k]
                : 0.0f;
  infer_normalised(xn, yn);
  for (int k = 0; k < kOut; ++k) y[k] = yn[k] * kScaling.out_gain[k] + kScaling.out_off[k];
}

// FNV-1a of the weights as stored in flash (equals cdam_model::kThetaFnv1a when intact).
inline std::uint32_t theta_fnv1a() {
  std::uint32_t h = 0x811C9DC5u;
  const auto* p = reinterpret_cast<const unsigned char*>(cdam_model::kTheta);
  for (unsigned k = 0; k < sizeof(cdam_model::kTheta); ++k) h = (h ^ p[k]) * 0x01000193u;
  return h;
}

// True when the packed weights the inference reads are what pack_mlp makes of theta as stored
// in flash (with theta_fnv1a, this covers the copy in use). Always true in the exact image.
inline bool check_packed() {
#ifdef CDAM_FW_EXACT_ACTIVATION
  return true;
#else
  const float* theta = cdam_model::kTheta;
  __asm__ volatile("" : "+r"(theta));   // read theta from memory, not the compiler's constants
  return packed_matches(kPacked, theta, !cdam_model::kTansig);
#endif
}

}  // namespace fw
