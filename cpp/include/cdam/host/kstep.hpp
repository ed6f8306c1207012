// k-step (simulation) training of a network used recurrently on a physics model's residual
// (issue [flights] item 5, [speed] item 5). Host code: allocates at setup, std::thread.
//
// The model (ns recurrent states s, ne exogenous network inputs e, H tanh hidden units):
//   x_t = [(s_t - m) / c ; e_t]                              (ni = ns + ne network inputs)
//   o_t = r o (W2 tanh(W1 x_t + b1) + b2)                     (the network's residual)
//   s_{t+1} = s_t + d_t + o_t + sum_l L_l s_{t-l}             (d_t: the physics increment,
//                                                              computed outside from the inputs)
// The linear part L = [L_0 .. L_{na-1}] (ns x na ns, optional: KStepShape::lin) carries a
// linear base model's state dependence (an ARX: L_0 = A_1 - I, L_l = A_{l+1}); states before
// a window's start are the measured ones (so a start a needs a >= na - 1).
// theta = [W1(:); b1; W2(:); b2] in the project's layout (column-major, W1 H x ni, W2 ns x H;
// reference/__init__.py), D = H ni + H + ns H + ns.
//
// The error: windows of K steps from the measured state s_a at each start a (the caller keeps
// windows inside one record); residual row (w, j, i) = omega_j (S[a + j, i] - s_hat_j,i) / q_i,
// j = 1..K (q: the error scale per state, omega: an optional weight per step, 1 without; or
// q_{j,i} / omega_j replaced by one scale per step and state, KStepShape::err_scale_k);
// mse = sum e^2 / (W K ns).
//
// Jacobian by forward sensitivities, G_j = d s_hat_j / d theta (D x ns), G_0 = 0:
//   G_{j+1} = G_j + G_j A_j^T + sum_l G_{j-l} L_l^T + B_j (G_i = 0 for i <= 0),  A_j = d o / d s = diag(r) W2 diag(1 - a^2) W1[:, :ns]
//   diag(1/c); B_j = d o / d theta at fixed s: dO_i/dW2[i,h] = r_i a_h, dO_i/db2[i] = r_i,
//   dO_i/dW1[h,k] = r_i W2[i,h] (1 - a_h^2) x_k, dO_i/db1[h] = r_i W2[i,h] (1 - a_h^2).
// Each step's G_j (I + A_j)^T and G_{j-l} L_l^T are tall-by-small products in register tiles
// (host::sensitivity_product, kstep_kernels.hpp; only G_{j+1}, G_j and the lags' G are kept).
// The rows of J = G / q of one window (K ns columns of D values) go through the rank update
// J'J += V V' (host::syrk_lower on the AVX2 path, Eigen's rankUpdate otherwise); J'e alongside.
//
// Threads: the windows are cut into fixed chunks (at most kMaxChunks, at least 8 windows each,
// from the window count alone); each chunk's partial sums go into its own slot and the slots are
// added in chunk order, so the result is bit-identical at any thread count.
//
// FLOPs of one J'J pass (the bound in benchmarks/bench_kstep.py): W K ns D (D + 1) for the lower
// triangle and the diagonal (a multiply-add counted as 2), about 2 W K ns (ns D + H ni) for the
// sensitivities and 2 W K (H ni + ns H) for the forward pass.
#ifdef CDAM_TARGET_EMBEDDED
#error "cdam/host/kstep.hpp is host-only (std::vector, std::thread)"
#endif
#pragma once
#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <system_error>
#include <thread>
#include <vector>

#include "../levenberg_marquardt.hpp"
#include "../status.hpp"
#include "kernels.hpp"
#include "kstep_kernels.hpp"

