// Vectorised host kernels of the BP network, in double (shared by host/normal_equations.hpp and
// host/bp_fitness.hpp, hence here and not under optim/): the sum of squared
// errors ("sse") of one network over a range of samples (`sse_soa`), the hidden activation over
// a buffer (`activate_inplace`), and the rank update G += V V' (`syrk_lower`, the J'J blocks of
// normal_equations.hpp; `jtj_blocks`, the same tiles on the network's symmetric blocks), the
// blocked Cholesky of LM's solve (`cholesky_lower`, `cholesky_solve`). The SSE loop is written
// as plain loops over samples that the compiler vectorises, in a structure-of-arrays layout
// (each input and target channel contiguous over the samples).
//
// Per block of B samples (B = 128 by default: the h x B hidden activations and the input and
// target rows of a block stay in L1):
//   a_j(s) = b1_j + sum_l W1(j, l) x_l(s) for every j;  a = act(a);
//   y_k(s) = b2_k + sum_j W2(k, j) a_j(s);  sse += sum_k sum_s (t_k(s) - y_k(s))^2,
// the sums over l and j kept in registers for 4 samples at a time.
//
// The activation is computed with one exponential and one division per value:
//   exp(x) = 2^n E(r), n = round(x / ln 2), r = x - n ln 2 (two-part ln 2), and Cephes' Pade form
//   E(r) = (Q(r^2) + r P(r^2)) / (Q(r^2) - r P(r^2))  (the form Eigen's pexp uses; about 1 ulp);
//   tansig: tanh(a) = (e^{2a} - 1) / (e^{2a} + 1) = ((s - 1) Q + (s + 1) rP) / ((s + 1) Q +
//   (s - 1) rP), s = 2^n, r from x = 2a clamped to [-40, 40] (tanh(20) rounds to 1); near 0
//   (n = 0) this is exactly 2 rP / 2 Q, so the relative accuracy holds there too;
//   logsig: 1 / (1 + e^{-a}) = Qm / (Qm + 2^n Qp), Qp = Q + rP, Qm = Q - rP, with x = -a
//   clamped to [-700, 700].
// 2^n is built from the bits of the rounded value (no floor, no libm call), so the loop
// vectorises with SSE2 already. Measured against std::tanh / the logistic function on a dense
// grid over [-40, 40] (tests): tanh within 3e-16 absolute and 1e-15 relative, the logistic
// function within 1e-15 relative.
//
// On x86-64 with GCC or Clang the same body is also compiled for AVX2 + FMA and chosen at run
// time when the CPU has them (`KernelPath::Auto`; `KernelPath::Generic` forces the SSE2 build):
// 4 doubles per instruction instead of 2, and FMA. The tiles' generic build is slow (the
// 8-accumulator tile spills with SSE2 registers): normal_equations.hpp and training.hpp only
// call grad_block, jtj_reduced and the Cholesky on the AVX2 path and keep Eigen's products,
// rankUpdate and LLT otherwise (jtj_blocks, the session-6 form, is no longer called by the LM;
// it is kept with its test). The SSE kernel is also built for AVX-512 and taken when the CPU has
// it (issue 23 item 2: 0.43 against 0.52 ms at 10,000 x 6-20-8).
// Both paths give the same value to rounding (FMA contraction may change the last bits); one
// machine always takes the same path, so a seed still gives the same run.
// Measured (10,000 samples, 6-20-8, shared 2-core AMD EPYC, load 3-7): the SSE kernel 0.65-0.9
// ms CPU per evaluation (the former Eigen version 3.5-7 ms), the activation of 200,000 values
// 0.28 ms (std::tanh 3.8 ms), the 160 x 160 rank update over 10,000 samples 13 ms (Eigen 41).
#ifdef CDAM_TARGET_EMBEDDED
#error "cdam/host/kernels.hpp is host-only (x86 AVX2 dispatch, GCC vector extensions)"
#endif
#pragma once
#include <cmath>
#include <cstdint>
#include <cstring>

#include "../activation.hpp"
#include "../mlp.hpp"

