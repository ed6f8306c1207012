// Min-max scaling to [-1, 1] (MATLAB mapminmax): x' = 2 (x - xmin) / (xmax - xmin) - 1.
// A constant column (xmax == xmin) maps to 0 and inverse-maps to its constant.
// Data are samples x channels in row-major (C) order. No heap.
#pragma once
#include <cstddef>

#include "status.hpp"

namespace cdam {

template <typename Scalar>
Status minmax_fit(const Scalar* x, std::ptrdiff_t samples, std::ptrdiff_t channels, Scalar* xmin,
                  Scalar* xmax) {
  if (samples < 1 || channels < 1) return Status::Empty;
  for (std::ptrdiff_t c = 0; c < channels; ++c) xmin[c] = xmax[c] = x[c];
  for (std::ptrdiff_t n = 1; n < samples; ++n)
    for (std::ptrdiff_t c = 0; c < channels; ++c) {
      const Scalar v = x[n * channels + c];
      if (v < xmin[c]) xmin[c] = v;
      if (v > xmax[c]) xmax[c] = v;
    }
  return Status::Ok;
}

template <typename Scalar>
inline Scalar minmax_forward(Scalar v, Scalar lo, Scalar hi) {
  return hi > lo ? Scalar(2) * (v - lo) / (hi - lo) - Scalar(1) : Scalar(0);
}

template <typename Scalar>
inline Scalar minmax_inverse(Scalar v, Scalar lo, Scalar hi) {
  return hi > lo ? (v + Scalar(1)) * (hi - lo) / Scalar(2) + lo : lo;
}

// In place; inverse=false scales, inverse=true back-scales.
template <typename Scalar>
void minmax_apply(Scalar* x, std::ptrdiff_t samples, std::ptrdiff_t channels, const Scalar* xmin,
                  const Scalar* xmax, bool inverse) {
  for (std::ptrdiff_t n = 0; n < samples; ++n)
    for (std::ptrdiff_t c = 0; c < channels; ++c) {
      Scalar& v = x[n * channels + c];
      v = inverse ? minmax_inverse(v, xmin[c], xmax[c]) : minmax_forward(v, xmin[c], xmax[c]);
    }
}

}  // namespace cdam
