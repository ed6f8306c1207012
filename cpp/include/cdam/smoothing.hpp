// Five-point cubic smoothing ("five-spot triple smoothing"): least-squares cubic over a sliding
// 5-point window, with the two one-sided formulas at each end (ALGORITHMS.md; equals
// scipy.signal.savgol_filter(y, 5, 3, mode="interp")). In place, O(1) extra memory, no heap.
// `poll` (status.hpp: a callable bool(), NeverCancel by default) is asked before every pass;
// false stops the passes with Status::Cancelled (the bindings stop on Ctrl-C this way).
#pragma once
#include <cstddef>

#include "status.hpp"

namespace cdam {

// One channel of n samples at y[0], y[stride], ..., smoothed `passes` times in place.
template <typename Scalar, typename Poll = NeverCancel>
Status five_point_cubic_smooth_inplace(Scalar* y, std::ptrdiff_t n, std::ptrdiff_t stride,
                                       int passes, Poll poll = Poll()) {
  if (passes < 0) return Status::InvalidArgument;
  if (n < 5) return Status::TooFewSamples;
  const Scalar c35 = Scalar(35), c70 = Scalar(70);
  auto at = [&](std::ptrdiff_t i) -> Scalar& { return y[i * stride]; };
  for (int p = 0; p < passes; ++p) {
    if (!poll()) return Status::Cancelled;
    const Scalar a0 = at(0), a1 = at(1), a2 = at(2), a3 = at(3), a4 = at(4);
    at(0) = (Scalar(69) * a0 + Scalar(4) * a1 - Scalar(6) * a2 + Scalar(4) * a3 - a4) / c70;
    at(1) = (Scalar(2) * a0 + Scalar(27) * a1 + Scalar(12) * a2 - Scalar(8) * a3 + Scalar(2) * a4) / c35;
    // originals of samples i-3, i-2, i-1 (already overwritten in y)
    Scalar o3 = Scalar(0), o2 = a0, o1 = a1;
    for (std::ptrdiff_t i = 2; i <= n - 3; ++i) {
      const Scalar cur = at(i);
      at(i) = (Scalar(-3) * o2 + Scalar(12) * o1 + Scalar(17) * cur + Scalar(12) * at(i + 1) -
               Scalar(3) * at(i + 2)) / c35;
      o3 = o2;
      o2 = o1;
      o1 = cur;
    }
    // o3, o2, o1 now hold the originals of n-5, n-4, n-3
    const Scalar b3 = at(n - 2), b4 = at(n - 1);
    at(n - 2) = (Scalar(2) * o3 - Scalar(8) * o2 + Scalar(12) * o1 + Scalar(27) * b3 + Scalar(2) * b4) / c35;
    at(n - 1) = (-o3 + Scalar(4) * o2 - Scalar(6) * o1 + Scalar(4) * b3 + Scalar(69) * b4) / c70;
  }
  return Status::Ok;
}

// A samples x channels array in row-major (C) order: every channel smoothed in place, all
// channels of a sample together (contiguous, vectorisable). work: 3 * channels scalars of caller
// storage (the originals of the three previous samples).
template <typename Scalar, typename Poll = NeverCancel>
Status five_point_cubic_smooth_rows(Scalar* data, std::ptrdiff_t samples, std::ptrdiff_t channels,
                                    int passes, Scalar* work, Poll poll = Poll()) {
  if (channels < 1) return Status::Empty;
  if (passes < 0) return Status::InvalidArgument;
  if (samples < 5) return Status::TooFewSamples;
  const std::ptrdiff_t C = channels, n = samples;
  Scalar* o3 = work;
  Scalar* o2 = work + C;
  Scalar* o1 = work + 2 * C;
  auto row = [&](std::ptrdiff_t i) { return data + i * C; };
  const Scalar c35 = Scalar(35), c70 = Scalar(70);
  for (int p = 0; p < passes; ++p) {
    if (!poll()) return Status::Cancelled;
    Scalar *r0 = row(0), *r1 = row(1), *r2 = row(2), *r3 = row(3), *r4 = row(4);
    for (std::ptrdiff_t c = 0; c < C; ++c) {
      const Scalar a0 = r0[c], a1 = r1[c], a2 = r2[c], a3 = r3[c], a4 = r4[c];
      r0[c] = (Scalar(69) * a0 + Scalar(4) * a1 - Scalar(6) * a2 + Scalar(4) * a3 - a4) / c70;
      r1[c] = (Scalar(2) * a0 + Scalar(27) * a1 + Scalar(12) * a2 - Scalar(8) * a3 + Scalar(2) * a4) / c35;
      o2[c] = a0;
      o1[c] = a1;
    }
    for (std::ptrdiff_t i = 2; i <= n - 3; ++i) {
      Scalar* ri = row(i);
      const Scalar* rp1 = row(i + 1);
      const Scalar* rp2 = row(i + 2);
      for (std::ptrdiff_t c = 0; c < C; ++c) {
        const Scalar cur = ri[c];
        ri[c] = (Scalar(-3) * o2[c] + Scalar(12) * o1[c] + Scalar(17) * cur + Scalar(12) * rp1[c] -
                 Scalar(3) * rp2[c]) / c35;
        o3[c] = o2[c];
        o2[c] = o1[c];
        o1[c] = cur;
      }
    }
    Scalar *rb3 = row(n - 2), *rb4 = row(n - 1);
    for (std::ptrdiff_t c = 0; c < C; ++c) {
      const Scalar b3 = rb3[c], b4 = rb4[c];
      rb3[c] = (Scalar(2) * o3[c] - Scalar(8) * o2[c] + Scalar(12) * o1[c] + Scalar(27) * b3 + Scalar(2) * b4) / c35;
      rb4[c] = (-o3[c] + Scalar(4) * o2[c] - Scalar(6) * o1[c] + Scalar(4) * b3 + Scalar(69) * b4) / c70;
    }
  }
  return Status::Ok;
}

}  // namespace cdam