namespace cdam::host {

// One set of windows: S, E, Dr row-major (sample-major) N x ns, N x ne, N x ns; starts: W row
// indices a with a + K < N (checked by the caller: check_windows).
struct KStepData {
  const double* S = nullptr;
  const double* E = nullptr;
  const double* Dr = nullptr;
  Index N = 0;
  const long long* starts = nullptr;
  Index W = 0;
};

// The fixed parts of the problem: sizes, horizon and scales (each ns values).
struct KStepShape {
  Index ns = 0, ne = 0, H = 0, K = 0;
  const double* in_mean = nullptr;
  const double* in_scale = nullptr;
  const double* out_scale = nullptr;
  const double* err_scale = nullptr;
  const double* step_weight = nullptr;   // K weights of the steps' errors (null: all 1)
  const double* err_scale_k = nullptr;   // K x ns scales per step and state (row-major); given,
                                         // they replace err_scale / step_weight
  Index na = 0;                          // lags of the linear part (0: none)
  const double* lin = nullptr;           // L, ns x (na ns) row-major: L[i, l ns + k]
  Index ni() const { return ns + ne; }
  Index lin_lags() const { return lin ? na : 0; }
  Index dim() const { return H * ni() + H + ns * H + ns; }
};

inline bool check_windows(const KStepShape& sh, const KStepData& d) {
  for (Index w = 0; w < d.W; ++w)
    if (d.starts[w] < std::max<Index>(sh.lin_lags() - 1, 0) || d.starts[w] + sh.K >= d.N)
      return false;
  return true;
}

class KStep {
 public:
  static constexpr Index kMaxChunks = 16;

  KStep(const KStepShape& sh, int threads)
      : sh_(sh), D_(sh.dim()), threads_(std::max(1, threads)),
        scratch_(static_cast<size_t>(std::min<Index>(threads_, kMaxChunks))) {
    for (auto& s : scratch_) alloc(s);
    slots_.resize(static_cast<size_t>(kMaxChunks));
  }

  Index dim() const { return D_; }
  int threads() const { return threads_; }

  // Sum of squared errors over the windows of d (no derivatives).
  double sse(const double* theta, const KStepData& d) { return run(theta, d, nullptr, nullptr); }

  // SSE; J'e into jte (D); with jtj, J'J (D x D, column-major; lower triangle, then mirrored).
  double normal(const double* theta, const KStepData& d, double* jte, double* jtj) {
    return run(theta, d, jte, jtj);
  }

  // One window's residuals e (K ns) and, with J non-null, its Jacobian rows, J[r * D + p] =
  // d y_hat_r / d theta_p / q (row r = j ns + i for step j + 1), dense: for tests.
  void window(const double* theta, const KStepData& d, Index w, double* e, double* J) {
    Scratch& s = scratch_[0];
    rollout(theta, d, d.starts[w], s, e, J != nullptr);
    if (J)
      for (Index r = 0; r < sh_.K * sh_.ns; ++r)
        for (Index p = 0; p < D_; ++p) J[r * D_ + p] = s.V[static_cast<size_t>(r * D_ + p)];
  }

 private:
  struct Scratch {
    std::vector<double> x, a, g, c, A, G, V, e, st;
  };
  struct Slot {
    std::vector<double> jtj, jte;
    double sse = 0;
  };

  // Slots of the sensitivities kept: G_{j+1}, G_j and the linear part's lags G_{j-1} ..
  Index ring() const { return std::max<Index>(sh_.lin_lags(), 1) + 1; }
  double* slot(Scratch& s, Index j) const {
    return s.G.data() + (j % ring()) * D_ * sh_.ns;
  }

  void alloc(Scratch& s) const {
    const Index ns = sh_.ns, H = sh_.H;
    s.x.resize(static_cast<size_t>(sh_.ni()));
    s.a.resize(static_cast<size_t>(H));
    s.g.resize(static_cast<size_t>(H));
    s.c.resize(static_cast<size_t>(ns * H));
    s.A.resize(static_cast<size_t>(ns * ns));
    s.G.resize(static_cast<size_t>(D_ * ns * ring()));       // G_j in slot j % ring()
    s.V.resize(static_cast<size_t>(D_ * ns * sh_.K));
    s.e.resize(static_cast<size_t>(ns * sh_.K));
    s.st.resize(static_cast<size_t>(ns * (sh_.K + 1)));       // s_hat_0 .. s_hat_K
  }

