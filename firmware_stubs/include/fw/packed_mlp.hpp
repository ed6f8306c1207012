// The BP network's inference on the target, laid out for the Cortex-M4F's FPU.
//
// Layout (built at compile time from theta = [W1(:); b1; W2(:); b2], MATLAB column-major, by
// pack_mlp): b2 (O values), then one block per hidden unit j of 1 + I + O values:
// [b1_j, W1(j, 0..I-1), W2(0..O-1, j)]. One pass over the weights in storage order computes
// n_j = b1_j + W1(j, :) x (a chain of fused multiply-adds), a_j = tanh(n_j), and adds W2(:, j) a_j
// to the O output accumulators; the hidden activations are never stored.
//
// A logsig network is folded into the same tansig kernel: logsig(n) = (1 + tanh(n / 2)) / 2, so
// b1 and W1 are halved (exact in binary floating point), W2 is halved and b2 gains
// sum_j W2(:, j) / 2 (rounded once to float).
//
// forward_packed is plain C++ (any target, the host tests). On a Cortex-M4F (ARMv7E-M with the
// single-precision FPU and VFMA) with I <= 8 and O <= 8 the same arithmetic runs as one inline
// assembly block: the inputs in s24.., the output accumulators in s16.., each block and the
// tanh coefficients brought in by one VLDM each, every multiply-add one VFMA, the tanh
// (cdam/fast_math.hpp's rational, same coefficients and operation order) with its saturation
// test as one compare, a flag transfer and a branch. No heap, no libm, no table besides the
// weights and the 12 tanh constants.
#pragma once

#include "cdam/fast_math.hpp"

