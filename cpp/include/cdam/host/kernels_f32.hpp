// The float32 BP fitness kernel of the swarm search (issue 23, item 3): the sum of squared errors
// of one network over a range of samples of a channel-contiguous (SoA) float record, 8 floats a
// vector on AVX2 + FMA, 16 on AVX-512, chosen at run time; the generic build (SSE2) uses the
// same 8-float vectors as two xmm. The swarm's fitness and the float32 LM's trial passes read
// it; the float32 LM's gradient pass and J'J are the float kernels further down (session 8).
//
// Per block of B samples (B = 256: the h x B hidden activations and the block's inputs and
// targets stay in L1), per vector of W samples:
//   a_j = tanh(b1_j + sum_l W1(j, l) x_l)   (the W inputs kept in registers, the activation
//                                            computed in registers before it is stored);
//   y_k = b2_k + sum_j W2(k, j) a_j, 4 outputs at a time; e_k = t_k - y_k; sse += e_k^2
// in float lanes; each block's lanes are summed in double (at most B m / W terms a lane in
// float), the blocks in order in double.
//
// tanh: Eigen 3.4's rational 13/6 minimax form (fast_math.hpp's kTanhP / kTanhQ, the firmware's
// and Eigen's generic_fast_tanh_float): x clamped to +-7.905311, tanh(x) = x P(x^2) / Q(x^2),
// 9 FMAs, 1 multiply and 1 division a value, no table, no branch. Measured against tanh in double
// on a dense grid over [-10, 10] (tests/identify/test_fitness_f32.py): within 2.4e-7 absolute
// and 4 float ulps of the correctly rounded value. logsig: 0.5 tanh(x / 2) + 0.5.
// The samples beyond the last whole vector of a block take the same formulas one at a time.
// A machine always takes the same path (AVX-512, AVX2 or generic); the paths agree to float
// rounding, not bit for bit (lane counts differ, so do the partial sums).
#ifdef CDAM_TARGET_EMBEDDED
#error "cdam/host/kernels_f32.hpp is host-only (x86 AVX2/AVX-512 dispatch, GCC vector extensions)"
#endif
#pragma once
#include <cstdint>
#include <cstring>

#include "../activation.hpp"
#include "../fast_math.hpp"
#include "../mlp.hpp"
#include "kernels.hpp"  // CDAM_OUTPUT_ERRORS