  // One window from row a: residuals into e (K ns); with sens, the scaled sensitivities into
  // s.V (column r = j ns + i, D values each).
  void rollout(const double* th, const KStepData& d, long long a, Scratch& s, double* e,
               bool sens) const {
    const Index ns = sh_.ns, ne = sh_.ne, H = sh_.H, ni = sh_.ni(), D = D_;
    const double* W1 = th;                 // H x ni, column-major: W1[k H + h]
    const double* b1 = th + H * ni;
    const double* W2 = b1 + H;             // ns x H: W2[h ns + i]
    const double* b2 = W2 + ns * H;
    const Index o_b1 = H * ni, o_W2 = o_b1 + H, o_b2 = o_W2 + ns * H;
    const Index nl = sh_.lin_lags(), nlin = nl * ns;
    double* sh = s.st.data();   // sh + j ns: s_hat_j (s_hat_0 the measured start)
    for (Index i = 0; i < ns; ++i) sh[i] = d.S[a * ns + i];
    for (Index j = 0; j < sh_.K; ++j) {
      const Index t = static_cast<Index>(a) + j;
      const double* st = sh + j * ns;
      double* nx = sh + (j + 1) * ns;
      double* x = s.x.data();
      for (Index k = 0; k < ns; ++k) x[k] = (st[k] - sh_.in_mean[k]) / sh_.in_scale[k];
      for (Index l = 0; l < ne; ++l) x[ns + l] = d.E[t * ne + l];
      double* av = s.a.data();
      for (Index h = 0; h < H; ++h) av[h] = b1[h];
      for (Index k = 0; k < ni; ++k) {
        const double xk = x[k];
        const double* w = W1 + k * H;
        for (Index h = 0; h < H; ++h) av[h] += w[h] * xk;
      }
      for (Index h = 0; h < H; ++h) av[h] = std::tanh(av[h]);
      if (sens) {
        double* g = s.g.data();
        double* c = s.c.data();   // c[i H + h] = r_i W2[i,h] (1 - a_h^2)
        for (Index h = 0; h < H; ++h) g[h] = 1.0 - av[h] * av[h];
        for (Index i = 0; i < ns; ++i)
          for (Index h = 0; h < H; ++h) c[i * H + h] = sh_.out_scale[i] * W2[h * ns + i] * g[h];
        double* A = s.A.data();   // A[i ns + k] = d o_i / d s_k (+ L_0[i, k])
        for (Index i = 0; i < ns; ++i)
          for (Index k = 0; k < ns; ++k) {
            double acc = 0.0;
            for (Index h = 0; h < H; ++h) acc += c[i * H + h] * W1[k * H + h];
            A[i * ns + k] = acc / sh_.in_scale[k] + (nl ? sh_.lin[i * nlin + k] : 0.0);
          }
        // G_{j+1} = G_j (I + A)^T + sum_{l>=1} G_{j-l} L_l^T (G_i = 0 for i <= 0), then B
        double* Gn = slot(s, j + 1);
        if (j == 0) {
          std::fill(Gn, Gn + D * ns, 0.0);
        } else {
          for (Index i = 0; i < ns; ++i) A[i * ns + i] += 1.0;
          sensitivity_product(Gn, D, slot(s, j), D, A, ns, D, ns, ns, false);
          for (Index l = 1; l < nl && j - l >= 1; ++l)
            sensitivity_product(Gn, D, slot(s, j - l), D, sh_.lin + l * ns, nlin, D, ns, ns,
                                true);
        }
        for (Index i = 0; i < ns; ++i) {
          double* out = Gn + i * D;
          const double* ci = c + i * H;
          for (Index k = 0; k < ni; ++k) {
            const double xk = x[k];
            double* o = out + k * H;
            for (Index h = 0; h < H; ++h) o[h] += ci[h] * xk;
          }
          for (Index h = 0; h < H; ++h) out[o_b1 + h] += ci[h];
          const double ri = sh_.out_scale[i];
          for (Index h = 0; h < H; ++h) out[o_W2 + h * ns + i] += ri * av[h];
          out[o_b2 + i] += ri;
        }
      }
      for (Index i = 0; i < ns; ++i) {
        double o = b2[i];
        for (Index h = 0; h < H; ++h) o += W2[h * ns + i] * av[h];
        double lin = 0.0;
        for (Index l = 0; l < nl; ++l) {
          // s_{t-l}: predicted for j - l >= 1, else measured (row a + j - l)
          const double* sl = j - l >= 1 ? sh + (j - l) * ns : d.S + (t - l) * ns;
          const double* Li = sh_.lin + i * nlin + l * ns;
          for (Index k = 0; k < ns; ++k) lin += Li[k] * sl[k];
        }
        nx[i] = st[i] + d.Dr[t * ns + i] + sh_.out_scale[i] * o + lin;
      }
      const double wj = sh_.step_weight ? sh_.step_weight[j] : 1.0;
      for (Index i = 0; i < ns; ++i) {
        const double q = sh_.err_scale_k ? sh_.err_scale_k[j * ns + i] : sh_.err_scale[i] / wj;
        e[j * ns + i] = (d.S[(t + 1) * ns + i] - nx[i]) / q;
        if (sens) {
          const double* gi = slot(s, j + 1) + i * D;
          double* v = s.V.data() + (j * ns + i) * D;
          for (Index p = 0; p < D; ++p) v[p] = gi[p] / q;
        }
      }
    }
  }