namespace cdam::host {

namespace kernel {

// tanh (tansig) or logistic (logsig) of v[0..n), in place.
#define CDAM_ACT_BODY                                                                       \
  constexpr double kLog2e = 1.4426950408889634074, kC1 = 0.693145751953125,                 \
                   kC2 = 1.42860682030941723212e-6, kMagic = 6755399441055744.0; /* 1.5 2^52 */ \
  constexpr double p0 = 1.26177193074810590878e-4, p1 = 3.02994407707441961300e-2,           \
                   p2 = 9.99999999999999999910e-1;                                           \
  constexpr double q0 = 3.00198505138664455042e-6, q1 = 2.52448340349684104192e-3,           \
                   q2 = 2.27265548208155028766e-1, q3 = 2.00000000000000000009e0;            \
  const double sx = tansig ? 2.0 : -1.0, lim = tansig ? 40.0 : 700.0;                         \
  for (Index s = 0; s < n; ++s) {                                                            \
    double x = sx * v[s];                                                                    \
    x = x > lim ? lim : (x < -lim ? -lim : x);                                               \
    const double t = x * kLog2e + kMagic;                                                    \
    const double fn = t - kMagic;                                                            \
    std::uint64_t bits;                                                                      \
    std::memcpy(&bits, &t, sizeof bits);                                                     \
    /* low bits of t hold n + 2^51; 2^n has exponent field n + 1023 */                      \
    bits = (bits - 0x4338000000000000ULL + 1023ULL) << 52;                                   \
    double p2n;                                                                              \
    std::memcpy(&p2n, &bits, sizeof bits);                                                   \
    const double r = (x - fn * kC1) - fn * kC2;                                              \
    const double r2 = r * r;                                                                 \
    const double px = r * ((p0 * r2 + p1) * r2 + p2);                                        \
    const double qx = ((q0 * r2 + q1) * r2 + q2) * r2 + q3;                                  \
    const double sm = p2n - 1.0, sp = p2n + 1.0;                                             \
    const double num = tansig ? sm * qx + sp * px : qx - px;                                 \
    const double den = tansig ? sp * qx + sm * px : (qx - px) + p2n * (qx + px);             \
    v[s] = num / den; /* one division per value */                                           \
  }

// The outputs of the vectors of samples at s (V: the vector type, one sample a lane; the
// hidden activations at a + j B + s), 4 at a time, and their squared errors added to the
// vector TOT: y_k = b2_k + sum_j W2(k, j) a_j, e_k = t_k - y_k. Shared by the double kernel
// below and the float32 one (kernels_f32.hpp).
#define CDAM_OUTPUT_ERRORS(V, TOT)                                                           \
  Index k0 = 0;                                                                              \
  for (; k0 + 4 <= m; k0 += 4) {                                                             \
    V y0 = V{} + b2[k0], y1 = V{} + b2[k0 + 1], y2 = V{} + b2[k0 + 2], y3 = V{} + b2[k0 + 3]; \
    for (Index j = 0; j < h; ++j) {                                                          \
      V aj;                                                                                  \
      std::memcpy(&aj, a + j * B + s, sizeof aj);                                            \
      const auto* w = W2 + j * m + k0;                                                       \
      y0 += w[0] * aj;                                                                       \
      y1 += w[1] * aj;                                                                       \
      y2 += w[2] * aj;                                                                       \
      y3 += w[3] * aj;                                                                       \
    }                                                                                        \
    V t0, t1, t2, t3;                                                                        \
    std::memcpy(&t0, T + k0 * ld + s0 + s, sizeof t0);                                       \
    std::memcpy(&t1, T + (k0 + 1) * ld + s0 + s, sizeof t1);                                 \
    std::memcpy(&t2, T + (k0 + 2) * ld + s0 + s, sizeof t2);                                 \
    std::memcpy(&t3, T + (k0 + 3) * ld + s0 + s, sizeof t3);                                 \
    t0 -= y0;                                                                                \
    t1 -= y1;                                                                                \
    t2 -= y2;                                                                                \
    t3 -= y3;                                                                                \
    TOT += (t0 * t0 + t1 * t1) + (t2 * t2 + t3 * t3);                                        \
  }                                                                                          \
  for (; k0 < m; ++k0) {                                                                     \
    V y0 = V{} + b2[k0];                                                                     \
    for (Index j = 0; j < h; ++j) {                                                          \
      V aj;                                                                                  \
      std::memcpy(&aj, a + j * B + s, sizeof aj);                                            \
      y0 += W2[j * m + k0] * aj;                                                             \
    }                                                                                        \
    V t0;                                                                                    \
    std::memcpy(&t0, T + k0 * ld + s0 + s, sizeof t0);                                       \
    t0 -= y0;                                                                                \
    TOT += t0 * t0;                                                                          \
  }

// SSE of one network (W1 h x i, b1, W2 m x h, b2; column-major) over samples [0, n) of the
// SoA record: x_l(s) = X[l * ld + s], t_k(s) = T[k * ld + s]. a: h B values of caller
// storage. Register-blocked over 4 samples (one vector of 4 doubles: one ymm
// with AVX2, two xmm otherwise): phase 1 writes the hidden sums of a block, the activation runs
// over the block, phase 2 accumulates 4 outputs at a time in registers and the squared errors.
#define CDAM_SSE_BODY                                                                        \
  typedef double v4d __attribute__((vector_size(32)));                                       \
  v4d total4 = {0.0, 0.0, 0.0, 0.0};                                                         \
  double total = 0.0;                                                                        \
  for (Index s0 = 0; s0 < n; s0 += B) {                                                      \
    const Index nb = n - s0 < B ? n - s0 : B, nv = nb & ~Index(3);                           \
    for (Index s = 0; s < nv; s += 4) {                                                      \
      for (Index j = 0; j < h; ++j) {                                                        \
        v4d acc = {b1[j], b1[j], b1[j], b1[j]};                                              \
        for (Index l = 0; l < i; ++l) {                                                      \
          v4d x;                                                                             \
          std::memcpy(&x, X + l * ld + s0 + s, sizeof x);                                    \
          acc += W1[j + l * h] * x;                                                          \
        }                                                                                    \
        std::memcpy(a + j * B + s, &acc, sizeof acc);                                        \
      }                                                                                      \
    }                                                                                        \
    for (Index s = nv; s < nb; ++s)                                                          \
      for (Index j = 0; j < h; ++j) {                                                        \
        double acc = b1[j];                                                                  \
        for (Index l = 0; l < i; ++l) acc += W1[j + l * h] * X[l * ld + s0 + s];             \
        a[j * B + s] = acc;                                                                  \
      }                                                                                      \
    activate_block(a, h * B, tansig);                                                        \
    for (Index s = 0; s < nv; s += 4) {                                                      \
      CDAM_OUTPUT_ERRORS(v4d, total4)                                                        \
    }                                                                                        \
    for (Index s = nv; s < nb; ++s)                                                          \
      for (Index k = 0; k < m; ++k) {                                                        \
        double yk = b2[k];                                                                   \
        for (Index j = 0; j < h; ++j) yk += W2[j * m + k] * a[j * B + s];                    \
        const double e = T[k * ld + s0 + s] - yk;                                            \
        total += e * e;                                                                      \
      }                                                                                      \
  }                                                                                          \
  return total + ((total4[0] + total4[1]) + (total4[2] + total4[3]));

// One slice of ns samples: G (leading dimension ldg) += X W^T, X: R rows, W: C rows, both
// column-major with leading dimension ldv (one sample a column). lower: only the entries on and
// below the diagonal (row >= column; some just above it, in the 4 x 4 diagonal tiles, are
// written too, with their correct values when X = W); otherwise all R x C. Tiles of 8 rows x 4
// columns kept in 8 vector registers. alpha: +1 or -1 (exact: the sums are those of alpha = 1).
#define CDAM_TILES_BODY                                                                      \
  typedef double v4d __attribute__((vector_size(32)));                                       \
  Index c0 = 0;                                                                              \
  for (; c0 + 4 <= C; c0 += 4) {                                                             \
    Index r = lower ? c0 : 0;                                                                \
    for (; r + 8 <= R; r += 8) {                                                             \
      v4d a0 = {0, 0, 0, 0}, a1 = a0, a2 = a0, a3 = a0, b0 = a0, b1 = a0, b2 = a0, b3 = a0;   \
      for (Index s = 0; s < ns; ++s) {                                                       \
        const double* xc = X + s * ldv;                                                      \
        const double* wc = W + s * ldv;                                                      \
        v4d x, y;                                                                            \
        std::memcpy(&x, xc + r, sizeof x);                                                   \
        std::memcpy(&y, xc + r + 4, sizeof y);                                               \
        const double w0 = wc[c0], w1 = wc[c0 + 1], w2 = wc[c0 + 2], w3 = wc[c0 + 3];         \
        a0 += x * w0; a1 += x * w1; a2 += x * w2; a3 += x * w3;                              \
        b0 += y * w0; b1 += y * w1; b2 += y * w2; b3 += y * w3;                              \
      }                                                                                      \
      const v4d* acc[8] = {&a0, &a1, &a2, &a3, &b0, &b1, &b2, &b3};                          \
      for (int q = 0; q < 4; ++q) {                                                          \
        double* g = G + r + (c0 + q) * ldg;                                                  \
        v4d g0, g1;                                                                          \
        std::memcpy(&g0, g, sizeof g0);                                                      \
        std::memcpy(&g1, g + 4, sizeof g1);                                                  \
        g0 += alpha * *acc[q];                                                               \
        g1 += alpha * *acc[4 + q];                                                           \
        std::memcpy(g, &g0, sizeof g0);                                                      \
        std::memcpy(g + 4, &g1, sizeof g1);                                                  \
      }                                                                                      \
    }                                                                                        \
    for (; r + 4 <= R; r += 4) {                                                             \
      v4d a0 = {0, 0, 0, 0}, a1 = a0, a2 = a0, a3 = a0;                                      \
      for (Index s = 0; s < ns; ++s) {                                                       \
        const double* wc = W + s * ldv;                                                      \
        v4d x;                                                                               \
        std::memcpy(&x, X + s * ldv + r, sizeof x);                                          \
        a0 += x * wc[c0]; a1 += x * wc[c0 + 1]; a2 += x * wc[c0 + 2];                        \
        a3 += x * wc[c0 + 3];                                                                \
      }                                                                                      \
      const v4d* acc[4] = {&a0, &a1, &a2, &a3};                                              \
      for (int q = 0; q < 4; ++q) {                                                          \
        double* g = G + r + (c0 + q) * ldg;                                                  \
        v4d g0;                                                                              \
        std::memcpy(&g0, g, sizeof g0);                                                      \
        g0 += alpha * *acc[q];                                                               \
        std::memcpy(g, &g0, sizeof g0);                                                      \
      }                                                                                      \
    }                                                                                        \
    for (; r < R; ++r)                                                                       \
      for (Index c = c0; c < c0 + 4; ++c) {                                                  \
        double acc = 0.0;                                                                    \
        for (Index s = 0; s < ns; ++s) acc += X[r + s * ldv] * W[c + s * ldv];               \
        G[r + c * ldg] += alpha * acc;                                                       \
      }                                                                                      \
  }                                                                                          \
  for (; c0 < C; ++c0)                                                                       \
    for (Index r = lower ? c0 : 0; r < R; ++r) {                                             \
      double acc = 0.0;                                                                      \
      for (Index s = 0; s < ns; ++s) acc += X[r + s * ldv] * W[c0 + s * ldv];                \
      G[r + c0 * ldg] += alpha * acc;                                                        \
    }

// G += alpha V V^T on and below the diagonal (see CDAM_TILES_BODY), V: P x nb column-major with
// leading dimension ldv. Samples in slices of 32 (the slice of V stays in L1).
#define CDAM_SYRK_BODY                                                                       \
  for (Index s0 = 0; s0 < nb; s0 += 32) {                                                    \
    const double* Vs = V + s0 * ldv;                                                         \
    tiles(G, ldg, Vs, Vs, ldv, P, P, nb - s0 < 32 ? nb - s0 : 32, true, alpha);              \
  }

// The J'J sums of normal_equations.hpp with the network's symmetries (issue 23, item 2). V (rows
// of one sample, column-major, leading dimension ldv, nb samples): nz = i + 1 blocks of h rows
// v_l = z_l d (l h .. l h + h - 1), then a (h rows), then a row of ones; K (leading dimension
// ldk) receives, per slice of 32 samples:
//   for l >= l': the lower triangle of sum v_l v_l'^T: each such h x h block is symmetric
//                (z_l z_l' d d^T), so its upper triangle is not computed;
//   sum [a; 1] v_l^T in full ((h + 1) x h: the C blocks with the sums of v in the last row);
//   the lower triangle of sum [a; 1] [a; 1]^T (R, with the sums of a and the sample count).
// Multiply-adds per sample for 6-20-8: about 9,900 against 12,900 for the whole lower triangle
// of [v; a] [v; a]^T; the row sums come with them.
// Row strides: block l of v starts at row l hs and [a; 1] at nz hs, with ha rows; hs >= h and
// ha >= h + 1 let the caller pad each block with rows of zeros to a multiple of 4 (no tile
// remainder runs one row at a time; the padded sums are zero and never read).
#define CDAM_JTJ_BODY                                                                        \
  const Index P = nz * hs;                                                                   \
  for (Index s0 = 0; s0 < nb; s0 += 32) {                                                    \
    const Index ns = nb - s0 < 32 ? nb - s0 : 32;                                            \
    const double* Vs = V + s0 * ldv;                                                         \
    for (Index l = 0; l < nz; ++l)                                                           \
      for (Index l2 = 0; l2 <= l; ++l2)                                                      \
        tiles(K + l * hs + l2 * hs * ldk, ldk, Vs + l * hs, Vs + l2 * hs, ldv, hs, hs, ns, true, \
              1.0);                                                                          \
    for (Index l = 0; l < nz; ++l)                                                           \
      tiles(K + P + l * hs * ldk, ldk, Vs + P, Vs + l * hs, ldv, ha, hs, ns, false, 1.0);    \
    tiles(K + P + P * ldk, ldk, Vs + P, Vs + P, ldv, ha, ha, ns, true, 1.0);                 \
  }

// The reduced J'J sums (issue 23, item 2): the hidden-hidden sums S(l h + j, l' h + j') =
// sum z_l z_l' d_j d_j' use the symmetry in the inputs and in the hidden units separately: per
// slice of samples the products w = d_j d_j' (j >= j', hw rows, the pairs j (j + 1) / 2 + j', zero
// rows up to hw) and u = z_l z_l' (l >= l', nu rows, pairs l (l + 1) / 2 + l', z_{nz-1} = 1)
// are formed in buf (ld hw + nu, SLICE columns) and Kh (hw x nu, leading dimension ldh) +=
// w u^T by the dense 8 x 4 tiles: h (h + 1) / 2 (i + 1) (i + 2) / 2 multiply-adds a sample (5,880
// for 6-20-8) with no triangle waste, against 6,720 for the lower triangles of the h x h blocks.
// The rest as in CDAM_JTJ_BODY, into K (ha x (P + ha), leading dimension ldk, P = nz hs):
// columns 0 .. P - 1 receive sum [a; 1] v^T (the C blocks, the row sums of v in row h), columns
// P .. P + ha - 1 the lower triangle of sum [a; 1] [a; 1]^T (R). d is V's block nz - 1
// (z_{nz-1} = 1, so v_{nz-1} = d); the inputs z_l (l < nz - 1) are X[l + s ldx].
// One body for double (S double, VEC 4 doubles, SLICE kPairSlice, CDAM_JTJR_DOUBLE) and float
// (kernels_f32.hpp: 8 floats, SLICE kLmSlice): ADD_PRODUCTS(G, ldg, X, W, ldv, R, C, ns, lower)
// as in CDAM_FB_BODY (double: tiles; float: lm_tiles). Left defined for kernels_f32.hpp (which
// undefines it).
#define CDAM_JTJR_BODY(S, VEC, LANES, ADD_PRODUCTS, SLICE)                                    \
  const Index P = nz * hs, ldb = hw + nu, hp = h * (h + 1) / 2;                               \
  const S* Dv = V + (nz - 1) * hs;                                                            \
  for (Index s0 = 0; s0 < nb; s0 += SLICE) {                                                  \
    const Index ns = nb - s0 < SLICE ? nb - s0 : SLICE;                                       \
    for (Index s = 0; s < ns; ++s) {                                                          \
      const S* d = Dv + (s0 + s) * ldv;                                                       \
      const S* x = X + (s0 + s) * ldx;                                                        \
      S* w = buf + s * ldb;                                                                   \
      /* whole LANES-vectors: row j's last store may run up to LANES - 1 values into the     \
         rows after it (written next), the padding or u (written after), in float (8 lanes)   \
         also into the next sample (written after) or the buffer's slack past the last; d is  \
         read within its padded block */                                                      \
      for (Index j = 0; j < h; ++j) {                                                         \
        const S dj = d[j];                                                                    \
        S* wj = w + j * (j + 1) / 2;                                                          \
        for (Index j2 = 0; j2 <= j; j2 += LANES) {                                            \
          VEC dv;                                                                             \
          std::memcpy(&dv, d + j2, sizeof dv);                                                \
          dv *= dj;                                                                           \
          std::memcpy(wj + j2, &dv, sizeof dv);                                               \
        }                                                                                     \
      }                                                                                       \
      for (Index q = hp; q < hw; ++q) w[q] = S(0);                                            \
      S* u = w + hw;                                                                          \
      Index q = 0;                                                                            \
      for (Index l = 0; l < nz; ++l) {                                                        \
        const S zl = l + 1 < nz ? x[l] : S(1);                                                \
        for (Index l2 = 0; l2 <= l; ++l2) u[q++] = zl * (l2 + 1 < nz ? x[l2] : S(1));         \
      }                                                                                       \
      for (; q < nu; ++q) u[q] = S(0);                                                        \
    }                                                                                         \
    ADD_PRODUCTS(Kh, ldh, buf, buf + hw, ldb, hw, nu, ns, false);                             \
    const S* Vs = V + s0 * ldv;                                                               \
    ADD_PRODUCTS(K, ldk, Vs + P, Vs, ldv, ha, P, ns, false);                                  \
    ADD_PRODUCTS(K + P * ldk, ldk, Vs + P, Vs + P, ldv, ha, ha, ns, true);                    \
  }


// The gradient pass of LM (normal_equations.hpp modes 1 and 2) over one block of nb samples,
// one sample a column (X: i x nb, leading dimension i; T: m x nb, leading dimension m), in
// place of Eigen's small products; one body for double (below) and float (kernels_f32.hpp).
// The weights come zero-padded (W1p hs x i, b1p hs, W2p me x h, b2p me, W2tp = W2' hs x m,
// each column a whole number of LANES-vectors VEC of S), so every sum runs in a register over
// whole vectors of hidden units or outputs: a = act(W1 x + b1) for every sample into A
// (hs x nb), then per sample y = W2 a + b2, e = t - y, sse += e'e (each squared error in S,
// summed in double), g = (W2' e) .* d (d = act'(a)), written into V's column (leading dimension
// ldv): a at row pa (h rows; row pa + h holds 1), e at pe (me), g at pg (hs), x at pz (row
// pz + i holds 1; the constant and padding rows are the caller's), and with full (mode 2) the
// fused layout's v_l = d x_l at rows l hs (l < i) and d at i hs (their padding rows get values
// that are never read). The gradient sums then come from the tiles, per slice of SLICE
// samples: gO (me x ha, leading dimension me) += e [a; 1]', gH (hs x nzp, leading dimension
// hs) += g [x; 1]'. Without grad only the sse (and e) is computed. Returns the block's sse.
// The paths' hooks: ACT_VECTOR(v), the activation of one vector of hidden sums before it is
// stored (float: the float tanh in registers); ACT_BLOCK(A, n, tansig), that of the block's
// n hidden values after the sums (double: activate_block); ADD_PRODUCTS(G, ldg, X, W, ldv, R,
// C, ns, lower): G (double) += X W' over ns samples, R x C, lower as tiles' (double: tiles;
// float: lm_tiles, each slice's float sums added into double). Double (CDAM_FB_DOUBLE): S
// double, 4 lanes, SLICE 32.
// A macro, not a template: a template (the hooks as an always-inlined policy class) gave the
// same results bit for bit but other register allocation and code placement, and the double
// gradient pass 4-7 % slower (mlp_mse_gradient at 10,000 x 6-20-8, best of 7: 1.17-1.23
// against 1.13-1.15 ms, A/B interleaved, load 2; session 9); with the macro the extension
// builds to the same bytes as with the two former bodies. Left defined for kernels_f32.hpp (which
// undefines it, as CDAM_OUTPUT_ERRORS and CDAM_FB_ARGS).
#define CDAM_FB_BODY(S, VEC, LANES, ACT_VECTOR, ACT_BLOCK, ADD_PRODUCTS, SLICE)               \
  for (Index s = 0; s < nb; ++s) {                                                            \
    const S* x = X + s * i;                                                                   \
    for (Index j0 = 0; j0 < hs; j0 += LANES) {                                                \
      VEC acc;                                                                                \
      std::memcpy(&acc, b1p + j0, sizeof acc);                                                \
      for (Index l = 0; l < i; ++l) {                                                         \
        VEC w;                                                                                \
        std::memcpy(&w, W1p + l * hs + j0, sizeof w);                                         \
        acc += w * x[l];                                                                      \
      }                                                                                       \
      ACT_VECTOR(acc);                                                                        \
      std::memcpy(A + s * hs + j0, &acc, sizeof acc);                                         \
    }                                                                                         \
  }                                                                                           \
  ACT_BLOCK(A, hs * nb, tansig);                                                              \
  double sse = 0.0;                                                                           \
  for (Index s = 0; s < nb; ++s) {                                                            \
    const S* x = X + s * i;                                                                   \
    const S* t = T + s * m;                                                                   \
    const S* as = A + s * hs;                                                                 \
    S* vs = V + s * ldv;                                                                      \
    S* e = vs + pe;                                                                           \
    for (Index k0 = 0; k0 < me; k0 += LANES) {                                                \
      VEC acc;                                                                                \
      std::memcpy(&acc, b2p + k0, sizeof acc);                                                \
      for (Index j = 0; j < h; ++j) {                                                         \
        VEC w;                                                                                \
        std::memcpy(&w, W2p + j * me + k0, sizeof w);                                         \
        acc += w * as[j];                                                                     \
      }                                                                                       \
      std::memcpy(e + k0, &acc, sizeof acc);                                                  \
    }                                                                                         \
    for (Index k = 0; k < m; ++k) {                                                           \
      e[k] = t[k] - e[k];                                                                     \
      sse += static_cast<double>(e[k] * e[k]);                                                \
    }                                                                                         \
    if (!grad) continue;                                                                      \
    for (Index k = m; k < me; ++k) e[k] = S(0);                                               \
    for (Index j0 = 0; j0 < hs; j0 += LANES) {                                                \
      VEC acc = {}, av;                                                                       \
      for (Index k = 0; k < m; ++k) {                                                         \
        VEC w;                                                                                \
        std::memcpy(&w, W2tp + k * hs + j0, sizeof w);                                        \
        acc += w * e[k];                                                                      \
      }                                                                                       \
      std::memcpy(&av, as + j0, sizeof av);                                                   \
      const VEC dv = tansig ? S(1) - av * av : av * (S(1) - av);                              \
      acc *= dv;                                                                              \
      std::memcpy(vs + pg + j0, &acc, sizeof acc);                                            \
      if (full) {                                                                             \
        for (Index l = 0; l < i; ++l) {                                                       \
          const VEC vl = dv * x[l];                                                           \
          std::memcpy(vs + l * hs + j0, &vl, sizeof vl);                                      \
        }                                                                                     \
        std::memcpy(vs + i * hs + j0, &dv, sizeof dv);                                        \
      }                                                                                       \
    }                                                                                         \
    std::memcpy(vs + pa, as, sizeof(S) * h);                                                  \
    std::memcpy(vs + pz, x, sizeof(S) * i);                                                   \
  }                                                                                           \
  for (Index s0 = 0; grad && s0 < nb; s0 += SLICE) {                                          \
    const Index ns = nb - s0 < SLICE ? nb - s0 : SLICE;                                       \
    const S* Vs = V + s0 * ldv;                                                               \
    ADD_PRODUCTS(gO, me, Vs + pe, Vs + pa, ldv, me, ha, ns, false);                           \
    ADD_PRODUCTS(gH, hs, Vs + pg, Vs + pz, ldv, hs, nzp, ns, false);                          \
  }                                                                                           \
  return sse;

// Cholesky factor of the symmetric n x n matrix A (lower triangle read, column-major, leading
// dimension ld) in place: A = L L', L in the lower triangle (the strict upper triangle is
// scratch). Right-looking, in panels of kCholPanel columns: the panel's diagonal block by
// plain loops, the rows below it by a triangular solve (column updates the compiler
// vectorises), the trailing matrix by syrk_lower with alpha = -1. Returns 0, or k + 1 when the
// k-th pivot is not positive (or NaN): A is then not positive definite.
#define CDAM_CHOL_BODY                                                                       \
  for (Index k0 = 0; k0 < n; k0 += kCholPanel) {                                             \
    const Index kb = n - k0 < kCholPanel ? n - k0 : kCholPanel, k1 = k0 + kb;                \
    for (Index c = k0; c < k1; ++c) {                                                        \
      double* col = A + c * ld;                                                              \
      const double d = col[c];                                                               \
      if (!(d > 0.0)) return c + 1;                                                          \
      const double l = std::sqrt(d), inv = 1.0 / l;                                          \
      col[c] = l;                                                                            \
      for (Index r = c + 1; r < n; ++r) col[r] *= inv;                                       \
      for (Index c2 = c + 1; c2 < k1; ++c2) {                                                \
        double* col2 = A + c2 * ld;                                                          \
        const double f = col[c2];                                                            \
        for (Index r = c2; r < n; ++r) col2[r] -= col[r] * f;                                \
      }                                                                                      \
    }                                                                                        \
    if (k1 < n)                                                                              \
      syrk_lower(A + k1 + k1 * ld, ld, A + k1 + k0 * ld, ld, n - k1, kb, -1.0);              \
  }                                                                                          \
  return 0;

// Solves L L' x = b in place (b: n values) with the factor of CDAM_CHOL_BODY.
#define CDAM_CHOL_SOLVE_BODY                                                                 \
  for (Index c = 0; c < n; ++c) {                                                            \
    const double* col = L + c * ld;                                                          \
    const double y = b[c] / col[c];                                                          \
    b[c] = y;                                                                                \
    for (Index r = c + 1; r < n; ++r) b[r] -= col[r] * y;                                    \
  }                                                                                          \
  for (Index c = n - 1; c >= 0; --c) {                                                       \
    const double* col = L + c * ld;                                                          \
    double acc = 0.0;                                                                        \
    for (Index r = c + 1; r < n; ++r) acc += col[r] * b[r];                                  \
    b[c] = (b[c] - acc) / col[c];                                                            \
  }

#define CDAM_SYRK_ARGS                                                                       \
  double *__restrict G, Index ldg, const double *__restrict V, Index ldv, Index P, Index nb,  \
      double alpha

#define CDAM_TILES_ARGS                                                                      \
  double *__restrict G, Index ldg, const double *__restrict X, const double *__restrict W,    \
      Index ldv, Index R, Index C, Index ns, bool lower, double alpha

#define CDAM_JTJ_ARGS                                                                        \
  double *__restrict K, Index ldk, const double *__restrict V, Index ldv, Index hs, Index ha, \
      Index nz, Index nb

#define CDAM_JTJR_ARGS                                                                       \
  double *__restrict Kh, Index ldh, double *__restrict K, Index ldk,                          \
      const double *__restrict V, Index ldv, const double *__restrict X, Index ldx, Index h,   \
      Index hs, Index ha, Index nz, Index hw, Index nu, Index nb, double *__restrict buf

// The gradient pass's arguments (S: double or float).
#define CDAM_FB_ARGS(S)                                                                      \
  const S *__restrict W1p, const S *__restrict b1p, const S *__restrict W2p,                  \
      const S *__restrict b2p, const S *__restrict W2tp, Index i, Index h, Index m, Index hs,  \
      Index me, bool tansig, const S *__restrict X, const S *__restrict T, Index nb,           \
      S *__restrict A, double *__restrict gH, Index nzp, double *__restrict gO, Index ha,      \
      S *__restrict V, Index ldv, Index pa, Index pe, Index pg, Index pz, bool grad, bool full
// No activation hook of CDAM_FB_BODY (ACT_VECTOR, ACT_BLOCK); left defined for kernels_f32.hpp.
#define CDAM_FB_NO_ACT(...)
// The double gradient pass (the hooks: this build's activate_block and tiles).
// The double bodies of the gradient pass and the reduced J'J (their hooks: this build's
// activate_block and tiles).
#define CDAM_TILES_SUM(G, ldg, X, W, ldv, R, C, ns, lower)                                   \
  tiles(G, ldg, X, W, ldv, R, C, ns, lower, 1.0)
#define CDAM_FB_DOUBLE                                                                       \
  typedef double v4d __attribute__((vector_size(32)));                                       \
  CDAM_FB_BODY(double, v4d, 4, CDAM_FB_NO_ACT, activate_block, CDAM_TILES_SUM, 32)
#define CDAM_JTJR_DOUBLE                                                                     \
  typedef double v4d __attribute__((vector_size(32)));                                       \
  CDAM_JTJR_BODY(double, v4d, 4, CDAM_TILES_SUM, kPairSlice)

#define CDAM_SSE_ARGS                                                                        \
  const double *__restrict W1, const double *__restrict b1, const double *__restrict W2,      \
      const double *__restrict b2, Index i, Index h, Index m, bool tansig,                    \
      const double *__restrict X, const double *__restrict T, Index ld, Index n,              \
      double *__restrict a, Index B

// Columns per panel of the blocked Cholesky (one syrk_lower slice of samples).
constexpr Index kCholPanel = 32;
// Samples per slice of the reduced J'J's pair products (buf: (hw + nu) kPairSlice doubles).
constexpr Index kPairSlice = 16;

namespace generic {
inline void activate_block(double* __restrict v, Index n, bool tansig) { CDAM_ACT_BODY }
inline double sse_block(CDAM_SSE_ARGS) { CDAM_SSE_BODY }
inline void tiles(CDAM_TILES_ARGS) { CDAM_TILES_BODY }
inline void syrk_lower(CDAM_SYRK_ARGS) { CDAM_SYRK_BODY }
inline void jtj_blocks(CDAM_JTJ_ARGS) { CDAM_JTJ_BODY }
inline void jtj_reduced(CDAM_JTJR_ARGS) { CDAM_JTJR_DOUBLE }
inline double grad_block(CDAM_FB_ARGS(double)) { CDAM_FB_DOUBLE }
inline Index cholesky_lower(double* A, Index ld, Index n) { CDAM_CHOL_BODY }
inline void cholesky_solve(const double* L, Index ld, Index n, double* b) { CDAM_CHOL_SOLVE_BODY }
}  // namespace generic

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__)) && !defined(__AVX2__)
#define CDAM_HAVE_AVX2_CLONE 1
namespace avx2 {
__attribute__((target("avx2,fma"))) inline void activate_block(double* __restrict v, Index n,
                                                               bool tansig) {
  CDAM_ACT_BODY
}
__attribute__((target("avx2,fma"))) inline double sse_block(CDAM_SSE_ARGS) { CDAM_SSE_BODY }
__attribute__((target("avx2,fma"))) inline void tiles(CDAM_TILES_ARGS) { CDAM_TILES_BODY }
__attribute__((target("avx2,fma"))) inline void syrk_lower(CDAM_SYRK_ARGS) { CDAM_SYRK_BODY }
__attribute__((target("avx2,fma"))) inline void jtj_blocks(CDAM_JTJ_ARGS) { CDAM_JTJ_BODY }
__attribute__((target("avx2,fma"))) inline void jtj_reduced(CDAM_JTJR_ARGS) {
  CDAM_JTJR_DOUBLE
}
__attribute__((target("avx2,fma"))) inline double grad_block(CDAM_FB_ARGS(double)) {
  CDAM_FB_DOUBLE
}
__attribute__((target("avx2,fma"))) inline Index cholesky_lower(double* A, Index ld, Index n) {
  CDAM_CHOL_BODY
}
__attribute__((target("avx2,fma"))) inline void cholesky_solve(const double* L, Index ld, Index n,
                                                               double* b) {
  CDAM_CHOL_SOLVE_BODY
}
}  // namespace avx2
// AVX-512 (F, VL, DQ): the SSE pass of LM's trial steps only, where the 8-lane activation pays
// (10,000 x 6-20-8: 0.43 against 0.52 ms on the AVX2 build; the J'J tiles, the gradient pass and
// the Cholesky measured no faster with it, so they keep the AVX2 build).
namespace avx512 {
#define CDAM_TARGET_512 \
  __attribute__((target("avx512f,avx512vl,avx512dq,avx2,fma,prefer-vector-width=512")))
CDAM_TARGET_512 inline void activate_block(double* __restrict v, Index n, bool tansig) {
  CDAM_ACT_BODY
}
CDAM_TARGET_512 inline double sse_block(CDAM_SSE_ARGS) { CDAM_SSE_BODY }
#undef CDAM_TARGET_512
}  // namespace avx512
inline bool cpu_has_avx2() {
  static const bool has = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return has;
}
inline bool cpu_has_avx512() {
  static const bool has = cpu_has_avx2() && __builtin_cpu_supports("avx512f") &&
                          __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512dq");
  return has;
}
#else
#define CDAM_HAVE_AVX2_CLONE 0
inline bool cpu_has_avx2() { return false; }
inline bool cpu_has_avx512() { return false; }
#endif

