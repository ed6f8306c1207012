// Butterfly Optimization Algorithm (Arora and Singh, Soft Computing 2019), minimising a fitness.
// ALGORITHMS.md "BOA"; the numpy twin is cdam_core.reference.optimisers.boa.
//
// Fragrance f_i = c |I_i|^a (I the fitness; |.| guards negative objectives). Two forms:
//
// BoaForm::Author (default; the author's published MATLAB code): butterflies are visited in
// index order; the fragrance comes from the fitness of the butterfly's last trial point S_i
// (stored, not re-evaluated); S_i = clip(x_i + (r g* - x_i) f_i) with r = u1 u2 (global move,
// when u < p), else S_i = clip(x_i + (e^2 x_j - x_k) f_i), j != k random; S_i is evaluated at
// once, accepted if f(S_i) <= f(x_i), and g* is updated at once if f(S_i) <= f(g*).
//   Draws per butterfly: u; global: u1, u2; local: e, j = index(n), k = index(n - 1)
//   (k += 1 when k >= j).
// BoaForm::Paper (the paper's equations): every move is computed from the positions at the
// start of the iteration with r^2, r one draw, and the fragrance of the current position; all
// new positions are evaluated in one batch and replace the old ones (no greedy selection); g*
// is updated afterwards (index order, <=).
//   Draws per butterfly: u; global: r; local: e, j, k as above.
// Both forms then update the sensory modality c <- c + 0.025 / (c Tmax) (author's code).
//
// Initialisation (also IBOA's): x_ij = lb + u (ub - lb), individual by individual, dimension
// fastest (n D draws); one batch evaluation; S = x; g* = the first best.
// Records: curve[0] = best fitness after initialisation, curve[t] after iteration t.
#pragma once
#include <cmath>

#include "../rng.hpp"
#include "../status.hpp"
#include "swarm.hpp"

namespace cdam::optim {

enum class BoaForm { Author = 0, Paper = 1 };

struct BoaOptions {
  int iterations = 50;   // Tmax
  double p = 0.8;        // switch probability (global move when u < p)
  double c = 0.01;       // sensory modality, initial value (the paper's Table 1 says 2)
  double a = 0.1;        // power exponent
  double lb = -1.0, ub = 1.0;  // box bounds of every decision variable
  BoaForm form = BoaForm::Author;

  Status check(Index n) const {
    if (n < 2) return Status::InvalidArgument;
    if (!fits<int>(n)) return Status::Overflow;  // int labels; Rng::index takes 32 bits
    if (iterations < 0 || !(p >= 0 && p <= 1) || !(c > 0) || !std::isfinite(a) || !(lb < ub) ||
        !std::isfinite(lb) || !std::isfinite(ub))
      return Status::InvalidArgument;
    return Status::Ok;
  }
};

// Uniform initialisation of the whole swarm and its evaluation.
template <typename SwarmT, typename Fitness>
void uniform_init(SwarmT& s, Fitness& fitness, Rng& rng, double lb_, double ub_) {
  using Scalar = typename SwarmT::Scalar;
  const Scalar lb = Scalar(lb_), ub = Scalar(ub_);
  for (Index i = 0; i < s.size(); ++i)
    for (Index d = 0; d < s.dim(); ++d) s.x(d, i) = lb + (ub - lb) * rng.uniform<Scalar>();
  fitness.batch(s.x.data(), s.size(), s.fit.data());
  s.evaluations += s.size();
  s.trial = s.x;
  s.trial_fit = s.fit;
  const Index b = arg_extreme(s.fit, s.size());
  s.best = s.x.col(b);
  s.best_fit = s.fit[b];
}

template <typename Scalar_, int Dim = Eigen::Dynamic, int Pop = Eigen::Dynamic>
class Boa {
 public:
  using Scalar = Scalar_;
  using SwarmT = Swarm<Scalar, Dim, Pop>;

  explicit Boa(const BoaOptions& opt = {}) : opt_(opt), c_(opt.c) {}

  const BoaOptions& options() const { return opt_; }
  double sensory_modality() const { return c_; }

