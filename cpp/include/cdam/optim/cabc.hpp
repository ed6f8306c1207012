// Chaotic Artificial Bee Colony (ABC of Karaboga with the chaotic recipe of Alatas 2010),
// minimising a fitness. ALGORITHMS.md "CABC"; numpy twin: cdam_core.reference.optimisers.cabc.
//
// Colony size n (the paper's Np); SN = n / 2 food sources (Karaboga's convention: as many
// employed as onlooker bees), stored in the first SN columns of the Swarm.
// Initialisation (reconstructed "chaotic initialisation"): one draw seeds the logistic map z;
// x_ij = lb + z (ub - lb) with z stepped once per value, source by source, dimension fastest;
// one batch evaluation; trial counters 0; g* = the first best.
// Neighbour move of source i (employed and onlooker bees): draws j = index(D),
// k = index(SN - 1) (k += 1 when k >= i), phi = -1 + 2 u; v = x_i with
// v_j = clip(x_ij + phi (x_ij - x_kj)); evaluated at once (sources are updated in place, in
// order); accepted if f(v) < f(x_i) (counter reset, g* updated if f(v) < f(g*)), else the
// counter grows.
// Iteration: employed bees (i = 0..SN-1); roulette weights w_i = 1 / (1 + f_i) (1 + |f_i| when
// f_i < 0) computed once; SN onlooker bees each draw u, pick the first i with
// cumsum(w)_i > u sum(w) (index order; the last source if none) and make the neighbour move;
// scout (reconstructed "chaotic scout search"): the source with the largest counter (lowest
// index on ties), if its counter exceeds `limit`, is replaced by the best of
// `scout_candidates` chaotic points around g*, x' = clip(g* + R (ub - lb) (2 z - 1)),
// R = scout_radius, evaluated in one batch; its counter is reset and g* updated (<).
#pragma once
#include <cmath>

#include "../rng.hpp"
#include "../status.hpp"
#include "chaos.hpp"
#include "swarm.hpp"

namespace cdam::optim {

struct CabcOptions {
  int iterations = 50;         // Tmax
  int limit = 20;              // abandonment limit
  double lb = -1.0, ub = 1.0;  // box bounds
  int scout_candidates = 5;    // chaotic points tried by a scout (1 .. n)
  double scout_radius = 0.1;   // R

  Status check(Index n) const {
    if (n < 4) return Status::InvalidArgument;  // at least two food sources
    if (!fits<int>(n)) return Status::Overflow;  // int labels; Rng::index takes 32 bits
    if (iterations < 0 || limit < 0 || !(lb < ub) || !std::isfinite(lb) || !std::isfinite(ub) ||
        scout_candidates < 1 || scout_candidates > n || !(scout_radius > 0))
      return Status::InvalidArgument;
    return Status::Ok;
  }
};

template <typename Scalar_, int Dim = Eigen::Dynamic, int Pop = Eigen::Dynamic>
class Cabc {
 public:
  using Scalar = Scalar_;
  using SwarmT = Swarm<Scalar, Dim, Pop>;

  explicit Cabc(const CabcOptions& opt = {}) : opt_(opt) {}
  const CabcOptions& options() const { return opt_; }
  static Index sources(const SwarmT& s) { return s.size() / 2; }

  template <typename Fitness>
  Status init(SwarmT& s, Fitness& fitness, Rng& rng) {
    const Status st = opt_.check(s.size());
    if (st != Status::Ok) return st;
    if (!fits<std::uint32_t>(s.dim())) return Status::Overflow;  // Rng::index(D)
    const Index sn = sources(s);
    const Scalar lb = Scalar(opt_.lb), ub = Scalar(opt_.ub);
    chaos_.seed(rng);
    for (Index i = 0; i < sn; ++i)
      for (Index d = 0; d < s.dim(); ++d) s.x(d, i) = lb + chaos_.next() * (ub - lb);
    fitness.batch(s.x.data(), sn, s.fit.data());
    s.evaluations += sn;
    for (Index i = 0; i < sn; ++i) s.counter[i] = 0;
    const Index b = arg_extreme(s.fit, sn);
    s.best = s.x.col(b);
    s.best_fit = s.fit[b];
    return Status::Ok;
  }