#undef CDAM_ACT_BODY
#undef CDAM_SSE_BODY
#undef CDAM_SSE_ARGS
#undef CDAM_SYRK_BODY
#undef CDAM_SYRK_ARGS
#undef CDAM_TILES_BODY
#undef CDAM_TILES_ARGS
#undef CDAM_JTJ_BODY
#undef CDAM_JTJ_ARGS
#undef CDAM_JTJR_DOUBLE
#undef CDAM_JTJR_ARGS
#undef CDAM_TILES_SUM
#undef CDAM_FB_DOUBLE
#undef CDAM_CHOL_BODY
#undef CDAM_CHOL_SOLVE_BODY

}  // namespace kernel

// Which compiled path the kernels take: Auto (AVX2 + FMA when the CPU has them) or Generic.
enum class KernelPath { Auto = 0, Generic = 1 };

inline bool avx2_path(KernelPath p) {
  return p == KernelPath::Auto && kernel::cpu_has_avx2();
}

// tanh or logistic of v[0..n) in place (see the header comment for the accuracy).
inline void activate_inplace(double* v, Index n, Activation act, KernelPath p = KernelPath::Auto) {
  const bool tansig = act == Activation::Tansig;
#if CDAM_HAVE_AVX2_CLONE
  if (avx2_path(p)) return kernel::avx2::activate_block(v, n, tansig);
#endif
  (void)p;
  kernel::generic::activate_block(v, n, tansig);
}

