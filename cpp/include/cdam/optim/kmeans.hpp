// Lloyd's k-means on the columns of a D x n position matrix (IBOA's clustering competitive
// learning). No heap: centres, labels, counts and the seeding permutation live in the Swarm.
//
// Draw order (Rng): k draws for the seeding, a partial Fisher-Yates shuffle of 0..n-1:
//   perm = 0..n-1; for c = 0..k-1: j = c + index(n - c); swap(perm[c], perm[j]);
//   centre c = x[:, perm[c]].
// Then up to `iters` Lloyd rounds: assign each point to the nearest centre by squared Euclidean
// distance (ties to the lowest cluster index); stop when no label changes (after the first
// round); recompute each centre as the mean of its members summed in index order; an empty
// cluster keeps its previous centre. No further draws.
#pragma once
#include "../rng.hpp"
#include "swarm.hpp"

namespace cdam::optim {

template <typename Positions, typename Labels>
void kmeans(const Positions& x, Index k, int iters, Rng& rng, Positions& centres, Labels& label,
            Labels& count, Labels& perm) {
  const Index n = x.cols(), D = x.rows();
  for (Index i = 0; i < n; ++i) perm[i] = static_cast<int>(i);
  for (Index c = 0; c < k; ++c) {
    const Index j = c + static_cast<Index>(rng.index(static_cast<std::uint32_t>(n - c)));
    const int tmp = perm[c];
    perm[c] = perm[j];
    perm[j] = tmp;
    centres.col(c) = x.col(perm[c]);
  }
  for (Index i = 0; i < n; ++i) label[i] = -1;
  for (int it = 0; it < iters; ++it) {
    bool changed = false;
    for (Index i = 0; i < n; ++i) {
      int bc = 0;
      typename Positions::Scalar bd = 0;
      for (Index c = 0; c < k; ++c) {
        typename Positions::Scalar d2 = 0;
        for (Index d = 0; d < D; ++d) {
          const auto e = x(d, i) - centres(d, c);
          d2 += e * e;
        }
        if (c == 0 || d2 < bd) { bd = d2; bc = static_cast<int>(c); }
      }
      if (label[i] != bc) { label[i] = bc; changed = true; }
    }
    if (!changed) break;
    for (Index c = 0; c < k; ++c) count[c] = 0;
    for (Index i = 0; i < n; ++i) ++count[label[i]];
    for (Index c = 0; c < k; ++c) {
      if (count[c] == 0) continue;
      centres.col(c).setZero();
      for (Index i = 0; i < n; ++i)
        if (label[i] == c) centres.col(c) += x.col(i);
      centres.col(c) /= static_cast<typename Positions::Scalar>(count[c]);
    }
  }
}

}  // namespace cdam::optim
