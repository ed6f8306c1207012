// Caller-owned storage of a population-based optimiser (BOA, IBOA, CABC) and the fitness concept.
//
// Sizes are template parameters: Dim (decision-vector length D) and Pop (population n) fixed on
// the target (no heap at all), Eigen::Dynamic on the host (the constructor is the one place that
// allocates; the iterations never do). One column is one individual.
//
// Fitness concept (minimised): an object `f` with
//   Scalar f(const Scalar* x)                                one individual, D values;
//   void   f.batch(const Scalar* X, Index n, Scalar* out)    n individuals stored as a
//                                                            column-major D x n block.
// The optimisers call batch() wherever the algorithm's semantics let several individuals be
// evaluated independently (initialisation, the paper-form BOA move, IBOA's competitive and
// chaotic phases, CABC's scout candidates); a host fitness spreads those over threads.
// `SerialFitness` turns a plain callable Scalar(const Scalar*) into the concept.
#pragma once
#include <Eigen/Core>

#include "../mlp.hpp"
#include "../rng.hpp"
#include "../safe_size.hpp"
#include "../status.hpp"

namespace cdam::optim {

using cdam::Index;

template <typename Scalar_, int Dim = Eigen::Dynamic, int Pop = Eigen::Dynamic>
struct Swarm {
  using Scalar = Scalar_;
  using Positions = Eigen::Matrix<Scalar, Dim, Pop>;  // D x n
  using Values = Eigen::Matrix<Scalar, Pop, 1>;       // n
  using Labels = Eigen::Matrix<int, Pop, 1>;          // n
  using Point = Eigen::Matrix<Scalar, Dim, 1>;        // D

  Positions x;         // D x n   current positions (BOA: Sol; CABC: food sources, first n/2)
  Values fit;          // n       fitness of x
  Positions trial;     // D x n   BOA's last trial point per butterfly (the author's S)
  Values trial_fit;    // n       fitness of trial
  Positions scratch;   // D x n   candidates evaluated in one batch; k-means centres (IBOA)
  Values scratch_fit;  // n
  Positions centres;   // D x n   k-means centres (first k columns)
  Labels label;        // n       k-means cluster of each butterfly
  Labels counter;      // n       k-means cluster sizes / CABC trial counters
  Labels perm;         // n       k-means seeding permutation
  Point best;          // D       the best position found (g*)
  Scalar best_fit = Scalar(0);
  long evaluations = 0;

  Swarm(Index dim = Dim, Index n = Pop)
      : x(dim, n), fit(n), trial(dim, n), trial_fit(n), scratch(dim, n), scratch_fit(n),
        centres(dim, n), label(n), counter(n), perm(n), best(dim) {}

  Index dim() const { return x.rows(); }
  Index size() const { return x.cols(); }
};

// Wraps a callable Scalar(const Scalar* x) as a fitness (batch = a loop).
template <typename Scalar, typename F>
struct SerialFitness {
  F f;
  Index dim;
  Scalar operator()(const Scalar* x) { return f(x); }
  void batch(const Scalar* X, Index n, Scalar* out) {
    for (Index k = 0; k < n; ++k) out[k] = f(X + k * dim);
  }
};
template <typename Scalar, typename F>
SerialFitness<Scalar, F> serial_fitness(F f, Index dim) { return {f, dim}; }

template <typename Scalar>
inline Scalar clip(Scalar v, Scalar lb, Scalar ub) {
  return v < lb ? lb : (v > ub ? ub : v);
}

// Index of the smallest (largest when `largest`) of v[0..n-1]; ties go to the lowest index.
template <typename V>
inline Index arg_extreme(const V& v, Index n, bool largest = false) {
  Index k = 0;
  for (Index i = 1; i < n; ++i)
    if (largest ? v[i] > v[k] : v[i] < v[k]) k = i;
  return k;
}

// init, then `iterations` iterations of any optimiser with init()/iterate() (BOA, IBOA, CABC);
// curve (iterations + 1 values, may be null) receives the best fitness after each. `poll`
// (status.hpp) is asked before every iteration; false ends the run with Status::Cancelled.
template <typename Optimiser, typename SwarmT, typename Fitness, typename Poll = NeverCancel>
Status run_optimiser(Optimiser& o, SwarmT& s, Fitness& fitness, Rng& rng, int iterations,
                     double* curve, Poll poll = Poll()) {
  const Status st = o.init(s, fitness, rng);
  if (st != Status::Ok) return st;
  if (curve) curve[0] = static_cast<double>(s.best_fit);
  for (int t = 1; t <= iterations; ++t) {
    if (!poll()) return Status::Cancelled;
    o.iterate(s, fitness, rng);
    if (curve) curve[t] = static_cast<double>(s.best_fit);
  }
  return Status::Ok;
}

}  // namespace cdam::optim
