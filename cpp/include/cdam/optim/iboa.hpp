// Improved BOA (the paper's IBOA): BOA + clustering competitive learning + chaotic elite
// learning. The paper's equations 23-27 were lost; every step below is a reconstruction
// (ALGORITHMS.md "IBOA additions") and each choice is a parameter. numpy twin:
// cdam_core.reference.optimisers.iboa.
//
// Initialisation: as BOA (n D uniform draws, one batch evaluation), then one draw seeds the
// logistic map (chaos.hpp).
// Iteration t = 1..Tmax:
//  1. one BOA iteration (boa.hpp; BoaForm::Author by default) including the c update;
//  2. clustering competitive learning: k-means (kmeans.hpp: k seeding draws, Lloyd rounds) on
//     the positions; in each cluster the best member (lowest fitness, lowest index on ties) is
//     the winner and is left alone; every loser l, in index order, draws r1 (D values) then
//     r2 (D values) and moves to
//         x_l' = clip(x_l + r1 .* (x_w - x_l) + phi r2 .* (c_k - x_l))
//     (the Competitive Swarm Optimizer move with the swarm mean replaced by the cluster centre
//     c_k); all losers' candidates are evaluated in one batch; each is accepted if
//     f(x_l') <= f(x_l); g* is then updated in index order (<=);
//  3. chaotic elite learning (no draws): `chaos_candidates` points, each taking D steps of the
//     logistic map z (dimension fastest):
//         convex:   x' = clip((1 - lambda) g* + lambda (lb + z (ub - lb))),
//                   lambda = (Tmax - t + 1) / Tmax
//         additive: x' = clip(g* + s (ub - lb) (2 z - 1)),  s = chaos_scale;
//     evaluated in one batch; if the best candidate (lowest index on ties) is strictly better
//     than g*, it becomes g* and replaces the worst butterfly (highest fitness, lowest index on
//     ties), whose stored trial point S is left as it was.
#pragma once
#include "boa.hpp"
#include "chaos.hpp"
#include "kmeans.hpp"

namespace cdam::optim {

enum class ChaosForm { Convex = 0, Additive = 1 };

struct IboaOptions {
  BoaOptions boa;                 // n, Tmax, p, c, a, bounds, BOA form
  int clusters = 3;               // k of k-means (1 <= k <= n)
  int kmeans_iters = 10;          // Lloyd rounds at most
  double phi = 0.1;               // weight of the pull towards the cluster centre
  int chaos_candidates = 5;       // chaotic elite candidates per iteration (0 .. n)
  ChaosForm chaos_form = ChaosForm::Convex;
  double chaos_scale = 0.1;       // s of the additive form

  Status check(Index n) const {
    const Status st = boa.check(n);
    if (st != Status::Ok) return st;
    if (clusters < 1 || clusters > n || kmeans_iters < 1 || !std::isfinite(phi) ||
        chaos_candidates < 0 || chaos_candidates > n || !(chaos_scale > 0))
      return Status::InvalidArgument;
    return Status::Ok;
  }
};

template <typename Scalar_, int Dim = Eigen::Dynamic, int Pop = Eigen::Dynamic>
class Iboa {
 public:
  using Scalar = Scalar_;
  using SwarmT = Swarm<Scalar, Dim, Pop>;

  explicit Iboa(const IboaOptions& opt = {}) : opt_(opt), boa_(opt.boa) {}
  const IboaOptions& options() const { return opt_; }

  template <typename Fitness>
  Status init(SwarmT& s, Fitness& fitness, Rng& rng) {
    const Status st = opt_.check(s.size());
    if (st != Status::Ok) return st;
    boa_.init(s, fitness, rng);
    chaos_.seed(rng);
    t_ = 0;
    return Status::Ok;
  }

  template <typename Fitness>
  void iterate(SwarmT& s, Fitness& fitness, Rng& rng) {
    ++t_;
    boa_.iterate(s, fitness, rng);
    competitive(s, fitness, rng);
    elite(s, fitness);
  }

