// Batch evaluation of the BP network on a record: sum of squared errors, J'e and J'J, computed in
// blocks of samples so that memory does not grow with the record length, and without forming J.
//
// Structure used (z = [x; 1], a' = [a; 1], d = f'(a), Q = W2' W2, hidden parameters ordered
// l h + j for [W1 b1](j, l), output parameters j m + k for [W2 b2](k, j)):
//   J'J hidden-hidden  (l h + j, l' h + j') = Q(j, j') * S(l h + j, l' h + j'),  S = sum_n v v',
//                      v = kron(z, d)                                     (h(i+1))^2 per sample
//   J'J output-output  (j m + k, j' m + k') = delta(k, k') R(j, j'),      R = sum_n a' a'^T
//   J'J output-hidden  (j'' m + k, l h + j) = W2(k, j) C(j'', l h + j),   C = sum_n a' v'
//   J'e hidden = vec(sum_n ((W2' e) .* d) z'),  J'e output = vec(sum_n e a'^T),  e = t - y.
// Per sample this costs about (h(i+1))^2 / 2 + (h+1) h (i+1) multiply-adds instead of the
// m D^2 of forming J'J from J: for 6-20-8 about 12,700 against 759,000.
//
// S's entry (l h + j, l' h + j') is sum z_l z_l' d_j d_j': symmetric in (l, l') and in (j, j')
// separately. On a CPU with AVX2 + FMA (double), modes 1 and 2 run two hand kernels per block
// (host/kernels.hpp, issue 23 item 2): grad_block (the forward pass, e, g = (W2' e) .* d, the
// gradient sums as register tiles over [e; g] against [a; 1; x; 1], and the rows of V) and
// jtj_reduced: S as one dense product of the h (h + 1) / 2 pair products d_j d_j' against the
// (i + 1)(i + 2) / 2 products z_l z_l' (5,880 multiply-adds a sample for 6-20-8, no triangle
// waste), C and R (with the row sums of v and a) from [a; 1] against [v; a; 1]; about 9,700
// multiply-adds a sample with the padding, near the 1-core DGEMM rate. 10,000 x 6-20-8, shared
// 2-core EPYC, thread CPU: gradient pass 1.6 -> 1.0 ms, gradient + J'J 6.9 -> 5.9 ms against
// the zero-padded lower triangles of session 6 (jtj_blocks_padded) and Eigen's SSE2 products.
// Otherwise S, C and R come from Eigen's rankUpdate and products, as written above.
// Mode 0 (the SSE alone: LM's trial and validation passes) in double is host/kernels.hpp's
// sse_soa on blocks of 128 samples transposed on the fly.
// Float (issue 23 item 1, session 8), on an AVX2 + FMA CPU: the same layout with blocks padded to
// 8 rows, host/kernels_f32.hpp's float twins of grad_block and jtj_reduced (float products and
// sums over 32-sample slices, added into double accumulators: K, Kh, gHp, gOp are double for both
// Scalars) and its float SSE kernel for mode 0; evaluate_d returns J'e and J'J in double (the
// float LM solves in double). Otherwise Eigen's float products as before.
// The hidden activation (double) is the vectorised one of host/kernels.hpp (within 5e-16 of
// std::tanh / the logistic function; about ten times faster than the scalar libm call).
// Threads and determinism: the record is cut into chunks of whole blocks whose number
// (clamp(blocks / 4, 1, 16)) and boundaries depend only on N and the block size, never on the
// thread count; each thread computes a chunk's partial sums into its own slot and adds them to
// the total in chunk order (a thread waits until the chunks before its own are in), so the
// sums are ((p0 + p1) + p2) + ... for any thread count: the results are bit-identical at 1, 2
// or more threads (issue 24 item 7). Memory: one slot per thread plus the total, as before.
// Measured (10,000 samples, 6-20-8, shared 2-core EPYC, best of 8 runs against the former
// one-part-per-thread split): J'J 12.2 -> 12.5 ms at 1 thread, 6.9 -> 7.0 ms at 2; an LM epoch
// 15.9 -> 15.9 ms and 9.4 -> 9.5 ms (one 160 x 160 band add per 1,024-sample chunk).
// This is host code: the workspace is allocated once, in the constructor (the one place that
// allocates); evaluate() allocates nothing on one thread (more threads: the std::thread objects).
#ifdef CDAM_TARGET_EMBEDDED
#error "cdam/host/normal_equations.hpp is host-only (allocates, std::thread, AVX2 kernels)"
#endif
#pragma once
#include <Eigen/Core>
#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <mutex>
#include <system_error>
#include <thread>
#include <type_traits>
#include <vector>

