// The residual monitor beside the model step (cdam_core.evaluate.monitor, the same recursion in
// the same float32 order): per output c, with the measured y and the one-step prediction p,
//   r = y - p;  z = (r - mean_c) / std_c;  e = e + lam (z - e);
//   up = max(0, (up + z) - k);  dn = max(0, (dn - z) - k);
//   flags = CUSUM_UP [up > h_c] | CUSUM_DOWN [dn > h_c] | EWMA [|e| > L_c]  (0 when the
//   output is not watched, kMonWatch_c = 0: a unit quaternion's largest component);
// an output that alarms restarts its three statistics at 0. The numbers (mean, std, h, L, k,
// lam, watch) are the model file's `monitor` section, in generated/model.hpp when
// CDAM_MODEL_HAS_MONITOR is 1. Fixed sizes, no heap, no libm.
//
// Alarm frame (kAlarmId = 0x3F2, standard id, 8 bytes, little-endian; not a C610 id (0x1FF,
// 0x200..0x208) nor the loop's 0x300, 0x3F0, 0x3F1):
//   byte 0 output index, byte 1 flags (bit 0 CUSUM up, bit 1 CUSUM down, bit 2 EWMA),
//   bytes 2-3 uint16 alarms so far (saturating at 65535), bytes 4-7 uint32 sample counter.
#pragma once
#include <cstdint>

#include "cdam/c610.hpp"
#include "fw/step_model.hpp"
#include "model.hpp"

namespace fw {

constexpr std::uint32_t kAlarmId = 0x3F2;
constexpr std::uint8_t kCusumUp = 1, kCusumDown = 2, kEwma = 4;

inline cdam::CanFrame alarm_frame(int channel, std::uint8_t flags, std::uint16_t count,
                                  std::uint32_t sample) {
  cdam::CanFrame f;
  f.id = kAlarmId;
  f.dlc = 8;
  f.data[0] = static_cast<std::uint8_t>(channel);
  f.data[1] = flags;
  f.data[2] = static_cast<std::uint8_t>(count & 0xFFu);
  f.data[3] = static_cast<std::uint8_t>(count >> 8);
  for (int b = 0; b < 4; ++b) f.data[4 + b] = static_cast<std::uint8_t>(sample >> (8 * b));
  return f;
}

#if CDAM_MODEL_HAS_MONITOR

template <int N>
class Monitor {
 public:
  // One row: measured y and prediction p (N outputs each); flags per output out (0: none).
  // Returns true when any output alarmed.
  bool update(const float* y, const float* p, std::uint8_t* flags) {
    using namespace cdam_model;
    bool any = false;
    for (int c = 0; c < N; ++c) {
      const float r = y[c] - p[c];
      const float z = (r - kMonMean[c]) / kMonStd[c];
      e_[c] = e_[c] + kMonLambda * (z - e_[c]);
      const float up = (up_[c] + z) - kMonK;
      const float dn = (dn_[c] - z) - kMonK;
      up_[c] = up > 0.0f ? up : 0.0f;
      dn_[c] = dn > 0.0f ? dn : 0.0f;
      const float ae = e_[c] < 0.0f ? -e_[c] : e_[c];
      std::uint8_t f = 0;
      if (up_[c] > kMonH[c]) f |= kCusumUp;
      if (dn_[c] > kMonH[c]) f |= kCusumDown;
      if (ae > kMonEwmaLimit[c]) f |= kEwma;
      if (kMonWatch[c] == 0.0f) f = 0;   // an output the monitor does not watch
      flags[c] = f;
      if (f) {
        e_[c] = up_[c] = dn_[c] = 0.0f;
        if (count_ < 0xFFFFu) ++count_;
        any = true;
      }
    }
    return any;
  }

  std::uint16_t count() const { return count_; }

 private:
  float e_[N] = {}, up_[N] = {}, dn_[N] = {};
  std::uint16_t count_ = 0;
};

// FNV-1a of the monitor's numbers: mean, std, h, L, watch, then k and lam
// (cdam_core.firmware.step)
inline std::uint32_t monitor_fnv1a() {
  using namespace cdam_model;
  std::uint32_t h = fnv1a_floats(0x811C9DC5u, kMonMean, sizeof(kMonMean) / 4);
  h = fnv1a_floats(h, kMonStd, sizeof(kMonStd) / 4);
  h = fnv1a_floats(h, kMonH, sizeof(kMonH) / 4);
  h = fnv1a_floats(h, kMonEwmaLimit, sizeof(kMonEwmaLimit) / 4);
  h = fnv1a_floats(h, kMonWatch, sizeof(kMonWatch) / 4);
  const float kl[2] = {kMonK, kMonLambda};
  return fnv1a_floats(h, kl, 2);
}

#endif

}  // namespace fw