// SSE of the network `net` with parameters theta over n samples of an SoA record (channel l of
// the inputs at X + l ld, channel k of the targets at T + k ld). a: h B doubles of caller
// storage.
inline double sse_soa(const Mlp<double>& net, const double* theta, const double* X,
                      const double* T, Index ld, Index n, double* a, Index B,
                      KernelPath p = KernelPath::Auto) {
  const Index i = net.inputs(), h = net.hidden(), m = net.outputs();
  const double *W1 = theta, *b1 = theta + net.off_b1(), *W2 = theta + net.off_w2(),
               *b2 = theta + net.off_b2();
  const bool tansig = net.activation() == Activation::Tansig;
#if CDAM_HAVE_AVX2_CLONE
  if (avx2_path(p) && kernel::cpu_has_avx512())
    return kernel::avx512::sse_block(W1, b1, W2, b2, i, h, m, tansig, X, T, ld, n, a, B);
  if (avx2_path(p)) return kernel::avx2::sse_block(W1, b1, W2, b2, i, h, m, tansig, X, T, ld, n, a, B);
#endif
  (void)p;
  return kernel::generic::sse_block(W1, b1, W2, b2, i, h, m, tansig, X, T, ld, n, a, B);
}

// G += V V^T on and below the diagonal (see CDAM_SYRK_BODY): G P x P with leading dimension
// ldg, V P x nb column-major with leading dimension ldv. The normal equations' J'J blocks.
inline void syrk_lower(double* G, Index ldg, const double* V, Index ldv, Index P, Index nb,
                       KernelPath p = KernelPath::Auto) {
#if CDAM_HAVE_AVX2_CLONE
  if (avx2_path(p)) return kernel::avx2::syrk_lower(G, ldg, V, ldv, P, nb, 1.0);
#endif
  (void)p;
  kernel::generic::syrk_lower(G, ldg, V, ldv, P, nb, 1.0);
}