#include "../mlp.hpp"
#include "kernels.hpp"
#include "kernels_f32.hpp"

namespace cdam {

template <typename Scalar>
class NormalEquations {
 public:
  using Mat = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;
  using Vec = Eigen::Matrix<Scalar, Eigen::Dynamic, 1>;
  using ConstMap = Eigen::Map<const Mat>;
  using Net = Mlp<Scalar>;
  // The record's sums (the fused path's accumulators, J'J and J'e before the output's type).
  using MatD = Eigen::MatrixXd;
  using VecD = Eigen::VectorXd;

  // A record of B blocks of samples is cut into clamp(B / kMinChunkBlocks, 1, kMaxChunks)
  // chunks of whole blocks (a record of fewer than 4 blocks is one chunk).
  static constexpr Index kMaxChunks = 16;
  static constexpr Index kMinChunkBlocks = 4;

  explicit NormalEquations(const Net& net, Index block = 256, int threads = 1)
      : net_(net), block_(std::max<Index>(1, block)), threads_(std::max(1, threads)),
        total_(net_, fused_path()) {
    const Index nt = std::min<Index>(threads_, kMaxChunks);
    scratch_.reserve(static_cast<size_t>(nt));
    for (Index t = 0; t < nt; ++t) scratch_.emplace_back(net_, block_);
    const Index P = net_.hidden() * (net_.inputs() + 1);
    S_.resize(P, P);
    C_.resize(net_.hidden() + 1, P);
    R_.resize(net_.hidden() + 1, net_.hidden() + 1);
  }

  int threads() const { return threads_; }

  // The number of chunks of an n-sample record; chunk c holds the blocks
  // [nblocks c / chunks, nblocks (c + 1) / chunks). A function of n and the block size only,
  // never of the thread count.
  Index chunks(Index n) const {
    const Index blocks = (n + block_ - 1) / block_;
    return std::max<Index>(1, std::min(kMaxChunks, blocks / kMinChunkBlocks));
  }

  // X: i x N, T: m x N (column = sample). Returns the sum of squared errors; fills Jte (D) when
  // jte is non-null and JtJ (D x D) when jtj is non-null.
  // Threads take chunks in order from a shared counter; each computes its chunk's partial sums
  // (sse, J'e, J'J blocks) into its own slot and then adds them to the total strictly in chunk
  // order (chunk 0 is computed in the total; chunk c is added once chunks 0 .. c - 1 are). The
  // total is therefore ((p0 + p1) + p2) + ... whoever computed each p: bit-identical for any
  // thread count.
  double evaluate(const Scalar* theta, const ConstMap& X, const ConstMap& T, Vec* jte, Mat* jtj) {
    return evaluate_into(theta, X, T, jte, jtj);
  }
  // The same with J'e and J'J in double whatever the Scalar (the float LM's solve).
  double evaluate_d(const Scalar* theta, const ConstMap& X, const ConstMap& T, VecD* jte,
                    MatD* jtj) {
    return evaluate_into(theta, X, T, jte, jtj);
  }

