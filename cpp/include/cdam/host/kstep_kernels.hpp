// The sensitivity product of the k-step rollout (cdam/host/kstep.hpp): one step of
//   G_{j+1} = G_j (I + A_j)^T + sum_{l >= 1} G_{j-l} L_l^T + B_j
// is, per term, a tall-by-small product
//   G[:, c] (=|+=) sum_s X[:, s] M(c, s),   c < C, s < S,   M(c, s) = M[c ldm + s] (row-major),
// with G and X column-major (R rows: the D parameters; C = S = ns states). Written as plain
// loops, each column of G was read and written once per term of the sum (2 loads and a store per
// multiply-add, SSE2): 46 % of an epoch's time on the nano-drone flights (D 357, ns 13), beside
// 38 % for the D^2 J'J. Here tiles of 8 rows x 4 columns stay in 8 vector registers over the
// whole sum (2 loads and 4 broadcasts per 8 fused multiply-adds, G stored once), compiled twice
// like kernels.hpp: a generic build and an AVX2 + FMA one chosen at run time.
// Every entry is the same sum in the same order (s = 0 .. S - 1) on both paths but for FMA
// rounding; one machine always takes the same path.
#ifdef CDAM_TARGET_EMBEDDED
#error "cdam/host/kstep_kernels.hpp is host-only (x86 AVX2 dispatch, GCC vector extensions)"
#endif
#pragma once
#include <cstring>

#include "kernels.hpp"

namespace cdam::host {

namespace kernel {

// One tile of NC columns (1..4) at column c0, rows r .. r + 4 RV - 1 (RV vectors of 4 rows).
template <int NC, int RV>
__attribute__((always_inline)) inline void product_tile(double* __restrict G, Index ldg,
                                                        const double* __restrict X, Index ldx,
                                                        const double* __restrict M, Index ldm,
                                                        Index S, Index r, Index c0, bool add) {
  typedef double v4d __attribute__((vector_size(32)));
  v4d acc[NC * RV];
  for (int q = 0; q < NC * RV; ++q) acc[q] = v4d{0, 0, 0, 0};
  for (Index s = 0; s < S; ++s) {
    const double* xc = X + s * ldx + r;
    v4d x[RV];
    for (int v = 0; v < RV; ++v) std::memcpy(&x[v], xc + 4 * v, sizeof(v4d));
    for (int q = 0; q < NC; ++q) {
      const double m = M[(c0 + q) * ldm + s];
      for (int v = 0; v < RV; ++v) acc[q * RV + v] += x[v] * m;
    }
  }
  for (int q = 0; q < NC; ++q)
    for (int v = 0; v < RV; ++v) {
      double* g = G + (c0 + q) * ldg + r + 4 * v;
      if (add) {
        v4d old;
        std::memcpy(&old, g, sizeof old);
        acc[q * RV + v] += old;
      }
      std::memcpy(g, &acc[q * RV + v], sizeof(v4d));
    }
}

template <int NC>
__attribute__((always_inline)) inline void product_columns(double* __restrict G, Index ldg,
                                                           const double* __restrict X, Index ldx,
                                                           const double* __restrict M, Index ldm,
                                                           Index R, Index S, Index c0, bool add) {
  Index r = 0;
  for (; r + 8 <= R; r += 8) product_tile<NC, 2>(G, ldg, X, ldx, M, ldm, S, r, c0, add);
  for (; r + 4 <= R; r += 4) product_tile<NC, 1>(G, ldg, X, ldx, M, ldm, S, r, c0, add);
  for (; r < R; ++r)
    for (int q = 0; q < NC; ++q) {
      double acc = 0.0;
      for (Index s = 0; s < S; ++s) acc += X[s * ldx + r] * M[(c0 + q) * ldm + s];
      double* g = G + (c0 + q) * ldg + r;
      *g = add ? *g + acc : acc;
    }
}

#define CDAM_PRODUCT_ARGS                                                                    \
  double *__restrict G, Index ldg, const double *__restrict X, Index ldx,                    \
      const double *__restrict M, Index ldm, Index R, Index C, Index S, bool add
#define CDAM_PRODUCT_BODY                                                                    \
  Index c0 = 0;                                                                              \
  for (; c0 + 4 <= C; c0 += 4) product_columns<4>(G, ldg, X, ldx, M, ldm, R, S, c0, add);    \
  switch (C - c0) {                                                                          \
    case 3: product_columns<3>(G, ldg, X, ldx, M, ldm, R, S, c0, add); break;                \
    case 2: product_columns<2>(G, ldg, X, ldx, M, ldm, R, S, c0, add); break;                \
    case 1: product_columns<1>(G, ldg, X, ldx, M, ldm, R, S, c0, add); break;                \
    default: break;                                                                          \
  }

namespace generic {
inline void product(CDAM_PRODUCT_ARGS) { CDAM_PRODUCT_BODY }
}  // namespace generic
#if CDAM_HAVE_AVX2_CLONE
namespace avx2 {
__attribute__((target("avx2,fma"))) inline void product(CDAM_PRODUCT_ARGS) { CDAM_PRODUCT_BODY }
}  // namespace avx2
#endif
#undef CDAM_PRODUCT_ARGS
#undef CDAM_PRODUCT_BODY

}  // namespace kernel

// G[:, c] = (add ? G[:, c] : 0) + sum_s X[:, s] M[c ldm + s] for c < C, s < S; G and X
// column-major (R rows; leading dimensions ldg, ldx). G must not overlap X or M.
inline void sensitivity_product(double* G, Index ldg, const double* X, Index ldx, const double* M,
                                Index ldm, Index R, Index C, Index S, bool add,
                                KernelPath p = KernelPath::Auto) {
#if CDAM_HAVE_AVX2_CLONE
  if (avx2_path(p)) return kernel::avx2::product(G, ldg, X, ldx, M, ldm, R, C, S, add);
#endif
  (void)p;
  kernel::generic::product(G, ldg, X, ldx, M, ldm, R, C, S, add);
}

}  // namespace cdam::host
