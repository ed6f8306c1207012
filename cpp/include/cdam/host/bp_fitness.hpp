// The host's BP fitness of the optimisers (semantics: optim/mlp_fitness.hpp, MSE = sum (T - Y)^2
// / (N m), minimised), fast and threaded.
//
// BpFitness<Scalar> (host): the record is copied once into a channel-contiguous layout and
// cut into a fixed number of contiguous chunks that depends only on N; every (individual,
// chunk) partial SSE is computed by one thread with the vectorised kernel of host/kernels.hpp
// (blocks of 128 samples, one exponential and one division per activation, AVX2 + FMA when
// the CPU has them). threads - 1 pool threads, started by the constructor and parked on a
// condition variable between batches, and the caller take tasks from a shared counter (a
// descheduled thread delays only the chunk it holds); the partials of an individual are summed
// in chunk order. The result is therefore bit-identical for any thread count. The constructor allocates (the one place);
// evaluating allocates nothing unless a batch is larger than any seen before.
#ifdef CDAM_TARGET_EMBEDDED
#error "cdam/host/bp_fitness.hpp is host-only (std::thread, std::mutex, std::vector); the target uses cdam/optim/mlp_fitness.hpp"
#endif
#pragma once
#include <Eigen/Core>
#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <type_traits>
#include <vector>

#include "../mlp.hpp"
#include "../optim/mlp_fitness.hpp"
#include "kernels.hpp"
#include "normal_equations.hpp"

namespace cdam::optim {

using host::KernelPath;

// BpFitness<double> (host, any thread count); the kernel is double only.
template <typename Scalar>
class BpFitness {
  static_assert(std::is_same<Scalar, double>::value, "BpFitness: the host kernel is double only");

 public:
  using Map = typename NormalEquations<Scalar>::ConstMap;
  static constexpr Index kBlock = 128;  // samples per kernel block (L1-resident)

  // X: i x N, T: m x N (column = sample). The constructor copies them once into a
  // channel-contiguous (structure-of-arrays) layout, the kernel's; the caller's arrays are not
  // kept.
  BpFitness(const Mlp<Scalar>& net, const Map& X, const Map& T, int threads = 2,
            Index max_batch = 64)
      : net_(net), n_(X.cols()), threads_(std::min(16, std::max(1, threads))) {
    const Index i = X.rows(), m = T.rows();
    xs_.resize(static_cast<size_t>(n_ * i));
    ts_.resize(static_cast<size_t>(n_ * m));
    for (Index s = 0; s < n_; ++s) {
      for (Index l = 0; l < i; ++l) xs_[static_cast<size_t>(l * n_ + s)] = X(l, s);
      for (Index k = 0; k < m; ++k) ts_[static_cast<size_t>(k * n_ + s)] = T(k, s);
    }
    chunks_ = std::max<Index>(1, std::min<Index>(16, n_ / 256));
    work_.resize(static_cast<size_t>(threads_ * net_.hidden() * kBlock));
    parts_.resize(static_cast<size_t>(max_batch * chunks_));
    try {
      for (int t = 1; t < threads_; ++t) pool_.emplace_back(&BpFitness::worker, this, t);
    } catch (...) {  // no thread left running if one cannot be started
      stop_pool();
      throw;
    }
  }

  BpFitness(const BpFitness&) = delete;
  BpFitness& operator=(const BpFitness&) = delete;

  Index dim() const { return net_.num_params(); }
  int threads() const { return threads_; }
  Index chunks() const { return chunks_; }
  // KernelPath::Generic forces the SSE2 build of the kernel (tests compare both paths).
  void set_path(KernelPath p) { path_ = p; }

  Scalar operator()(const Scalar* theta) {
    Scalar f;
    batch(theta, 1, &f);
    return f;
  }

  // n individuals (column-major D x n) -> n MSE values.
  void batch(const Scalar* thetas, Index n, Scalar* out) {
    const Index tasks = n * chunks_;
    if (static_cast<size_t>(tasks) > parts_.size()) parts_.resize(static_cast<size_t>(tasks));
    job_thetas_ = thetas;
    job_tasks_ = tasks;
    next_.store(0, std::memory_order_relaxed);
    if (pool_.empty() || tasks < 2 || n_ * n < 2048) {
      drain(0);
    } else {
      {
        std::lock_guard<std::mutex> lk(mu_);
        active_ = static_cast<int>(pool_.size());
        ++generation_;
      }
      start_.notify_all();
      drain(0);
      std::unique_lock<std::mutex> lk(mu_);
      done_.wait(lk, [this] { return active_ == 0; });
    }
    const double nm = static_cast<double>(n_ * net_.outputs());
    for (Index ind = 0; ind < n; ++ind) {
      double sse = 0;
      for (Index c = 0; c < chunks_; ++c) sse += parts_[static_cast<size_t>(ind * chunks_ + c)];
      out[ind] = static_cast<Scalar>(sse / nm);
    }
  }

  ~BpFitness() { stop_pool(); }

 private:
  void stop_pool() {
    {
      std::lock_guard<std::mutex> lk(mu_);
      stop_ = true;
    }
    start_.notify_all();
    for (auto& th : pool_) th.join();
    pool_.clear();
  }

  // Takes (individual, chunk) tasks from the shared counter until none is left; the partial of
  // task q always goes to parts_[q], whoever computes it.
  void drain(int t) {
    const Index D = dim();
    for (;;) {
      const Index q = next_.fetch_add(1, std::memory_order_relaxed);
      if (q >= job_tasks_) return;
      const Index ind = q / chunks_, c = q % chunks_;
      const Index lo = n_ * c / chunks_, hi = n_ * (c + 1) / chunks_;
      parts_[static_cast<size_t>(q)] = chunk_sse(job_thetas_ + ind * D, lo, hi, t);
    }
  }

  void worker(int t) {
    long seen = 0;
    for (;;) {
      {
        std::unique_lock<std::mutex> lk(mu_);
        start_.wait(lk, [&] { return stop_ || generation_ != seen; });
        if (stop_) return;
        seen = generation_;
      }
      drain(t);
      std::lock_guard<std::mutex> lk(mu_);
      if (--active_ == 0) done_.notify_one();
    }
  }

  double chunk_sse(const Scalar* theta, Index lo, Index hi, int t) {
    Scalar* a = work_.data() + static_cast<size_t>(t) * net_.hidden() * kBlock;
    return host::sse_soa(net_, theta, xs_.data() + lo, ts_.data() + lo, n_, hi - lo, a, kBlock, path_);
  }

  Mlp<Scalar> net_;
  Index n_;
  int threads_;
  Index chunks_;
  KernelPath path_ = KernelPath::Auto;
  std::vector<Scalar> xs_, ts_;  // N x i and N x m, channel-contiguous
  std::vector<Scalar> work_;     // per thread: the hidden activations of a block (h kBlock)
  std::vector<double> parts_;
  // the worker pool (threads - 1 threads started by the constructor, parked between batches)
  std::vector<std::thread> pool_;
  std::mutex mu_;
  std::condition_variable start_, done_;
  long generation_ = 0;
  int active_ = 0;
  bool stop_ = false;
  const Scalar* job_thetas_ = nullptr;
  Index job_tasks_ = 0;
  std::atomic<Index> next_{0};
};

}  // namespace cdam::optim