  template <class VOut, class MOut>
  double evaluate_into(const Scalar* theta, const ConstMap& X, const ConstMap& T, VOut* jte,
                       MOut* jtj) {
    const Index n = X.cols();
    const Index nc = chunks(n);
    const int mode = jtj ? 2 : (jte ? 1 : 0);
    const Index blocks = (n + block_ - 1) / block_;
    std::atomic<Index> next{0};
    std::mutex mu;
    std::condition_variable turn;
    Index added = 0;  // chunks [0, added) are in total_ (guarded by mu)
    auto drain = [&](int t) {
      Scratch& w = scratch_[static_cast<size_t>(t)];
      for (;;) {
        const Index c = next.fetch_add(1, std::memory_order_relaxed);
        if (c >= nc) return;
        const Index lo = std::min(n, block_ * (blocks * c / nc));
        const Index hi = std::min(n, block_ * (blocks * (c + 1) / nc));
        w.run(theta, X, T, lo, hi, mode, c == 0 ? total_ : w.part);
        std::unique_lock<std::mutex> lk(mu);
        turn.wait(lk, [&] { return added == c; });
        if (c > 0) total_.add(w.part, mode);
        added = c + 1;
        lk.unlock();
        turn.notify_all();
      }
    };
    const int nt = static_cast<int>(std::min<Index>(static_cast<Index>(scratch_.size()), nc));
    if (nt <= 1) {
      drain(0);
    } else {
      std::vector<std::thread> pool;
      pool.reserve(static_cast<size_t>(nt - 1));
      for (int t = 1; t < nt; ++t) {
        try {
          pool.emplace_back(drain, t);
        } catch (const std::system_error&) {  // no thread to spare: fewer threads, same bits
          break;
        }
      }
      drain(0);
      for (auto& th : pool) th.join();
    }
    Slot& s = total_;
    const Index h = net_.hidden();
    if (mode >= 1) {
      if (s.fused)
        assemble_gradient(s.gHp.topLeftCorner(h, s.gH.cols()),
                          s.gOp.topLeftCorner(s.gO.rows(), h + 1), *jte);
      else
        assemble_gradient(s.gH, s.gO, *jte);
    }
    if (mode == 2) {
      const Index P = s.C.cols();
      if (s.fused) {  // S from the pair sums Kh, C and R from the padded K
        const Index hs = padv(h), nz = P / h, Pp = nz * hs;
        for (Index l = 0; l < nz; ++l) {
          for (Index l2 = 0; l2 <= l; ++l2) {
            const Index cu = l * (l + 1) / 2 + l2;
            for (Index j2 = 0; j2 < h; ++j2)
              for (Index j = j2; j < h; ++j)
                S_(l * h + j, l2 * h + j2) = s.Kh(j * (j + 1) / 2 + j2, cu);
          }
          C_.middleCols(l * h, h) = s.K.block(0, l * hs, h + 1, h);
        }
        R_.template triangularView<Eigen::Lower>() = s.K.block(0, Pp, h + 1, h + 1);
      } else {
        S_.template triangularView<Eigen::Lower>() = s.S.template cast<double>();
        C_ = s.C.template cast<double>();
        R_.template triangularView<Eigen::Lower>() = s.R.template cast<double>();
      }
      assemble_jtj(theta, *jtj);
    }
    return s.sse;
  }

  // Network outputs Y (m x N) for inputs X (i x N).
  void predict(const Scalar* theta, const ConstMap& X, Eigen::Map<Mat> Y) {
    Scratch& w = scratch_[0];
    for (Index b0 = 0; b0 < X.cols(); b0 += block_) {
      const Index nb = std::min(block_, X.cols() - b0);
      w.forward(theta, X, b0, nb);
      Y.middleCols(b0, nb) = w.Y.leftCols(nb);
    }
  }

