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
// FitnessPrecision::Float32 (the swarm search's fast form, issue 23 item 3): the record is kept
// in float, the batch's parameters are rounded to float once, and every chunk runs
// host/kernels_f32.hpp (8 or 16 floats a vector, chosen at run time), its chunk boundaries
// multiples of 16 samples; the partials stay double and are summed in chunk order as above, so
// this form too is bit-identical at any thread count. Its MSE agrees with the double one to
// float rounding (about 1e-7 relative). Parked pool threads first spin briefly (a few
// microseconds, `kSpin` polls) before they sleep, so the short batches of the sequential BOA
// move do not wait for a wake-up each time.
#ifdef CDAM_TARGET_EMBEDDED
#error "cdam/host/bp_fitness.hpp is host-only (std::thread, std::mutex, std::vector); the target uses cdam/optim/mlp_fitness.hpp"
#endif
#pragma once
#include <Eigen/Core>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <type_traits>
#include <vector>

#include "../mlp.hpp"
#include "../optim/mlp_fitness.hpp"
#include "kernels.hpp"
#include "kernels_f32.hpp"
#include "normal_equations.hpp"

namespace cdam::optim {

using host::KernelPath;

// The arithmetic of BpFitness' kernel (the swarm search's; LM is always double).
enum class FitnessPrecision { Float64 = 0, Float32 = 1 };

// BpFitness<double> (host, any thread count); the kernel is double only.
template <typename Scalar>
class BpFitness {
  static_assert(std::is_same<Scalar, double>::value, "BpFitness: the host kernel is double only");

 public:
  using Map = typename NormalEquations<Scalar>::ConstMap;
  static constexpr Index kBlock = 128;     // samples per kernel block (L1-resident)
  static constexpr Index kBlockF32 = 256;  // the same for the float32 kernel
  static constexpr int kSpin = 2000;       // pause polls (tens of microseconds) before a sleep

