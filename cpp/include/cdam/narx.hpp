// NARX models on top of the BP network: lagged regressors from past outputs and inputs, one-step
// prediction (the network on measured regressors) and free-run simulation (past outputs replaced
// by the model's own predictions). No heap: the caller owns every buffer.
//
// Orders: na output lags, nb input lags, input delay nk. First usable time t0 = max(na, nk+nb-1).
// Regressor at time t (channels fastest):
//   [y(t-1); ...; y(t-na); u(t-nk); u(t-nk-1); ...; u(t-nk-nb+1)]   length na m + nb i.
// Signals are column-major (channels x samples): one sample per column.
#pragma once
#include <algorithm>

#include "mlp.hpp"
#include "status.hpp"

namespace cdam {

struct NarxOrders {
  int na = 0, nb = 1, nk = 0;
  int t0() const { return std::max(na, nk + nb - 1); }
  Index regressors(Index n_in, Index n_out) const { return na * n_out + nb * n_in; }
  Status check() const {
    if (na < 0 || nb < 0 || nk < 0 || na + nb < 1) return Status::InvalidArgument;
    return Status::Ok;
  }
};

// One regressor column for time t into r (length na m + nb i).
template <typename Scalar>
void narx_regressor(const Scalar* U, Index ni, const Scalar* Y, Index no, const NarxOrders& o,
                    Index t, Scalar* r) {
  Index p = 0;
  for (int lag = 1; lag <= o.na; ++lag)
    for (Index k = 0; k < no; ++k) r[p++] = Y[(t - lag) * no + k];
  for (int j = 0; j < o.nb; ++j)
    for (Index c = 0; c < ni; ++c) r[p++] = U[(t - o.nk - j) * ni + c];
}

// All regressors: X has (na m + nb i) rows and n - t0 columns.
template <typename Scalar>
Status narx_regressors(const Scalar* U, Index ni, const Scalar* Y, Index no, Index n,
                       const NarxOrders& o, Scalar* X) {
  if (o.check() != Status::Ok) return Status::InvalidArgument;
  const Index t0 = o.t0();
  if (n <= t0) return Status::TooFewSamples;
  const Index nr = o.regressors(ni, no);
  for (Index t = t0; t < n; ++t) narx_regressor(U, ni, Y, no, o, t, X + (t - t0) * nr);
  return Status::Ok;
}

// Free-run simulation: Y (m x n) holds the initial outputs in its first t0 columns; columns
// t0 .. n-1 are overwritten with the simulated outputs. reg: na m + nb i scalars, hidden: h.
template <typename Scalar, int I, int H, int O>
Status narx_simulate(const Mlp<Scalar, I, H, O>& net, const Scalar* theta, const Scalar* U,
                     Scalar* Y, Index n, Index ni, const NarxOrders& o, Scalar* reg,
                     Scalar* hidden) {
  if (o.check() != Status::Ok) return Status::InvalidArgument;
  const Index no = net.outputs();
  if (net.inputs() != o.regressors(ni, no)) return Status::SizeMismatch;
  const Index t0 = o.t0();
  if (n <= t0) return Status::TooFewSamples;
  for (Index t = t0; t < n; ++t) {
    narx_regressor(U, ni, Y, no, o, t, reg);
    net.forward(theta, reg, hidden, Y + t * no);
  }
  return Status::Ok;
}

}  // namespace cdam