 private:
  // Rows of a block of V in the fused layout: h (or h + 1) padded to a multiple of 4, so the
  // register tiles have no one-row remainders (session 6, h = 10: J'J 5.6 -> 1.8 ms, h = 20:
  // 5.6 -> 4.7 ms on 10,000 samples; the sums of the padded rows are never read); in float to
  // a multiple of 8 (the float kernels' vectors).
  static Index pad4(Index r) { return (r + 3) / 4 * 4; }
  static constexpr Index kV = std::is_same<Scalar, double>::value ? 4 : 8;
  static Index padv(Index r) { return (r + kV - 1) / kV * kV; }
  // Samples per slice of the pair products (Scratch::Pb's columns; float: one more column, the
  // float kernel's slack for its whole-vector stores).
  static constexpr Index kSlice = std::is_same<Scalar, double>::value
                                      ? host::kernel::kPairSlice
                                      : host::kernel_f32::kLmSlice + 1;
  // Rows of the reduced J'J's pair sums (host::jtj_reduced): the h (h + 1) / 2 products
  // d_j d_j' padded to a multiple of 8 (whole 8 x 4 tiles), the nz (nz + 1) / 2 products
  // z_l z_l' to a multiple of 4.
  static Index pairs_h(Index h) { return (h * (h + 1) / 2 + 7) / 8 * 8; }
  static Index pairs_z(Index nz) { return pad4(nz * (nz + 1) / 2); }
  // The rows of one sample's column of V in the fused layout (host::grad_block,
  // host::jtj_reduced): the blocks v_l (l <= i, hs rows each, v_i = d), [a; 1] at pa (ha rows),
  // e at pe (me), g at pg (hg), [x; 1] at pz (nzp); each padded to a multiple of 4.
  static Index wp_size(const Net& n) {
    const Index i = n.inputs(), h = n.hidden(), m = n.outputs();
    return padv(h) * (i + 1) + padv(m) * (h + 1) + padv(h) * m;
  }
  struct Lay {
    Index hs, ha, me, hg, nzp, pa, pe, pg, pz, rows;
    Lay(Index i, Index h, Index m)
        : hs(padv(h)), ha(padv(h + 1)), me(padv(m)), hg(padv(h)), nzp(padv(i + 1)),
          pa(hs * (i + 1)), pe(pa + ha), pg(pe + me), pz(pg + hg), rows(pz + nzp) {}
  };

  // The hand kernels: double on an AVX2 + FMA CPU (kernels.hpp), float likewise (kernels_f32.hpp's
  // float twins, AVX-512 when the CPU has it); otherwise Eigen's products.
  static bool fused_path() {
    if constexpr (std::is_same<Scalar, double>::value) return host::avx2_path(host::KernelPath::Auto);
    return host::kernel_f32::cpu_level() >= 1;
  }

  // The partial sums of one chunk: sse, the gradient blocks, and the J'J blocks (fused: C
  // and R in K, S as pair sums in Kh, host::jtj_reduced; otherwise S, R and C).
  struct Slot {
    bool fused;
    double sse = 0.0;
    Mat gH, gO;                // h x (i+1), m x (h+1)
    MatD gHp, gOp;             // fused: hg x nzp, me x ha (Lay), their top-left corners gH, gO
    Mat S, R, C;               // not fused: h(i+1) sq, (h+1) sq, (h+1) x h(i+1)
    MatD K, Kh;                // fused: K padv(h+1) x (padv(h)(i+1) + padv(h+1)), Kh hw x nu

    Slot(const Net& n_, bool fused_) : fused(fused_) {
      const Index i = n_.inputs(), h = n_.hidden(), m = n_.outputs(), P = h * (i + 1);
      gH.resize(h, i + 1);
      gO.resize(m, h + 1);
      C.resize(h + 1, P);   // its size is read on both paths; its values on Eigen's
      if (fused) {
        const Lay L(i, h, m);
        gHp.resize(L.hg, L.nzp);
        gOp.resize(L.me, L.ha);
        K.resize(padv(h + 1), padv(h) * (i + 1) + padv(h + 1));
        Kh.resize(pairs_h(h), pairs_z(i + 1));
      } else {
        R.resize(h + 1, h + 1);
        S.resize(P, P);
      }
    }