// The same with padded blocks (CDAM_JTJ_BODY): block l of v at row l hs (hs >= h), [a; 1] at
// row nz hs with ha >= h + 1 rows (padding rows zero); K at least nz hs + ha square.
inline void jtj_blocks_padded(double* K, Index ldk, const double* V, Index ldv, Index hs, Index ha,
                              Index nz, Index nb, KernelPath p = KernelPath::Auto) {
#if CDAM_HAVE_AVX2_CLONE
  if (avx2_path(p)) return kernel::avx2::jtj_blocks(K, ldk, V, ldv, hs, ha, nz, nb);
#endif
  (void)p;
  kernel::generic::jtj_blocks(K, ldk, V, ldv, hs, ha, nz, nb);
}

// The J'J sums with the network's symmetries (CDAM_JTJ_BODY): V has nz h + h + 1 rows (the
// blocks v_l, a, a row of ones), K (leading dimension ldk, at least nz h + h + 1 square).
inline void jtj_blocks(double* K, Index ldk, const double* V, Index ldv, Index h, Index nz,
                       Index nb, KernelPath p = KernelPath::Auto) {
  jtj_blocks_padded(K, ldk, V, ldv, h, h + 1, nz, nb, p);
}

// The reduced J'J sums (CDAM_JTJR_BODY): Kh (hw x nu, ldh) += the pair products, K the C and R
// blocks as jtj_blocks_padded; X: the inputs (column = sample, ldx), buf: (hw + nu) kPairSlice
// doubles of caller storage.
inline void jtj_reduced(double* Kh, Index ldh, double* K, Index ldk, const double* V, Index ldv,
                        const double* X, Index ldx, Index h, Index hs, Index ha, Index nz,
                        Index hw, Index nu, Index nb, double* buf,
                        KernelPath p = KernelPath::Auto) {
#if CDAM_HAVE_AVX2_CLONE
  if (avx2_path(p))
    return kernel::avx2::jtj_reduced(Kh, ldh, K, ldk, V, ldv, X, ldx, h, hs, ha, nz, hw, nu, nb,
                                     buf);
#endif
  (void)p;
  kernel::generic::jtj_reduced(Kh, ldh, K, ldk, V, ldv, X, ldx, h, hs, ha, nz, hw, nu, nb, buf);
}

