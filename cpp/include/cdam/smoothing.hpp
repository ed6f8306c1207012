// Five-point cubic smoothing ("five-spot triple smoothing"): least-squares cubic over a sliding
// 5-point window, with the two one-sided formulas at each end (ALGORITHMS.md; equals
// scipy.signal.savgol_filter(y, 5, 3, mode="interp")). In place, O(1) extra memory, no heap.
#pragma once
#include <cstddef>

#include "status.hpp"

namespace cdam {

// One channel of n samples at y[0], y[stride], ..., smoothed `passes` times in place.
template <typename Scalar>
Status five_point_cubic_smooth_inplace(Scalar* y, std::ptrdiff_t n, std::ptrdiff_t stride,
                                       int passes) {
  if (passes < 0) return Status::InvalidArgument;
  if (n < 5) return Status::TooFewSamples;
  const Scalar c35 = Scalar(35), c70 = Scalar(70);
  auto at = [&](std::ptrdiff_t i) -> Scalar& { return y[i * stride]; };
  for (int p = 0; p < passes; ++p) {
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

// A samples x channels array in row-major (C) order: every channel smoothed in place.
template <typename Scalar>
Status five_point_cubic_smooth_rows(Scalar* data, std::ptrdiff_t samples, std::ptrdiff_t channels,
                                    int passes) {
  if (channels < 1) return Status::Empty;
  for (std::ptrdiff_t c = 0; c < channels; ++c) {
    const Status s = five_point_cubic_smooth_inplace(data + c, samples, channels, passes);
    if (s != Status::Ok) return s;
  }
  return Status::Ok;
}

}  // namespace cdam