    void clear(int mode) {
      sse = 0.0;
      if (mode >= 1) {
        if (fused) { gHp.setZero(); gOp.setZero(); }
        else { gH.setZero(); gO.setZero(); }
      }
      if (mode == 2) {
        if (fused) { K.setZero(); Kh.setZero(); }
        else { R.setZero(); C.setZero(); band(S, [](auto c, auto) { c.setZero(); }); }
      }
    }

    void add(const Slot& o, int mode) {
      sse += o.sse;
      if (mode >= 1) {
        if (fused) { gHp += o.gHp; gOp += o.gOp; }
        else { gH += o.gH; gO += o.gO; }
      }
      if (mode == 2) {
        if (fused) { K += o.K; Kh += o.Kh; }
        else { R += o.R; C += o.C; band(S, o.S, [](auto c, auto oc) { c += oc; }); }
      }
    }

    // f(column segment of G, the same segment of O) over the part of a symmetric accumulator
    // the rank updates write: column c from row c - c % 4 down (the lower triangle, and the
    // entries above the diagonal in syrk_lower's 4 x 4 diagonal tiles). Half the memory
    // traffic of whole-matrix operations; the entries above are never read.
    template <typename F>
    static void band(Mat& G, const Mat& O, F f) {
      for (Index c = 0; c < G.cols(); ++c) {
        const Index r0 = c - c % 4;
        f(G.col(c).tail(G.rows() - r0), O.col(c).tail(G.rows() - r0));
      }
    }
    template <typename F>
    static void band(Mat& G, F f) {
      band(G, G, [&f](auto c, auto o) { f(c, o); });
    }
  };

  // Samples per block of the SSE-only pass (mode 0, double): the kernel's L1-sized block.
  static constexpr Index kSseBlock = 128;

  // One thread's block buffers and the slot of the chunk it computes.
  struct Scratch {
    const Net& net;
    Index i, h, m;
    Mat A, D, Y, E, G, V;      // h x B, h x B, m x B, m x B, h x B, (h(i+1) + h) x B
    Mat Xs, Ts;                // kSseBlock x i, kSseBlock x m: one block, channel-contiguous
    Mat Pb;                    // fused: the pair products of one slice (host::jtj_reduced)
    Vec Wp;                    // fused: host::pad_weights' padded weights
    bool fused;                // on an AVX2 + FMA CPU: the hand kernels (fused_path)
    Slot part;

    Scratch(const Net& n_, Index B)
        : net(n_), i(n_.inputs()), h(n_.hidden()), m(n_.outputs()),
          A(fused_path() ? padv(h) : h, std::max(B, kSseBlock)), D(h, B), Y(m, B), E(m, B), G(h, B),
          V(fused_path() ? Lay(n_.inputs(), n_.hidden(), n_.outputs()).rows : h * (i + 1) + h + 1, B),
          Xs(kSseBlock, i), Ts(kSseBlock, m),
          Pb(fused_path() ? pairs_h(h) + pairs_z(i + 1) : 0, kSlice),
          Wp(fused_path() ? wp_size(n_) : 0), fused(fused_path()), part(n_, fused) {
      // the fused layout (Lay): block l of v at row l hs, a at pa, then the row of ones (the
      // row sums), e, g, x and its row of ones; padding rows zero (never written after this)
      V.setZero();
      if (fused) {
        const Lay L(i, h, m);
        V.row(L.pa + h).setOnes();
        V.row(L.pz + i).setOnes();
      } else {
        V.row(h * (i + 2)).setOnes();
      }
    }

    // Mode 0 in double: the SSE by host/kernels.hpp's sse_soa (vectorised forward pass, AVX2 +
    // FMA when the CPU has them; about 0.4 against 0.7 ms for Eigen's products at 10,000 x
    // 6-20-8), each block of kSseBlock samples transposed to the kernel's layout first.
    double sse_kernel(const Scalar* theta, const ConstMap& X, const ConstMap& T, Index lo,
                      Index hi) {
      double sse = 0.0;
      for (Index b0 = lo; b0 < hi; b0 += kSseBlock) {
        const Index nb = std::min(kSseBlock, hi - b0);
        Xs.topRows(nb) = X.middleCols(b0, nb).transpose();
        Ts.topRows(nb) = T.middleCols(b0, nb).transpose();
        if constexpr (std::is_same<Scalar, double>::value)
          sse += host::sse_soa(net, theta, Xs.data(), Ts.data(), kSseBlock, nb, A.data(),
                               kSseBlock);
        else  // float: kernels_f32.hpp's SSE kernel (AVX-512 when the CPU has it)
          sse += host::sse_soa_f32(i, h, m, net.activation(), theta, Xs.data(), Ts.data(),
                                   kSseBlock, nb, A.data(), kSseBlock, host::f32_path());
      }
      return sse;
    }