  template <typename Fitness, typename Poll = NeverCancel>
  Status run(SwarmT& s, Fitness& fitness, Rng& rng, double* curve, Poll poll = Poll()) {
    return run_optimiser(*this, s, fitness, rng, opt_.boa.iterations, curve, poll);
  }

 private:
  template <typename Fitness>
  void competitive(SwarmT& s, Fitness& fitness, Rng& rng) {
    const Index n = s.size(), D = s.dim(), k = opt_.clusters;
    kmeans(s.x, k, opt_.kmeans_iters, rng, s.centres, s.label, s.counter, s.perm);
    // winners: counter[c] = index of the best member of cluster c
    for (Index c = 0; c < k; ++c) s.counter[c] = -1;
    for (Index i = 0; i < n; ++i) {
      const int c = s.label[i];
      if (s.counter[c] < 0 || s.fit[i] < s.fit[s.counter[c]]) s.counter[c] = static_cast<int>(i);
    }
    const Scalar lb = Scalar(opt_.boa.lb), ub = Scalar(opt_.boa.ub), phi = Scalar(opt_.phi);
    // perm[q] = the butterfly whose candidate is scratch column q
    Index q = 0;
    for (Index i = 0; i < n; ++i) {
      const int w = s.counter[s.label[i]];
      if (w == static_cast<int>(i)) continue;
      const int c = s.label[i];
      for (Index d = 0; d < D; ++d) s.scratch(d, q) = rng.uniform<Scalar>();  // r1
      for (Index d = 0; d < D; ++d) {
        const Scalar r1 = s.scratch(d, q), r2 = rng.uniform<Scalar>();
        const Scalar xl = s.x(d, i);
        s.scratch(d, q) =
            clip(xl + r1 * (s.x(d, w) - xl) + phi * r2 * (s.centres(d, c) - xl), lb, ub);
      }
      s.perm[q++] = static_cast<int>(i);
    }
    if (q == 0) return;
    fitness.batch(s.scratch.data(), q, s.scratch_fit.data());
    s.evaluations += q;
    for (Index j = 0; j < q; ++j) {
      const Index i = s.perm[j];
      if (s.scratch_fit[j] <= s.fit[i]) {
        s.x.col(i) = s.scratch.col(j);
        s.fit[i] = s.scratch_fit[j];
      }
      if (s.fit[i] <= s.best_fit) {
        s.best = s.x.col(i);
        s.best_fit = s.fit[i];
      }
    }
  }

  template <typename Fitness>
  void elite(SwarmT& s, Fitness& fitness) {
    const Index m = opt_.chaos_candidates, D = s.dim();
    if (m == 0) return;
    const Scalar lb = Scalar(opt_.boa.lb), ub = Scalar(opt_.boa.ub);
    const Scalar T = Scalar(opt_.boa.iterations);
    const Scalar lambda = T > 0 ? (T - Scalar(t_) + Scalar(1)) / T : Scalar(1);
    const Scalar sc = Scalar(opt_.chaos_scale);
    for (Index q = 0; q < m; ++q)
      for (Index d = 0; d < D; ++d) {
        const Scalar z = chaos_.next();
        const Scalar v = opt_.chaos_form == ChaosForm::Convex
                             ? (Scalar(1) - lambda) * s.best[d] + lambda * (lb + z * (ub - lb))
                             : s.best[d] + sc * (ub - lb) * (Scalar(2) * z - Scalar(1));
        s.scratch(d, q) = clip(v, lb, ub);
      }
    fitness.batch(s.scratch.data(), m, s.scratch_fit.data());
    s.evaluations += m;
    const Index b = arg_extreme(s.scratch_fit, m);
    if (s.scratch_fit[b] < s.best_fit) {
      s.best = s.scratch.col(b);
      s.best_fit = s.scratch_fit[b];
      const Index w = arg_extreme(s.fit, s.size(), true);
      s.x.col(w) = s.best;
      s.fit[w] = s.best_fit;
    }
  }

  IboaOptions opt_;
  Boa<Scalar, Dim, Pop> boa_;
  LogisticMap<Scalar> chaos_;
  int t_ = 0;
};

}  // namespace cdam::optim