// The gradient pass over one block (CDAM_FB_BODY): returns the sse, adds to gH (hs x nzp) and gO
// (me x ha), fills V's rows (and the fused layout's when full). Wp: the padded weights, W1p
// (hs x i), b1p (hs), W2p (me x h), b2p (me), W2tp (hs x m), in that order (pad_weights);
// A: hs nb doubles of caller storage.
inline double grad_block(const double* Wp, Index i, Index h, Index m, Index hs, Index me,
                         bool tansig, const double* X, const double* T, Index nb, double* A,
                         double* gH, Index nzp, double* gO, Index ha, double* V, Index ldv,
                         Index pa, Index pe, Index pg, Index pz, bool grad, bool full,
                         KernelPath p = KernelPath::Auto) {
  const double *W1p = Wp, *b1p = W1p + hs * i, *W2p = b1p + hs, *b2p = W2p + me * h,
               *W2tp = b2p + me;
#if CDAM_HAVE_AVX2_CLONE
  if (avx2_path(p))
    return kernel::avx2::grad_block(W1p, b1p, W2p, b2p, W2tp, i, h, m, hs, me, tansig, X, T, nb,
                                    A, gH, nzp, gO, ha, V, ldv, pa, pe, pg, pz, grad, full);
#endif
  (void)p;
  return kernel::generic::grad_block(W1p, b1p, W2p, b2p, W2tp, i, h, m, hs, me, tansig, X, T, nb,
                                     A, gH, nzp, gO, ha, V, ldv, pa, pe, pg, pz, grad, full);
}