    void forward(const Scalar* theta, const ConstMap& X, Index b0, Index nb) {
      Eigen::Map<Mat> a(A.data(), h, nb);  // A has pad4(h) rows on the fused path
      a.noalias() = net.W1(theta) * X.middleCols(b0, nb);
      a.colwise() += net.b1(theta);
      const Activation act = net.activation();
      if constexpr (std::is_same<Scalar, double>::value)
        host::activate_inplace(a.data(), h * nb, act);  // vectorised, within 5e-16 of std::tanh
      else
        a = a.unaryExpr([act](Scalar v) { return activate(act, v); });
      auto y = Y.leftCols(nb);
      y.noalias() = net.W2(theta) * a;
      y.colwise() += net.b2(theta);
    }

    // Samples [lo, hi) in blocks, into slot `out` (cleared first).
    void run(const Scalar* theta, const ConstMap& X, const ConstMap& T, Index lo, Index hi,
             int mode, Slot& out) {
      out.clear(mode);
      if (mode == 0 && (std::is_same<Scalar, double>::value || fused)) {
        out.sse = sse_kernel(theta, X, T, lo, hi);
        return;
      }
      const Index P = h * (i + 1);
      const Index B = D.cols();   // A may be wider (the SSE pass's block)
      const Activation act = net.activation();
      {
        if (fused) {  // the hand gradient pass and the reduced J'J kernel (double or float)
          const Lay L(i, h, m);
          host::pad_weights(net, theta, L.hs, L.me, Wp.data());
          for (Index b0 = lo; b0 < hi; b0 += B) {
            const Index nb = std::min(B, hi - b0);
            out.sse += host::grad_block(Wp.data(), i, h, m, L.hs, L.me,
                                        net.activation() == Activation::Tansig,
                                        X.data() + b0 * i, T.data() + b0 * m, nb, A.data(),
                                        out.gHp.data(), L.nzp, out.gOp.data(), L.ha, V.data(),
                                        V.rows(), L.pa, L.pe, L.pg, L.pz, mode >= 1, mode == 2);
            if (mode < 2) continue;
            host::jtj_reduced(out.Kh.data(), out.Kh.rows(), out.K.data(), out.K.rows(),
                              V.data(), V.rows(), X.data() + b0 * i, i, h, L.hs, L.ha,
                              i + 1, out.Kh.rows(), out.Kh.cols(), nb, Pb.data());
          }
          return;
        }
      }
      for (Index b0 = lo; b0 < hi; b0 += B) {
        const Index nb = std::min(B, hi - b0);
        forward(theta, X, b0, nb);
        auto e = E.leftCols(nb);
        e = T.middleCols(b0, nb) - Y.leftCols(nb);
        out.sse += static_cast<double>(e.squaredNorm());
        if (mode == 0) continue;
        Eigen::Map<Mat> a(A.data(), h, nb);
        auto d = D.leftCols(nb);
        d = a.unaryExpr([act](Scalar v) { return activation_slope(act, v); });
        auto g = G.leftCols(nb);
        g.noalias() = net.W2(theta).transpose() * e;
        g.array() *= d.array();
        const auto xb = X.middleCols(b0, nb);
        out.gH.leftCols(i).noalias() += g * xb.transpose();
        out.gH.col(i) += g.rowwise().sum();
        out.gO.leftCols(h).noalias() += e * a.transpose();
        out.gO.col(h) += e.rowwise().sum();
        if (mode < 2) continue;
        auto v = V.topLeftCorner(P, nb);
        for (Index l = 0; l < i; ++l)
          v.middleRows(l * h, h).array() = d.array().rowwise() * xb.row(l).array();
        v.middleRows(i * h, h) = d;
        out.S.template selfadjointView<Eigen::Lower>().rankUpdate(v);
        out.R.topLeftCorner(h, h).template selfadjointView<Eigen::Lower>().rankUpdate(a);
        out.C.topRows(h).noalias() += a * v.transpose();
        out.R.row(h).head(h) += a.rowwise().sum().transpose();
        out.R(h, h) += Scalar(nb);
        out.C.row(h) += v.rowwise().sum().transpose();
      }
    }
  };