  template <typename Fitness>
  Status init(SwarmT& s, Fitness& fitness, Rng& rng) {
    const Status st = opt_.check(s.size());
    if (st != Status::Ok) return st;
    c_ = opt_.c;
    uniform_init(s, fitness, rng, opt_.lb, opt_.ub);
    return Status::Ok;
  }

  // One iteration (the fitness decides where the work goes; nothing is allocated here).
  template <typename Fitness>
  void iterate(SwarmT& s, Fitness& fitness, Rng& rng) {
    if (opt_.form == BoaForm::Author) iterate_author(s, fitness, rng);
    else iterate_paper(s, fitness, rng);
    c_ = c_ + 0.025 / (c_ * opt_.iterations);
  }

  // init + iterations; curve (iterations + 1 values, may be null) gets the best fitness.
  template <typename Fitness, typename Poll = NeverCancel>
  Status run(SwarmT& s, Fitness& fitness, Rng& rng, double* curve, Poll poll = Poll()) {
    return run_optimiser(*this, s, fitness, rng, opt_.iterations, curve, poll);
  }

 private:
  Scalar fragrance(Scalar I) const {
    return Scalar(c_) * std::pow(std::abs(I), Scalar(opt_.a));
  }

  // The move of butterfly i from positions `from` into column `col` of `out`.
  template <typename From, typename Out>
  void move(const SwarmT& s, const From& from, Index i, Scalar fp, Rng& rng, Out& out,
            Index col, bool paper) const {
    const Index n = s.size();
    const Scalar lb = Scalar(opt_.lb), ub = Scalar(opt_.ub);
    const Scalar u = rng.uniform<Scalar>();
    if (u < Scalar(opt_.p)) {
      Scalar r;
      if (paper) {
        const Scalar r1 = rng.uniform<Scalar>();
        r = r1 * r1;
      } else {
        const Scalar r1 = rng.uniform<Scalar>();
        const Scalar r2 = rng.uniform<Scalar>();
        r = r1 * r2;
      }
      for (Index d = 0; d < s.dim(); ++d)
        out(d, col) = clip(from(d, i) + (r * s.best[d] - from(d, i)) * fp, lb, ub);
    } else {
      const Scalar e = rng.uniform<Scalar>();
      const Scalar r = e * e;
      const Index j = rng.index(static_cast<std::uint32_t>(n));
      Index k = rng.index(static_cast<std::uint32_t>(n - 1));
      if (k >= j) ++k;
      for (Index d = 0; d < s.dim(); ++d)
        out(d, col) = clip(from(d, i) + (r * from(d, j) - from(d, k)) * fp, lb, ub);
    }
  }

  template <typename Fitness>
  void iterate_author(SwarmT& s, Fitness& fitness, Rng& rng) {
    for (Index i = 0; i < s.size(); ++i) {
      move(s, s.x, i, fragrance(s.trial_fit[i]), rng, s.trial, i, false);
      const Scalar f = fitness(s.trial.col(i).data());
      ++s.evaluations;
      s.trial_fit[i] = f;
      if (f <= s.fit[i]) {
        s.x.col(i) = s.trial.col(i);
        s.fit[i] = f;
      }
      if (f <= s.best_fit) {
        s.best = s.trial.col(i);
        s.best_fit = f;
      }
    }
  }

  template <typename Fitness>
  void iterate_paper(SwarmT& s, Fitness& fitness, Rng& rng) {
    for (Index i = 0; i < s.size(); ++i) move(s, s.x, i, fragrance(s.fit[i]), rng, s.trial, i, true);
    fitness.batch(s.trial.data(), s.size(), s.trial_fit.data());
    s.evaluations += s.size();
    s.x = s.trial;
    s.fit = s.trial_fit;
    for (Index i = 0; i < s.size(); ++i)
      if (s.fit[i] <= s.best_fit) {
        s.best = s.x.col(i);
        s.best_fit = s.fit[i];
      }
  }

  BoaOptions opt_;
  double c_;
};

}  // namespace cdam::optim