// The padded weights of grad_block (grad_block_f32 in float) into Wp (hs i + hs + me h + me +
// hs m values, zeros first).
template <typename S>
inline void pad_weights(const Mlp<S>& net, const S* theta, Index hs, Index me, S* Wp) {
  const Index i = net.inputs(), h = net.hidden(), m = net.outputs();
  const S *W1 = theta, *b1 = theta + net.off_b1(), *W2 = theta + net.off_w2(),
          *b2 = theta + net.off_b2();
  S *W1p = Wp, *b1p = W1p + hs * i, *W2p = b1p + hs, *b2p = W2p + me * h, *W2tp = b2p + me;
  std::memset(Wp, 0, sizeof(S) * static_cast<size_t>(hs * i + hs + me * h + me + hs * m));
  for (Index l = 0; l < i; ++l)
    for (Index j = 0; j < h; ++j) W1p[l * hs + j] = W1[l * h + j];
  for (Index j = 0; j < h; ++j) b1p[j] = b1[j];
  for (Index j = 0; j < h; ++j)
    for (Index k = 0; k < m; ++k) {
      W2p[j * me + k] = W2[j * m + k];
      W2tp[k * hs + j] = W2[j * m + k];
    }
  for (Index k = 0; k < m; ++k) b2p[k] = b2[k];
}

// Cholesky factor in place (CDAM_CHOL_BODY): A (n x n, leading dimension ld, lower triangle
// read) becomes L in its lower triangle; the strict upper triangle is overwritten with scratch.
// Returns true when A is positive definite (every pivot > 0).
inline bool cholesky_lower(double* A, Index ld, Index n, KernelPath p = KernelPath::Auto) {
#if CDAM_HAVE_AVX2_CLONE
  if (avx2_path(p)) return kernel::avx2::cholesky_lower(A, ld, n) == 0;
#endif
  (void)p;
  return kernel::generic::cholesky_lower(A, ld, n) == 0;
}

// x = (L L')^-1 b in place, L from cholesky_lower.
inline void cholesky_solve(const double* L, Index ld, Index n, double* b,
                           KernelPath p = KernelPath::Auto) {
#if CDAM_HAVE_AVX2_CLONE
  if (avx2_path(p)) return kernel::avx2::cholesky_solve(L, ld, n, b);
#endif
  (void)p;
  kernel::generic::cholesky_solve(L, ld, n, b);
}

}  // namespace cdam::host