  // X: i x N, T: m x N (column = sample). The constructor copies them once into a
  // channel-contiguous (structure-of-arrays) layout, the kernel's; the caller's arrays are not
  // kept.
  BpFitness(const Mlp<Scalar>& net, const Map& X, const Map& T, int threads = 2,
            Index max_batch = 64, FitnessPrecision precision = FitnessPrecision::Float64)
      : net_(net), n_(X.cols()), threads_(std::min(16, std::max(1, threads))),
        f32_(precision == FitnessPrecision::Float32) {
    const Index i = X.rows(), m = T.rows();
    if (f32_) {
      xf_.resize(static_cast<size_t>(n_ * i));
      tf_.resize(static_cast<size_t>(n_ * m));
      for (Index s = 0; s < n_; ++s) {
        for (Index l = 0; l < i; ++l) xf_[static_cast<size_t>(l * n_ + s)] = to_float(X(l, s));
        for (Index k = 0; k < m; ++k) tf_[static_cast<size_t>(k * n_ + s)] = to_float(T(k, s));
      }
      workf_.resize(static_cast<size_t>(threads_ * net_.hidden() * kBlockF32));
      thf_.resize(static_cast<size_t>(max_batch * dim()));
      f32_path_ = host::f32_path();
    } else {
      xs_.resize(static_cast<size_t>(n_ * i));
      ts_.resize(static_cast<size_t>(n_ * m));
      for (Index s = 0; s < n_; ++s) {
        for (Index l = 0; l < i; ++l) xs_[static_cast<size_t>(l * n_ + s)] = X(l, s);
        for (Index k = 0; k < m; ++k) ts_[static_cast<size_t>(k * n_ + s)] = T(k, s);
      }
      work_.resize(static_cast<size_t>(threads_ * net_.hidden() * kBlock));
    }
    chunks_ = std::max<Index>(1, std::min<Index>(16, n_ / 256));
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
  FitnessPrecision precision() const {
    return f32_ ? FitnessPrecision::Float32 : FitnessPrecision::Float64;
  }
  // KernelPath::Generic forces the SSE2 build of the kernel (tests compare both paths); for
  // float32 it caps the path at 0 (generic), Auto restores the CPU's best.
  void set_path(KernelPath p) {
    path_ = p;
    f32_path_ = host::f32_path(p == KernelPath::Generic ? 0 : 2);
  }
  // float32: caps the kernel's path (0 generic, 1 AVX2, 2 AVX-512; tests compare them).
  void set_f32_path_limit(int limit) { f32_path_ = host::f32_path(limit); }
  int f32_path() const { return f32_path_; }

  Scalar operator()(const Scalar* theta) {
    Scalar f;
    batch(theta, 1, &f);
    return f;
  }

  // n individuals (column-major D x n) -> n MSE values.
  void batch(const Scalar* thetas, Index n, Scalar* out) {
    const Index tasks = n * chunks_;
    if (static_cast<size_t>(tasks) > parts_.size()) parts_.resize(static_cast<size_t>(tasks));
    if (f32_) {  // the batch's parameters rounded to float once
      const Index len = n * dim();
      if (static_cast<size_t>(len) > thf_.size()) thf_.resize(static_cast<size_t>(len));
      for (Index q = 0; q < len; ++q) thf_[static_cast<size_t>(q)] = to_float(thetas[q]);
    }
    job_thetas_ = thetas;
    job_tasks_ = tasks;
    next_.store(0, std::memory_order_relaxed);
    if (pool_.empty() || tasks < 2 || n_ * n < 2048) {
      drain(0);
    } else {
      {
        std::lock_guard<std::mutex> lk(mu_);
        active_.store(static_cast<int>(pool_.size()), std::memory_order_relaxed);
        generation_.store(generation_.load(std::memory_order_relaxed) + 1,
                          std::memory_order_release);
      }
      start_.notify_all();
      drain(0);
      for (int k = 0; k < kSpin && active_.load(std::memory_order_acquire) != 0; ++k) cpu_relax();
      if (active_.load(std::memory_order_acquire) != 0) {
        std::unique_lock<std::mutex> lk(mu_);
        done_.wait(lk, [this] { return active_.load(std::memory_order_acquire) == 0; });
      }
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
      if (f32_) {  // chunk boundaries on whole 16-float vectors
        const Index lo = c == 0 ? 0 : (n_ * c / chunks_) & ~Index(15);
        const Index hi = c + 1 == chunks_ ? n_ : (n_ * (c + 1) / chunks_) & ~Index(15);
        float* a = workf_.data() + static_cast<size_t>(t) * net_.hidden() * kBlockF32;
        parts_[static_cast<size_t>(q)] = host::sse_soa_f32(
            net_.inputs(), net_.hidden(), net_.outputs(), net_.activation(),
            thf_.data() + ind * D, xf_.data() + lo, tf_.data() + lo, n_, hi - lo, a, kBlockF32,
            f32_path_);
        continue;
      }
      const Index lo = n_ * c / chunks_, hi = n_ * (c + 1) / chunks_;
      parts_[static_cast<size_t>(q)] = chunk_sse(job_thetas_ + ind * D, lo, hi, t);
    }
  }

  // double -> float, saturating to +-inf beyond the float range (a plain cast is undefined
  // there); NaN stays NaN. The bindings refuse records beyond the float range by name.
  static float to_float(double v) {
    constexpr double kMax = 3.4028234663852886e38;  // FLT_MAX
    return v > kMax ? HUGE_VALF : (v < -kMax ? -HUGE_VALF : static_cast<float>(v));
  }

  static void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#endif
  }

  void worker(int t) {
    long seen = 0;
    for (;;) {
      // a short spin first (the next batch of a sequential optimiser comes within
      // microseconds), then sleep on the condition variable
      for (int k = 0; k < kSpin && generation_.load(std::memory_order_acquire) == seen; ++k)
        cpu_relax();
      {
        std::unique_lock<std::mutex> lk(mu_);
        start_.wait(lk, [&] {
          return stop_ || generation_.load(std::memory_order_relaxed) != seen;
        });
        if (stop_) return;
        seen = generation_.load(std::memory_order_relaxed);
      }
      drain(t);
      if (active_.fetch_sub(1, std::memory_order_acq_rel) == 1) {
        std::lock_guard<std::mutex> lk(mu_);
        done_.notify_one();
      }
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
  bool f32_;
  KernelPath path_ = KernelPath::Auto;
  int f32_path_ = 0;
  std::vector<Scalar> xs_, ts_;  // N x i and N x m, channel-contiguous
  std::vector<float> xf_, tf_;   // the same in float (float32 precision only)
  std::vector<float> workf_;     // per thread: h kBlockF32 floats
  std::vector<float> thf_;       // the batch's parameters in float
  std::vector<Scalar> work_;     // per thread: the hidden activations of a block (h kBlock)
  std::vector<double> parts_;
  // the worker pool (threads - 1 threads started by the constructor, parked between batches)
  std::vector<std::thread> pool_;
  std::mutex mu_;
  std::condition_variable start_, done_;
  std::atomic<long> generation_{0};
  std::atomic<int> active_{0};
  bool stop_ = false;
  const Scalar* job_thetas_ = nullptr;
  Index job_tasks_ = 0;
  std::atomic<Index> next_{0};
};

}  // namespace cdam::optim