namespace cdam::host {

namespace kernel_f32 {

// tanh in float: tanh(x) = u / (u + 2), u = e^{2x} - 1 (expm1, accurate near 0 too), 2x clamped
// to [-20, 20] (tanh(10) rounds to 1): e^y = 2^n (1 + r + r^2 E(r)), n = round(y / ln 2),
// r = y - n ln 2 (two-part ln 2), E Cephes expf's polynomial of degree 5, so
// u = (2^n - 1) + 2^n (r + r^2 E(r)), exact cancellation-free at n = 0; 2^n from the bits of the
// rounded value. About 20 operations, one division, no branch and no select.
// T is float or a float vector, I the matching int type.
#define CDAM_F32_TANH_BODY(T, I, x, out)                                                      \
  do {                                                                                        \
    T y_ = 2.0f * (x);                                                                        \
    y_ = y_ > 20.0f ? 20.0f : y_;                                                             \
    y_ = y_ < -20.0f ? -20.0f : y_;                                                           \
    const T t_ = y_ * 1.44269504088896341f + 12582912.0f; /* 1.5 2^23 */                     \
    const T fn_ = t_ - 12582912.0f;                                                           \
    I bits_;                                                                                  \
    std::memcpy(&bits_, &t_, sizeof bits_);                                                   \
    bits_ = (bits_ - 0x4B400000 + 127) << 23;                                                 \
    T p2n_;                                                                                   \
    std::memcpy(&p2n_, &bits_, sizeof p2n_);                                                  \
    const T r_ = (y_ - fn_ * 0.693359375f) - fn_ * -2.12194440e-4f;                           \
    const T e_ = ((((1.9875691500e-4f * r_ + 1.3981999507e-3f) * r_ + 8.3334519073e-3f) * r_  \
                   + 4.1665795894e-2f) * r_ + 1.6666665459e-1f) * r_ + 5.0000001201e-1f;      \
    const T q_ = (r_ * r_) * e_ + r_;                                                         \
    const T u_ = p2n_ * q_ + (p2n_ - 1.0f);                                                   \
    (out) = u_ / (u_ + 2.0f);                                                                 \
  } while (0)

// One tanh in float, the vector formula on a scalar (the tail samples and the tests).
inline float tanh1(float x) {
  float out;
  CDAM_F32_TANH_BODY(float, std::int32_t, x, out);
  return out;
}

// v = tanh(v) (or the logistic function) lane-wise; vf / vi are the caller's vector types.
#define CDAM_F32_TANH(v)                                                                      \
  do {                                                                                        \
    const vf xa_ = tansig ? (v) : 0.5f * (v);                                                 \
    vf ta_;                                                                                   \
    CDAM_F32_TANH_BODY(vf, vi, xa_, ta_);                                                     \
    (v) = tansig ? ta_ : 0.5f * ta_ + 0.5f;                                                   \
  } while (0)

// SSE over samples [0, n) of the SoA record: x_l(s) = X[l * ld + s], t_k(s) = T[k * ld + s].
// a: h B floats of caller storage. kW floats per vector (vf).
#define CDAM_F32_SSE_BODY                                                                     \
  double total = 0.0;                                                                         \
  const Index il = i < kMaxIn ? i : kMaxIn;                                                   \
  for (Index s0 = 0; s0 < n; s0 += B) {                                                       \
    const Index nb = n - s0 < B ? n - s0 : B, nv = nb - nb % kW;                              \
    /* phase 1: the hidden sums of the block's whole vectors */                               \
    for (Index s = 0; s < nv; s += kW) {                                                      \
      vf xv[kMaxIn];                                                                          \
      for (Index l = 0; l < il; ++l) std::memcpy(&xv[l], X + l * ld + s0 + s, sizeof(vf));  \
      for (Index j = 0; j < h; ++j) {                                                         \
        vf acc = vf{} + b1[j];                                                                \
        for (Index l = 0; l < il; ++l) acc += W1[j + l * h] * xv[l];                          \
        for (Index l = il; l < i; ++l) {                                                      \
          vf x;                                                                               \
          std::memcpy(&x, X + l * ld + s0 + s, sizeof x);                                     \
          acc += W1[j + l * h] * x;                                                           \
        }                                                                                     \
        std::memcpy(a + j * B + s, &acc, sizeof acc);                                         \
      }                                                                                       \
    }                                                                                         \
    /* phase 2: the activations (independent iterations: the CPU overlaps them) */            \
    for (Index j = 0; j < h; ++j)                                                             \
      for (Index s = 0; s < nv; s += kW) {                                                    \
        vf v;                                                                                 \
        std::memcpy(&v, a + j * B + s, sizeof v);                                            \
        CDAM_F32_TANH(v);                                                                     \
        std::memcpy(a + j * B + s, &v, sizeof v);                                            \
      }                                                                                       \
    /* phase 3: the outputs, 4 at a time, and the squared errors in float lanes */            \
    vf tot = {};                                                                              \
    for (Index s = 0; s < nv; s += kW) {                                                      \
      CDAM_OUTPUT_ERRORS(vf, tot)                                                             \
    }                                                                                         \
    double bs = 0.0;                                                                          \
    for (int q = 0; q < kW; ++q) bs += static_cast<double>(tot[q]);                           \
    /* the samples beyond the last whole vector, one at a time (a[0..h) is free now) */       \
    for (Index s = nv; s < nb; ++s) {                                                         \
      for (Index j = 0; j < h; ++j) {                                                         \
        float acc = b1[j];                                                                    \
        for (Index l = 0; l < i; ++l) acc += W1[j + l * h] * X[l * ld + s0 + s];              \
        a[j] = tansig ? tanh1(acc) : 0.5f * tanh1(0.5f * acc) + 0.5f;                         \
      }                                                                                       \
      for (Index k = 0; k < m; ++k) {                                                         \
        float yk = b2[k];                                                                     \
        for (Index j = 0; j < h; ++j) yk += W2[j * m + k] * a[j];                             \
        const float e = T[k * ld + s0 + s] - yk;                                              \
        bs += static_cast<double>(e * e);                                                     \
      }                                                                                       \
    }                                                                                         \
    total += bs;                                                                              \
  }                                                                                           \
  return total;

// The vector types of a path of kW floats.
#define CDAM_F32_VECTORS(W)                                                                   \
  constexpr int kW = W;                                                                       \
  typedef float vf __attribute__((vector_size(kW * 4)));                                      \
  typedef std::int32_t vi __attribute__((vector_size(kW * 4)));

#define CDAM_F32_SSE_ARGS                                                                     \
  const float *__restrict W1, const float *__restrict b1, const float *__restrict W2,         \
      const float *__restrict b2, Index i, Index h, Index m, bool tansig,                     \
      const float *__restrict X, const float *__restrict T, Index ld, Index n,                \
      float *__restrict a, Index B

// ---- The float32 LM kernels (issue 23 item 1, session 8): the float twins of kernels.hpp's
// grad_block and jtj_reduced, for NormalEquations<float> on an AVX2 + FMA CPU (AVX2 and
// AVX-512 builds, chosen at run time). Products and the sums over one slice of at most
// kLmSlice samples in float (8 floats a vector: twice the multiply-adds of a double vector a
// cycle), then each tile's float sums added into double accumulators (the record's sums over
// 10,000 samples and more stay in double: a float running sum would lose about 4 digits over
// them, and the LM's Cholesky with it). Layouts, padding and arguments as in kernels.hpp, the
// padded blocks of hidden units and outputs to a multiple of 8.

// Samples per slice of the float tiles (the float sums' length before they go to double).
constexpr Index kLmSlice = 32;

// acc (8 floats) added to the 8 doubles at g.
#define CDAM_F32_ADD8(g, acc)                                                                 \
  do {                                                                                        \
    v8d d_ = __builtin_convertvector((acc), v8d), g_;                                        \
    std::memcpy(&g_, (g), sizeof g_);                                                         \
    g_ += d_;                                                                                 \
    std::memcpy((g), &g_, sizeof g_);                                                         \
  } while (0)

// G (double, leading dimension ldg) += X W^T over ns <= kLmSlice samples: X R rows, W C rows
// (float, one sample a column, leading dimension ldv). lower: tiles from the diagonal down (as
// kernels.hpp's tiles). Tiles of 16 rows x 4 columns in 8 float registers, then 8 x 4, then
// one row at a time.
#define CDAM_F32_TILES_BODY                                                                   \
  typedef float v8f __attribute__((vector_size(32)));                                         \
  typedef double v8d __attribute__((vector_size(64)));                                        \
  Index c0 = 0;                                                                               \
  for (; c0 + 4 <= C; c0 += 4) {                                                              \
    /* lower: from the 8-row boundary at or above the diagonal (no one-row remainders when   \
       R is a multiple of 8; the few sums above the diagonal are never read) */              \
    Index r = lower ? c0 - c0 % 8 : 0;                                                        \
    for (; r + 16 <= R; r += 16) {                                                            \
      v8f a0 = {}, a1 = a0, a2 = a0, a3 = a0, b0 = a0, b1 = a0, b2 = a0, b3 = a0;             \
      for (Index s = 0; s < ns; ++s) {                                                        \
        const float* xc = X + s * ldv;                                                        \
        const float* wc = W + s * ldv;                                                        \
        v8f x, y;                                                                             \
        std::memcpy(&x, xc + r, sizeof x);                                                    \
        std::memcpy(&y, xc + r + 8, sizeof y);                                                \
        const float w0 = wc[c0], w1 = wc[c0 + 1], w2 = wc[c0 + 2], w3 = wc[c0 + 3];           \
        a0 += x * w0; a1 += x * w1; a2 += x * w2; a3 += x * w3;                               \
        b0 += y * w0; b1 += y * w1; b2 += y * w2; b3 += y * w3;                               \
      }                                                                                       \
      double* g = G + r + c0 * ldg;                                                           \
      CDAM_F32_ADD8(g, a0); CDAM_F32_ADD8(g + ldg, a1);                                       \
      CDAM_F32_ADD8(g + 2 * ldg, a2); CDAM_F32_ADD8(g + 3 * ldg, a3);                         \
      CDAM_F32_ADD8(g + 8, b0); CDAM_F32_ADD8(g + 8 + ldg, b1);                               \
      CDAM_F32_ADD8(g + 8 + 2 * ldg, b2); CDAM_F32_ADD8(g + 8 + 3 * ldg, b3);                 \
    }                                                                                         \
    for (; r + 8 <= R; r += 8) { /* even and odd samples apart: 8 independent chains */     \
      v8f a0 = {}, a1 = a0, a2 = a0, a3 = a0, e0 = a0, e1 = a0, e2 = a0, e3 = a0;             \
      Index s = 0;                                                                            \
      for (; s + 2 <= ns; s += 2) {                                                           \
        const float* wc = W + s * ldv;                                                        \
        const float* wd = wc + ldv;                                                           \
        v8f x, y;                                                                             \
        std::memcpy(&x, X + s * ldv + r, sizeof x);                                           \
        std::memcpy(&y, X + (s + 1) * ldv + r, sizeof y);                                     \
        a0 += x * wc[c0]; a1 += x * wc[c0 + 1]; a2 += x * wc[c0 + 2]; a3 += x * wc[c0 + 3];   \
        e0 += y * wd[c0]; e1 += y * wd[c0 + 1]; e2 += y * wd[c0 + 2]; e3 += y * wd[c0 + 3];   \
      }                                                                                       \
      for (; s < ns; ++s) {                                                                   \
        const float* wc = W + s * ldv;                                                        \
        v8f x;                                                                                \
        std::memcpy(&x, X + s * ldv + r, sizeof x);                                           \
        a0 += x * wc[c0]; a1 += x * wc[c0 + 1]; a2 += x * wc[c0 + 2]; a3 += x * wc[c0 + 3];   \
      }                                                                                       \
      a0 += e0; a1 += e1; a2 += e2; a3 += e3;                                                 \
      double* g = G + r + c0 * ldg;                                                           \
      CDAM_F32_ADD8(g, a0); CDAM_F32_ADD8(g + ldg, a1);                                       \
      CDAM_F32_ADD8(g + 2 * ldg, a2); CDAM_F32_ADD8(g + 3 * ldg, a3);                         \
    }                                                                                         \
    for (; r < R; ++r)                                                                        \
      for (Index c = c0; c < c0 + 4; ++c) {                                                   \
        float acc = 0.0f;                                                                     \
        for (Index s = 0; s < ns; ++s) acc += X[r + s * ldv] * W[c + s * ldv];                \
        G[r + c * ldg] += static_cast<double>(acc);                                           \
      }                                                                                       \
  }                                                                                           \
  for (; c0 < C; ++c0)                                                                        \
    for (Index r = lower ? c0 : 0; r < R; ++r) {                                              \
      float acc = 0.0f;                                                                       \
      for (Index s = 0; s < ns; ++s) acc += X[r + s * ldv] * W[c0 + s * ldv];                 \
      G[r + c0 * ldg] += static_cast<double>(acc);                                            \
    }

// The hook of kernels.hpp's CDAM_JTJR_BODY and CDAM_FB_BODY in float: the float tiles.
#define CDAM_F32_TILES_SUM(G, ldg, X, W, ldv, R, C, ns, lower)                                \
  lm_tiles(G, ldg, X, W, ldv, R, C, ns, lower)

// The reduced J'J sums (kernels.hpp's CDAM_JTJR_BODY) from float rows: per slice of kLmSlice
// samples the pair products d_j d_j' (hw rows) and z_l z_l' (nu rows) in float in buf (ld
// hw + nu, kLmSlice columns and 8 floats of slack), Kh (double) += their products; K (double)
// the C and R blocks from V's [a; 1] against [v; a; 1].
#define CDAM_F32_JTJR_BODY                                                                    \
  typedef float v8f __attribute__((vector_size(32)));                                         \
  CDAM_JTJR_BODY(float, v8f, 8, CDAM_F32_TILES_SUM, kLmSlice)

// The gradient pass (kernels.hpp's CDAM_FB_BODY) in float: 8 hidden units or outputs a vector
// (hs, me multiples of 8), the activation by this file's float tanh on each vector of hidden
// sums in registers; each squared error in float, the block's sse in double (as the SSE kernel);
// the gradient sums into gH, gO (double) per slice of kLmSlice samples by lm_tiles.
#define CDAM_F32_FB_BODY                                                                      \
  CDAM_F32_VECTORS(8)                                                                         \
  CDAM_FB_BODY(float, vf, 8, CDAM_F32_TANH, CDAM_FB_NO_ACT, CDAM_F32_TILES_SUM, kLmSlice)

#define CDAM_F32_LMT_ARGS                                                                     \
  double *__restrict G, Index ldg, const float *__restrict X, const float *__restrict W,      \
      Index ldv, Index R, Index C, Index ns, bool lower

#define CDAM_F32_JTJR_ARGS                                                                    \
  double *__restrict Kh, Index ldh, double *__restrict K, Index ldk,                          \
      const float *__restrict V, Index ldv, const float *__restrict X, Index ldx, Index h,     \
      Index hs, Index ha, Index nz, Index hw, Index nu, Index nb, float *__restrict buf

constexpr Index kMaxIn = 12;  // inputs kept in registers (more are loaded from L1)

namespace generic {
inline double sse_block(CDAM_F32_SSE_ARGS) {
  CDAM_F32_VECTORS(8)
  CDAM_F32_SSE_BODY
}
inline void lm_tiles(CDAM_F32_LMT_ARGS) { CDAM_F32_TILES_BODY }
inline void jtj_reduced(CDAM_F32_JTJR_ARGS) { CDAM_F32_JTJR_BODY }
inline double grad_block(CDAM_FB_ARGS(float)) { CDAM_F32_FB_BODY }
}  // namespace generic

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define CDAM_HAVE_F32_CLONES 1
namespace avx2 {
__attribute__((target("avx2,fma"))) inline double sse_block(CDAM_F32_SSE_ARGS) {
  CDAM_F32_VECTORS(8)
  CDAM_F32_SSE_BODY
}
__attribute__((target("avx2,fma"))) inline void lm_tiles(CDAM_F32_LMT_ARGS) {
  CDAM_F32_TILES_BODY
}
__attribute__((target("avx2,fma"))) inline void jtj_reduced(CDAM_F32_JTJR_ARGS) {
  CDAM_F32_JTJR_BODY
}
__attribute__((target("avx2,fma"))) inline double grad_block(CDAM_FB_ARGS(float)) {
  CDAM_F32_FB_BODY
}
}  // namespace avx2
namespace avx512 {
__attribute__((target("avx512f,avx512vl,avx2,fma"))) inline double sse_block(CDAM_F32_SSE_ARGS) {
  CDAM_F32_VECTORS(16)
  CDAM_F32_SSE_BODY
}
// The LM kernels with AVX-512VL's 32 vector registers and instructions (the same 8-float
// vectors: the tiles' shape is the AVX2 one).
#define CDAM_TARGET_512 __attribute__((target("avx512f,avx512vl,avx2,fma")))
CDAM_TARGET_512 inline void lm_tiles(CDAM_F32_LMT_ARGS) { CDAM_F32_TILES_BODY }
CDAM_TARGET_512 inline void jtj_reduced(CDAM_F32_JTJR_ARGS) { CDAM_F32_JTJR_BODY }
CDAM_TARGET_512 inline double grad_block(CDAM_FB_ARGS(float)) { CDAM_F32_FB_BODY }
#undef CDAM_TARGET_512
}  // namespace avx512
inline int cpu_level() {  // 2: AVX-512F, 1: AVX2 + FMA, 0: neither
  static const int level = __builtin_cpu_supports("avx512f") ? 2
                           : (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) ? 1
                                                                                              : 0;
  return level;
}
#else
#define CDAM_HAVE_F32_CLONES 0
inline int cpu_level() { return 0; }
#endif

#undef CDAM_F32_TANH
#undef CDAM_F32_TANH_BODY
#undef CDAM_F32_ADD8
#undef CDAM_F32_TILES_BODY
#undef CDAM_F32_JTJR_BODY
#undef CDAM_F32_FB_BODY
#undef CDAM_F32_LMT_ARGS
#undef CDAM_F32_JTJR_ARGS
#undef CDAM_F32_TILES_SUM
#undef CDAM_JTJR_BODY
#undef CDAM_FB_BODY
#undef CDAM_FB_ARGS
#undef CDAM_FB_NO_ACT
#undef CDAM_F32_SSE_BODY
#undef CDAM_F32_SSE_ARGS
#undef CDAM_F32_VECTORS
#undef CDAM_OUTPUT_ERRORS

}  // namespace kernel_f32

// Which float32 path: 0 generic (SSE2), 1 AVX2 + FMA, 2 AVX-512; `limit` caps it (tests).
inline int f32_path(int limit = 2) {
  const int l = kernel_f32::cpu_level();
  return l < limit ? l : limit;
}

// Lanes of a float32 vector on the path (8 or 16).
inline int f32_lanes(int path) { return path == 2 ? 16 : 8; }

// SSE, in float32 with double block sums, of the network (W1 h x i, b1, W2 m x h, b2 packed as
// Mlp's theta, in float) over n samples of a float SoA record (input l at X + l ld, target k at
// T + k ld). a: at least h B floats of caller storage, B the block length in samples.
inline double sse_soa_f32(Index i, Index h, Index m, Activation act, const float* theta,
                          const float* X, const float* T, Index ld, Index n, float* a, Index B,
                          int path) {
  const float *W1 = theta, *b1 = theta + i * h, *W2 = theta + i * h + h,
              *b2 = theta + i * h + h + h * m;
  const bool tansig = act == Activation::Tansig;
#if CDAM_HAVE_F32_CLONES
  if (path >= 2 && kernel_f32::cpu_level() >= 2)
    return kernel_f32::avx512::sse_block(W1, b1, W2, b2, i, h, m, tansig, X, T, ld, n, a, B);
  if (path >= 1 && kernel_f32::cpu_level() >= 1)
    return kernel_f32::avx2::sse_block(W1, b1, W2, b2, i, h, m, tansig, X, T, ld, n, a, B);
#endif
  (void)path;
  return kernel_f32::generic::sse_block(W1, b1, W2, b2, i, h, m, tansig, X, T, ld, n, a, B);
}

// The float LM kernels (CDAM_F32_FB_BODY, CDAM_F32_JTJR_BODY; overloads of kernels.hpp's
// grad_block and jtj_reduced on float rows) on the CPU's path: AVX-512 or
// AVX2 + FMA (NormalEquations<float> calls them only when the CPU has AVX2 + FMA), else the
// generic build. Arguments as kernels.hpp's grad_block and jtj_reduced, the sums in double.
inline double grad_block(const float* Wp, Index i, Index h, Index m, Index hs, Index me,
                             bool tansig, const float* X, const float* T, Index nb, float* A,
                             double* gH, Index nzp, double* gO, Index ha, float* V, Index ldv,
                             Index pa, Index pe, Index pg, Index pz, bool grad, bool full) {
  const float *W1p = Wp, *b1p = W1p + hs * i, *W2p = b1p + hs, *b2p = W2p + me * h,
              *W2tp = b2p + me;
#if CDAM_HAVE_F32_CLONES
  if (kernel_f32::cpu_level() >= 2)
    return kernel_f32::avx512::grad_block(W1p, b1p, W2p, b2p, W2tp, i, h, m, hs, me, tansig, X,
                                          T, nb, A, gH, nzp, gO, ha, V, ldv, pa, pe, pg, pz,
                                          grad, full);
  if (kernel_f32::cpu_level() >= 1)
    return kernel_f32::avx2::grad_block(W1p, b1p, W2p, b2p, W2tp, i, h, m, hs, me, tansig, X, T,
                                        nb, A, gH, nzp, gO, ha, V, ldv, pa, pe, pg, pz, grad,
                                        full);
#endif
  return kernel_f32::generic::grad_block(W1p, b1p, W2p, b2p, W2tp, i, h, m, hs, me, tansig, X,
                                         T, nb, A, gH, nzp, gO, ha, V, ldv, pa, pe, pg, pz, grad,
                                         full);
}

// buf: (hw + nu) kLmSlice + 8 floats of caller storage.
inline void jtj_reduced(double* Kh, Index ldh, double* K, Index ldk, const float* V,
                            Index ldv, const float* X, Index ldx, Index h, Index hs, Index ha,
                            Index nz, Index hw, Index nu, Index nb, float* buf) {
#if CDAM_HAVE_F32_CLONES
  if (kernel_f32::cpu_level() >= 2)
    return kernel_f32::avx512::jtj_reduced(Kh, ldh, K, ldk, V, ldv, X, ldx, h, hs, ha, nz, hw,
                                           nu, nb, buf);
  if (kernel_f32::cpu_level() >= 1)
    return kernel_f32::avx2::jtj_reduced(Kh, ldh, K, ldk, V, ldv, X, ldx, h, hs, ha, nz, hw, nu,
                                         nb, buf);
#endif
  kernel_f32::generic::jtj_reduced(Kh, ldh, K, ldk, V, ldv, X, ldx, h, hs, ha, nz, hw, nu, nb,
                                   buf);
}

}  // namespace cdam::host