  // J'e = [vec(gH); vec(gO)] (column-major) in the output's type.
  template <class GH, class GO, class VOut>
  static void assemble_gradient(const GH& gH, const GO& gO, VOut& jte) {
    using O = typename VOut::Scalar;
    const Index ph = gH.size(), po = gO.size();
    jte.resize(ph + po);
    for (Index c = 0; c < gH.cols(); ++c)
      for (Index r = 0; r < gH.rows(); ++r) jte(c * gH.rows() + r) = static_cast<O>(gH(r, c));
    for (Index c = 0; c < gO.cols(); ++c)
      for (Index r = 0; r < gO.rows(); ++r)
        jte(ph + c * gO.rows() + r) = static_cast<O>(gO(r, c));
  }

  // J'J from the summed S_, C_ and R_ (double) and the output weights, in the output's type.
  template <class MOut>
  void assemble_jtj(const Scalar* theta, MOut& jtj) const {
    using O = typename MOut::Scalar;
    const Index h = net_.hidden(), m = net_.outputs(), ph = C_.cols(), po = m * (h + 1);
    jtj.resize(ph + po, ph + po);
    const MatD W2 = net_.W2(theta).template cast<double>();
    const MatD Q = W2.transpose() * W2;  // h x h
    // hidden-hidden: S's block (l, l') (l >= l') is symmetric, and only the lower triangle of
    // each block is read (jtj_reduced computes no more)
    const Index nz = ph / h;
    for (Index l2 = 0; l2 < nz; ++l2)
      for (Index j2 = 0; j2 < h; ++j2) {
        const Index c = l2 * h + j2;
        for (Index l = l2; l < nz; ++l)
          for (Index j = l == l2 ? j2 : 0; j < h; ++j) {
            const O v = static_cast<O>(S_(l * h + std::max(j, j2), l2 * h + std::min(j, j2)) *
                                       Q(j, j2));
            jtj(l * h + j, c) = v;
            jtj(c, l * h + j) = v;
          }
      }
    // output-output
    jtj.bottomRightCorner(po, po).setZero();
    for (Index j = 0; j <= h; ++j)
      for (Index j2 = 0; j2 <= h; ++j2) {
        const O v = static_cast<O>(j >= j2 ? R_(j, j2) : R_(j2, j));
        for (Index k = 0; k < m; ++k) jtj(ph + j * m + k, ph + j2 * m + k) = v;
      }
    // output-hidden and its transpose
    for (Index c = 0; c < ph; ++c) {
      const Index jh = c % h;
      for (Index j = 0; j <= h; ++j)
        for (Index k = 0; k < m; ++k) {
          const O v = static_cast<O>(W2(k, jh) * C_(j, c));
          jtj(ph + j * m + k, c) = v;
          jtj(c, ph + j * m + k) = v;
        }
    }
  }

  Net net_;
  Index block_;
  int threads_;
  Slot total_;                    // the sums over the record (chunk 0, then each chunk added)
  std::vector<Scratch> scratch_;  // one per thread (at most kMaxChunks)
  MatD S_, C_, R_;                // the summed S and R (lower triangles) and C, assembled into J'J
};

}  // namespace cdam