  double run(const double* theta, const KStepData& d, double* jte, double* jtj) {
    const Index W = d.W;
    if (W == 0) {
      if (jte) std::fill(jte, jte + D_, 0.0);
      if (jtj) std::fill(jtj, jtj + D_ * D_, 0.0);
      return 0.0;
    }
    // fixed chunks from the window count alone
    const Index per = std::max<Index>(8, (W + kMaxChunks - 1) / kMaxChunks);
    const Index nchunks = (W + per - 1) / per;
    const bool wantj = jte != nullptr;
    const bool wantjj = jtj != nullptr;
    for (Index c = 0; c < nchunks; ++c) {
      Slot& sl = slots_[static_cast<size_t>(c)];
      sl.sse = 0.0;
      if (wantj) sl.jte.assign(static_cast<size_t>(D_), 0.0);
      if (wantjj) sl.jtj.assign(static_cast<size_t>(D_ * D_), 0.0);
    }
    const int nt = static_cast<int>(std::min<Index>(threads_, nchunks));
    auto work = [&](int tid) {
      Scratch& s = scratch_[static_cast<size_t>(tid)];
      for (Index c = tid; c < nchunks; c += nt) {
        Slot& sl = slots_[static_cast<size_t>(c)];
        const Index w0 = c * per, w1 = std::min(W, w0 + per);
        for (Index w = w0; w < w1; ++w) chunk_window(theta, d, w, s, sl, wantj, wantjj);
      }
    };
    if (nt == 1) {
      work(0);
    } else {
      std::vector<std::thread> pool;
      int started = 1;
      try {
        for (int t = 1; t < nt; ++t, ++started) pool.emplace_back(work, t);
      } catch (const std::system_error&) {
      }
      work(0);
      for (auto& th : pool) th.join();
      for (int t = started; t < nt; ++t) work(t);   // no thread to spare: same chunks, same bits
    }
    double sse = 0.0;
    if (wantj) std::fill(jte, jte + D_, 0.0);
    if (wantjj) std::fill(jtj, jtj + D_ * D_, 0.0);
    for (Index c = 0; c < nchunks; ++c) {
      const Slot& sl = slots_[static_cast<size_t>(c)];
      sse += sl.sse;
      if (wantj)
        for (Index p = 0; p < D_; ++p) jte[p] += sl.jte[static_cast<size_t>(p)];
      if (wantjj)
        for (Index q = 0; q < D_; ++q)
          for (Index p = q; p < D_; ++p) jtj[q * D_ + p] += sl.jtj[static_cast<size_t>(q * D_ + p)];
    }
    if (wantjj)
      for (Index q = 0; q < D_; ++q)
        for (Index p = q + 1; p < D_; ++p) jtj[p * D_ + q] = jtj[q * D_ + p];
    return sse;
  }