  template <typename Fitness>
  void iterate(SwarmT& s, Fitness& fitness, Rng& rng) {
    const Index sn = sources(s);
    for (Index i = 0; i < sn; ++i) neighbour(s, fitness, rng, i);
    Scalar total = 0;
    for (Index i = 0; i < sn; ++i) {
      const Scalar f = s.fit[i];
      s.trial_fit[i] = f >= Scalar(0) ? Scalar(1) / (Scalar(1) + f) : Scalar(1) + std::abs(f);
      total += s.trial_fit[i];
    }
    for (Index q = 0; q < sn; ++q) {
      const Scalar u = rng.uniform<Scalar>() * total;
      Index pick = sn - 1;
      Scalar acc = 0;
      for (Index i = 0; i < sn; ++i) {
        acc += s.trial_fit[i];
        if (acc > u) { pick = i; break; }
      }
      neighbour(s, fitness, rng, pick);
    }
    const Index w = arg_extreme(s.counter, sn, true);
    if (s.counter[w] > opt_.limit) scout(s, fitness, w);
  }

  template <typename Fitness, typename Poll = NeverCancel>
  Status run(SwarmT& s, Fitness& fitness, Rng& rng, double* curve, Poll poll = Poll()) {
    return run_optimiser(*this, s, fitness, rng, opt_.iterations, curve, poll);
  }

 private:
  template <typename Fitness>
  void neighbour(SwarmT& s, Fitness& fitness, Rng& rng, Index i) {
    const Index sn = sources(s);
    const Index j = rng.index(static_cast<std::uint32_t>(s.dim()));
    Index k = rng.index(static_cast<std::uint32_t>(sn - 1));
    if (k >= i) ++k;
    const Scalar phi = Scalar(-1) + Scalar(2) * rng.uniform<Scalar>();
    s.scratch.col(0) = s.x.col(i);
    s.scratch(j, 0) = clip(s.x(j, i) + phi * (s.x(j, i) - s.x(j, k)), Scalar(opt_.lb),
                           Scalar(opt_.ub));
    const Scalar f = fitness(s.scratch.col(0).data());
    ++s.evaluations;
    if (f < s.fit[i]) {
      s.x.col(i) = s.scratch.col(0);
      s.fit[i] = f;
      s.counter[i] = 0;
      if (f < s.best_fit) {
        s.best = s.x.col(i);
        s.best_fit = f;
      }
    } else {
      ++s.counter[i];
    }
  }

  template <typename Fitness>
  void scout(SwarmT& s, Fitness& fitness, Index w) {
    const Index m = opt_.scout_candidates;
    const Scalar lb = Scalar(opt_.lb), ub = Scalar(opt_.ub), R = Scalar(opt_.scout_radius);
    for (Index q = 0; q < m; ++q)
      for (Index d = 0; d < s.dim(); ++d)
        s.scratch(d, q) = clip(s.best[d] + R * (ub - lb) * (Scalar(2) * chaos_.next() - Scalar(1)),
                               lb, ub);
    fitness.batch(s.scratch.data(), m, s.scratch_fit.data());
    s.evaluations += m;
    const Index b = arg_extreme(s.scratch_fit, m);
    s.x.col(w) = s.scratch.col(b);
    s.fit[w] = s.scratch_fit[b];
    s.counter[w] = 0;
    if (s.fit[w] < s.best_fit) {
      s.best = s.x.col(w);
      s.best_fit = s.fit[w];
    }
  }

  CabcOptions opt_;
  LogisticMap<Scalar> chaos_;
};

}  // namespace cdam::optim