namespace fw {

// The tanh constants in the order the kernel loads them into s2..s13: P (7), Q (4), clamp^2.
constexpr float kTanhTable[12] = {
    cdam::kTanhP[0], cdam::kTanhP[1], cdam::kTanhP[2], cdam::kTanhP[3], cdam::kTanhP[4],
    cdam::kTanhP[5], cdam::kTanhP[6], cdam::kTanhQ[0], cdam::kTanhQ[1], cdam::kTanhQ[2],
    cdam::kTanhQ[3], cdam::kTanhClamp * cdam::kTanhClamp};

template <int I, int H, int O>
struct PackedMlp {
  static constexpr int kBlock = 1 + I + O;
  static constexpr int kSize = O + H * kBlock;
  static constexpr int kParams = I * H + H + H * O + O;
  float tanh[12];   // kTanhTable (below), beside the weights: the kernel needs no other address
  float w[kSize];
};

// Value idx (0 .. kSize-1) of the packed layout of theta (kParams values, MATLAB order);
// logsig: fold the logistic activation (see top).
template <int I, int H, int O>
constexpr float packed_value(const float* theta, bool logsig, int idx) {
  constexpr int w2 = I * H + H, b2 = w2 + H * O, B = PackedMlp<I, H, O>::kBlock;
  if (idx < O) {
    double b = theta[b2 + idx];
    if (logsig)
      for (int j = 0; j < H; ++j) b += 0.5 * double(theta[w2 + j * O + idx]);
    return static_cast<float>(b);
  }
  const int j = (idx - O) / B, r = (idx - O) % B;
  const float v = r == 0 ? theta[I * H + j]                      // b1_j
                  : r <= I ? theta[(r - 1) * H + j]              // W1(j, r - 1)
                           : theta[w2 + j * O + (r - 1 - I)];    // W2(r - 1 - I, j)
  return logsig ? 0.5f * v : v;
}

template <int I, int H, int O>
constexpr PackedMlp<I, H, O> pack_mlp(const float* theta, bool logsig) {
  PackedMlp<I, H, O> p{};
  for (int k = 0; k < 12; ++k) p.tanh[k] = kTanhTable[k];
  for (int k = 0; k < PackedMlp<I, H, O>::kSize; ++k)
    p.w[k] = packed_value<I, H, O>(theta, logsig, k);
  return p;
}

// True when p holds the packed layout of theta (a run-time check of the copy in flash).
template <int I, int H, int O>
inline bool packed_matches(const PackedMlp<I, H, O>& p, const float* theta, bool logsig) {
  const volatile float* w = p.w;
  const volatile float* t = p.tanh;
  for (int k = 0; k < 12; ++k)
    if (t[k] != kTanhTable[k]) return false;
  for (int k = 0; k < PackedMlp<I, H, O>::kSize; ++k)
    if (w[k] != packed_value<I, H, O>(theta, logsig, k)) return false;
  return true;
}

// Portable forward over the packed weights: x (I values) -> y (O values).
template <int I, int H, int O>
inline void forward_packed_portable(const PackedMlp<I, H, O>& p, const float* x, float* y) {
  for (int k = 0; k < O; ++k) y[k] = p.w[k];
  const float* blk = p.w + O;
  for (int j = 0; j < H; ++j, blk += PackedMlp<I, H, O>::kBlock) {
    float n = blk[0];
    for (int l = 0; l < I; ++l) n += blk[1 + l] * x[l];
    const float a = cdam::fast_tanh(n);
    for (int k = 0; k < O; ++k) y[k] += blk[1 + I + k] * a;
  }
}

#if defined(__ARM_ARCH_7EM__) && defined(__ARM_FP) && (__ARM_FP & 4) && \
    defined(__ARM_FEATURE_FMA) && defined(__thumb2__)
#define CDAM_FW_M4F_KERNEL 1

// Up to 8 of each operation, kept by .if on the sizes (the assembler sees plain numbers).
#define CDAM_M4F_FMA_IN(l, w, xr) ".if %c[ni] > " #l "\n vfma.f32 s0, s" #w ", s" #xr "\n.endif\n"
#define CDAM_M4F_FMA_OUT(k, yr, w) ".if %c[no] > " #k "\n vfma.f32 s" #yr ", s" #w ", s0\n.endif\n"

// Not inlined: GCC sizes an asm statement by its lines, not by its .rept expansion, and would
// place literal pools and branches of a caller out of reach; this function uses none.
template <int I, int H, int O>
[[gnu::noinline]] void forward_packed_m4f(const PackedMlp<I, H, O>& p, const float* x, float* y) {
  static_assert(I >= 1 && I <= 8 && O >= 1 && O <= 8 && H >= 1, "kernel sizes");
  const float* w = p.w;
  __asm__ volatile(
      "vldmia %[x], {s24-s%c[xl]}\n"          // inputs
      "vldmia %[w]!, {s16-s%c[yl]}\n"         // accumulators = b2
      ".rept %c[nh]\n"
      "vldmia %[w]!, {s0-s%c[ni]}\n"          // b1_j, W1(j, :)
      CDAM_M4F_FMA_IN(0, 1, 24) CDAM_M4F_FMA_IN(1, 2, 25) CDAM_M4F_FMA_IN(2, 3, 26)
      CDAM_M4F_FMA_IN(3, 4, 27) CDAM_M4F_FMA_IN(4, 5, 28) CDAM_M4F_FMA_IN(5, 6, 29)
      CDAM_M4F_FMA_IN(6, 7, 30) CDAM_M4F_FMA_IN(7, 8, 31)
      // tanh(s0): x^2, the constants, the saturation test
      "vmul.f32 s1, s0, s0\n"
      "vldmia %[c], {s2-s13}\n"
      "vcmp.f32 s1, s13\n"
      "vmrs APSR_nzcv, fpscr\n"
      "ble 1f\n"
      "vcmp.f32 s0, #0\n"                     // |x| > clamp: +-1
      "vmrs APSR_nzcv, fpscr\n"
      "vmov.f32 s0, #1.0\n"
      "it lt\n"
      "vmovlt.f32 s0, #-1.0\n"
      "b 2f\n"
      "1:\n"
      "vfma.f32 s7, s1, s8\n"                 // P(x^2), Horner
      "vfma.f32 s6, s1, s7\n"
      "vfma.f32 s5, s1, s6\n"
      "vfma.f32 s4, s1, s5\n"
      "vfma.f32 s3, s1, s4\n"
      "vfma.f32 s2, s1, s3\n"
      "vmul.f32 s2, s0, s2\n"                 // x P
      "vfma.f32 s11, s1, s12\n"               // Q(x^2)
      "vfma.f32 s10, s1, s11\n"
      "vfma.f32 s9, s1, s10\n"
      "vdiv.f32 s0, s2, s9\n"
      "2:\n"
      "vldmia %[w]!, {s1-s%c[no]}\n"          // W2(:, j)
      CDAM_M4F_FMA_OUT(0, 16, 1) CDAM_M4F_FMA_OUT(1, 17, 2) CDAM_M4F_FMA_OUT(2, 18, 3)
      CDAM_M4F_FMA_OUT(3, 19, 4) CDAM_M4F_FMA_OUT(4, 20, 5) CDAM_M4F_FMA_OUT(5, 21, 6)
      CDAM_M4F_FMA_OUT(6, 22, 7) CDAM_M4F_FMA_OUT(7, 23, 8)
      ".endr\n"
      "vstmia %[y], {s16-s%c[yl]}\n"
      : [w] "+r"(w)
      : [x] "r"(x), [y] "r"(y), [c] "r"(p.tanh), [ni] "i"(I), [no] "i"(O), [nh] "i"(H),
        [xl] "i"(23 + I), [yl] "i"(15 + O)
      : "s0", "s1", "s2", "s3", "s4", "s5", "s6", "s7", "s8", "s9", "s10", "s11", "s12", "s13",
        "s14", "s15", "s16", "s17", "s18", "s19", "s20", "s21", "s22", "s23", "s24", "s25", "s26",
        "s27", "s28", "s29", "s30", "s31", "cc", "memory");
}
#undef CDAM_M4F_FMA_IN
#undef CDAM_M4F_FMA_OUT
#endif

template <int I, int H, int O>
inline void forward_packed(const PackedMlp<I, H, O>& p, const float* x, float* y) {
#ifdef CDAM_FW_M4F_KERNEL
  if constexpr (I <= 8 && O <= 8) {
    forward_packed_m4f(p, x, y);
    return;
  }
#endif
  forward_packed_portable(p, x, y);
}

}  // namespace fw