  void chunk_window(const double* theta, const KStepData& d, Index w, Scratch& s, Slot& sl,
                    bool wantj, bool wantjj) const {
    const Index R = sh_.K * sh_.ns;
    rollout(theta, d, d.starts[w], s, s.e.data(), wantj);
    const double* e = s.e.data();
    double sse = 0.0;
    for (Index r = 0; r < R; ++r) sse += e[r] * e[r];
    sl.sse += sse;
    if (!wantj) return;
    const double* V = s.V.data();
    for (Index r = 0; r < R; ++r) {
      const double er = e[r];
      const double* v = V + r * D_;
      double* g = sl.jte.data();
      for (Index p = 0; p < D_; ++p) g[p] += v[p] * er;
    }
    if (!wantjj) return;
    if (avx2_path(KernelPath::Auto)) {
      syrk_lower(sl.jtj.data(), D_, V, D_, D_, R);
    } else {
      Eigen::Map<Eigen::MatrixXd> G(sl.jtj.data(), D_, D_);
      Eigen::Map<const Eigen::MatrixXd> Vm(V, D_, R);
      G.selfadjointView<Eigen::Lower>().rankUpdate(Vm);
    }
  }

  KStepShape sh_;
  Index D_;
  int threads_;
  std::vector<Scratch> scratch_;
  std::vector<Slot> slots_;
};

// lm_train's policy (levenberg_marquardt.hpp) on the k-step error: J'J and J'e from KStep,
// (J'J + mu I) d = J'e by the AVX2 blocked Cholesky or Eigen's LLT; optional validation windows.
class LmKStep {
 public:
  using Scalar = double;
  LmKStep(const KStepShape& sh, const KStepData& train, const KStepData* val, int threads)
      : ks_(sh, threads), train_(train), val_(val), D_(sh.dim()),
        n_train_(static_cast<double>(train.W * sh.K * sh.ns)),
        n_val_(val && val->W > 0 ? static_cast<double>(val->W * sh.K * sh.ns) : 1.0),
        trial_(D_), best_(D_), jte_(D_), step_(D_), jtj_(D_, D_), lhs_(D_, D_), llt_(D_) {}

  Index dim() const { return D_; }
  double train_mse(const double* th) { return ks_.sse(th, train_) / n_train_; }
  double normal(const double* th, bool with_jtj) {
    ks_.normal(th, train_, jte_.data(), with_jtj ? jtj_.data() : nullptr);
    return jte_.norm();
  }
  bool solve(double mu) {
    lhs_ = jtj_;
    lhs_.diagonal().array() += mu;
    if (avx2_path(KernelPath::Auto)) {
      if (!cholesky_lower(lhs_.data(), D_, D_)) return false;
      step_ = jte_;
      cholesky_solve(lhs_.data(), D_, D_, step_.data());
      return step_.allFinite();
    }
    llt_.compute(lhs_);
    if (llt_.info() != Eigen::Success) return false;
    step_ = llt_.solve(jte_);
    return step_.allFinite();
  }
  bool validation() const { return val_ != nullptr && val_->W > 0; }
  double val_mse(const double* th) { return ks_.sse(th, *val_) / n_val_; }
  double* step() { return step_.data(); }
  double* trial() { return trial_.data(); }
  double* best() { return best_.data(); }

 private:
  KStep ks_;
  KStepData train_;
  const KStepData* val_;
  Index D_;
  double n_train_, n_val_;
  Eigen::VectorXd trial_, best_, jte_, step_;
  Eigen::MatrixXd jtj_, lhs_;
  Eigen::LLT<Eigen::MatrixXd> llt_;
};

}  // namespace cdam::host
