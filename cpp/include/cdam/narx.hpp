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
#include "safe_size.hpp"
#include "status.hpp"

namespace cdam {

struct NarxOrders {
  int na = 0, nb = 1, nk = 0;

  // Orders valid (na, nb, nk >= 0 and na + nb >= 1: else InvalidArgument) and t0 representable
  // in int (else Overflow; nk = 2^31 - 1 used to wrap t0 negative). t0() and regressors() assume
  // that check() (and for regressors, check(n_in, n_out)) passed.
  Status check() const {
    if (na < 0 || nb < 0 || nk < 0) return Status::InvalidArgument;
    if (na == 0 && nb == 0) return Status::InvalidArgument;
    int last = 0;  // nk + nb - 1, the oldest input lag
    return (Checked<int>(nk) + (nb - 1)).get(&last);  // nb - 1 >= -1 cannot overflow
  }
  // check() and the regressor length na m + nb i representable in Index.
  Status check(Index n_in, Index n_out) const {
    const Status st = check();
    if (st != Status::Ok) return st;
    if (n_in < 0 || n_out < 0) return Status::InvalidArgument;
    Index nr = 0;
    return (Checked<Index>(na) * n_out + Checked<Index>(nb) * n_in).get(&nr);
  }
  int t0() const { return std::max(na, nk + (nb - 1)); }  // no intermediate overflow
  Index regressors(Index n_in, Index n_out) const {
    return static_cast<Index>(na) * n_out + static_cast<Index>(nb) * n_in;
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
  const Status st = o.check(ni, no);
  if (st != Status::Ok) return st;
  const Index t0 = o.t0();
  if (n <= t0) return Status::TooFewSamples;
  const Index nr = o.regressors(ni, no);
  for (Index t = t0; t < n; ++t) narx_regressor(U, ni, Y, no, o, t, X + (t - t0) * nr);
  return Status::Ok;
}

// Free-run simulation: Y (m x n) holds the initial outputs in its first t0 columns; columns
// t0 .. n-1 are overwritten with the simulated outputs. reg: na m + nb i scalars, hidden: h.
// `poll` (status.hpp) is asked every step; false ends the run with Status::Cancelled.
template <typename Scalar, int I, int H, int O, typename Poll = NeverCancel>
Status narx_simulate(const Mlp<Scalar, I, H, O>& net, const Scalar* theta, const Scalar* U,
                     Scalar* Y, Index n, Index ni, const NarxOrders& o, Scalar* reg,
                     Scalar* hidden, Poll poll = Poll()) {
  const Index no = net.outputs();
  const Status st = o.check(ni, no);
  if (st != Status::Ok) return st;
  if (net.inputs() != o.regressors(ni, no)) return Status::SizeMismatch;
  const Index t0 = o.t0();
  if (n <= t0) return Status::TooFewSamples;
  for (Index t = t0; t < n; ++t) {
    if (!poll()) return Status::Cancelled;
    narx_regressor(U, ni, Y, no, o, t, reg);
    net.forward(theta, reg, hidden, Y + t * no);
  }
  return Status::Ok;
}

}  // namespace cdam
