// The residual monitor in the loop, platform independent (the board image fw_monitor_pil and the
// host tests share it): the measurements arrive as CAN frames, one row [u (kU), y (kY)] of
// float32 per sample; the model runs beside them (fw::StepModel, one-step: step then correct)
// and its residual goes through fw::Monitor; an alarm frame (0x3F2, fw/monitor.hpp) names each
// output that alarms, and an acknowledgement closes every row.
//
// Frames in (standard ids, 8 bytes, little-endian float32 pairs): 0x310 + j carries row
// elements 2 j and 2 j + 1 of [u, y] (the last frame's second float is ignored when kU + kY is
// odd). A row runs when every one of its kRowFrames frames has arrived since the last row; a
// frame of the wrong length, remote, extended or with another id is counted and ignored.
// Frames out, per row: the alarm frames of the outputs that alarmed (output index order), then
//   0x3F3 ack: uint32 rows taken (this row included), uint8 status of that row (0 history row,
//              1 monitored, 2 rejected: a value not finite, the row not run), uint8 alarm frames
//              since the last ack, uint16 frames ignored so far (saturating);
// an ack follows every row that is not a plain monitored one (history, rejected, alarmed) and
// every kAckEvery-th row, and answers a remote frame 0x3F3 (the host asks for the last rows):
// the rows between two acks are monitored rows without an alarm. Fewer bytes a row on the link
// (44 in, 22 out with an ack per row for two inputs and two outputs).
// No heap, fixed sizes: at most kMaxRowFrames frames (64 values) a row.
#pragma once
#include <cmath>
#include <cstdint>
#include <cstring>

#include "cdam/c610.hpp"
#include "fw/monitor.hpp"
#include "fw/step_model.hpp"

namespace fw {

constexpr std::uint32_t kRowId = 0x310;
constexpr std::uint32_t kAckId = 0x3F3;
constexpr int kMaxRowFrames = 32;
constexpr int kRowValues = kU + kY;
constexpr int kRowFrames = (kRowValues + 1) / 2;
static_assert(kRowFrames <= kMaxRowFrames, "a row of more than 64 values does not fit the ids");
constexpr std::uint8_t kRowHistory = 0, kRowMonitored = 1, kRowRejected = 2;
constexpr std::uint32_t kAckEvery = 8;   // a plain monitored row is acknowledged every 8th

#if CDAM_MODEL_HAS_MONITOR

class MonitorLoop {
 public:
  // Feed one received frame. Returns the number of frames written to out (0 until a row is
  // complete; then the alarm frames and the ack). out holds kY + 1 frames.
  int on_frame(const cdam::CanFrame& f, cdam::CanFrame* out) {
    if (!f.extended && f.remote && f.id == kAckId) {
      out[0] = ack();
      return 1;
    }
    if (f.extended || f.remote || f.dlc != 8 || f.id < kRowId ||
        f.id >= kRowId + static_cast<std::uint32_t>(kRowFrames)) {
      if (ignored_ < 0xFFFFu) ++ignored_;
      return 0;
    }
    const int j = static_cast<int>(f.id - kRowId);
    float v[2];
    std::memcpy(v, f.data, 8);
    for (int k = 0; k < 2 && 2 * j + k < kRowValues; ++k) row_[2 * j + k] = v[k];
    fresh_ |= 1u << j;
    if (fresh_ != kAll) return 0;
    fresh_ = 0;
    return run_row(out);
  }

  std::uint32_t rows() const { return rows_; }
  std::uint16_t alarms() const { return monitor_.count(); }

 private:
  static constexpr std::uint32_t kAll =
      kRowFrames >= 32 ? 0xFFFFFFFFu : (1u << kRowFrames) - 1u;

  int run_row(cdam::CanFrame* out) {
    const std::uint32_t t = rows_++;
    std::uint8_t status = kRowMonitored;
    int n = 0;
    bool finite = true;
    for (int k = 0; k < kRowValues; ++k) finite = finite && std::isfinite(row_[k]);
    const float* u = row_;
    const float* y = row_ + kU;
    if (!finite) {
      status = kRowRejected;
    } else if (primed_ < kT0) {
      model_.prime(u, y);
      ++primed_;
      status = kRowHistory;
    } else {
      float p[kY];
      std::uint8_t flags[kY];
      model_.step(u, p);
      std::uint16_t count = monitor_.count();
      if (monitor_.update(y, p, flags)) {
        for (int c = 0; c < kY; ++c) {
          if (!flags[c]) continue;
          if (count < 0xFFFFu) ++count;
          out[n++] = alarm_frame(c, flags[c], count, t);
        }
      }
      model_.correct(y);
      model_.observe(y);   // the measured row (arm_coupling's columns)
    }
    status_ = status;
    pending_ = static_cast<std::uint8_t>(pending_ + n);
    if (status != kRowMonitored || n > 0 || rows_ % kAckEvery == 0) out[n++] = ack();
    return n;
  }

  cdam::CanFrame ack() {
    cdam::CanFrame f;
    f.id = kAckId;
    f.dlc = 8;
    std::memcpy(f.data, &rows_, 4);
    f.data[4] = status_;
    f.data[5] = pending_;
    std::memcpy(f.data + 6, &ignored_, 2);
    pending_ = 0;
    return f;
  }

  StepModel model_;
  Monitor<kY> monitor_;
  float row_[kRowFrames * 2] = {};
  std::uint32_t fresh_ = 0, rows_ = 0;
  int primed_ = 0;
  std::uint16_t ignored_ = 0;
  std::uint8_t status_ = kRowHistory, pending_ = 0;   // the last row's; alarms since an ack
};

#endif

}  // namespace fw
