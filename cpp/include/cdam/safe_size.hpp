// Checked integer arithmetic for sizes, lags and parameter counts (no exceptions, no heap, no
// compiler builtins: usable on the target and in constant expressions).
//
// Every size the core or the bindings derive from user input (t0 = max(na, nk + nb - 1), the
// regressor length na m + nb i, the parameter count D = i h + h + h m + m, N m, D^2, D n, ...)
// goes through these, so a huge lag or hidden size is reported instead of wrapping around and
// passing a later check (issue 24: `nk = 2**31 - 1` made t0 negative and the NARX kernel read
// before its array; `mlp_num_params(2**62, 8, 4)` returned 44).
//
//   checked_add(a, b, &r) / checked_mul(a, b, &r)   false on overflow (r untouched)
//   fits<To>(v)                                     v representable in To
//   round_saturate<Int>(x, lo, hi)                  float -> integer without undefined
//                                                   behaviour: NaN -> 0 (clamped into [lo, hi]),
//                                                   else x clamped to [lo, hi] and rounded half
//                                                   away from zero (the C610 current command,
//                                                   RK4 sub-step counts)
//   Checked<Int>                                    a value that remembers overflow through a
//                                                   chain of + and *: (Checked<Index>(i) * h + h
//                                                   + Checked<Index>(h) * m + m).ok()
#pragma once
#include <limits>
#include <type_traits>

#include "status.hpp"

namespace cdam {

// a + b without overflow into *out; false (and *out untouched) when it would overflow.
template <typename Int>
constexpr bool checked_add(Int a, Int b, Int* out) {
  static_assert(std::is_integral<Int>::value, "checked_add: integers only");
  using L = std::numeric_limits<Int>;
  if constexpr (std::is_signed<Int>::value) {
    if ((b > 0 && a > L::max() - b) || (b < 0 && a < L::min() - b)) return false;
  } else {
    if (a > L::max() - b) return false;
  }
  *out = static_cast<Int>(a + b);
  return true;
}

// a * b without overflow into *out; false (and *out untouched) when it would overflow.
template <typename Int>
constexpr bool checked_mul(Int a, Int b, Int* out) {
  static_assert(std::is_integral<Int>::value, "checked_mul: integers only");
  using L = std::numeric_limits<Int>;
  if (a != 0 && b != 0) {
    if constexpr (std::is_signed<Int>::value) {
      if (a > 0 ? (b > 0 ? a > L::max() / b : b < L::min() / a)
                : (b > 0 ? a < L::min() / b : (a == L::min() || b == L::min() || -a > L::max() / -b)))
        return false;
    } else {
      if (a > L::max() / b) return false;
    }
  }
  *out = static_cast<Int>(a * b);
  return true;
}

// v representable in To (both integral; signedness may differ).
template <typename To, typename From>
constexpr bool fits(From v) {
  static_assert(std::is_integral<To>::value && std::is_integral<From>::value, "fits: integers");
  using LT = std::numeric_limits<To>;
  if constexpr (std::is_signed<From>::value) {
    if (v < 0) {
      if constexpr (!std::is_signed<To>::value) return false;
      else return static_cast<long long>(v) >= static_cast<long long>(LT::min());
    }
  }
  return static_cast<unsigned long long>(v) <= static_cast<unsigned long long>(LT::max());
}

// x rounded half away from zero and saturated to [lo, hi] (lo <= hi, both exactly representable
// in Float); NaN gives 0 clamped into [lo, hi]. Never converts an out-of-range or NaN value.
template <typename Int, typename Float>
constexpr Int round_saturate(Float x, Int lo, Int hi) {
  static_assert(std::is_integral<Int>::value && std::is_floating_point<Float>::value,
                "round_saturate: float to integer");
  const Int zero = Int(0) < lo ? lo : (Int(0) > hi ? hi : Int(0));
  if (!(x == x)) return zero;  // NaN
  if (!(x > static_cast<Float>(lo))) return lo;
  if (!(x < static_cast<Float>(hi))) return hi;
  const Float r = x >= Float(0) ? x + Float(0.5) : x - Float(0.5);
  // |r| <= max(|lo|, |hi|) + 0.5 after the clamps; the truncating cast is in range unless r
  // rounds onto the bound itself, which the clamps below catch
  if (!(r < static_cast<Float>(hi))) return hi;
  if (!(r > static_cast<Float>(lo))) return lo;
  return static_cast<Int>(r);
}

// An integer that carries an overflow flag through + and *; once overflowed it stays so.
template <typename Int>
class Checked {
 public:
  constexpr Checked(Int v = 0) : v_(v) {}  // NOLINT: implicit on purpose (mixes with Int)
  constexpr bool ok() const { return ok_; }
  constexpr Int value() const { return v_; }  // meaningful only when ok()
  // *out = value() and Status::Ok, or Status::Overflow.
  constexpr Status get(Int* out) const {
    if (!ok_) return Status::Overflow;
    *out = v_;
    return Status::Ok;
  }

  friend constexpr Checked operator+(Checked a, Checked b) {
    Checked r;
    r.ok_ = a.ok_ && b.ok_ && checked_add(a.v_, b.v_, &r.v_);
    return r;
  }
  friend constexpr Checked operator*(Checked a, Checked b) {
    Checked r;
    r.ok_ = a.ok_ && b.ok_ && checked_mul(a.v_, b.v_, &r.v_);
    return r;
  }
  friend constexpr Checked operator-(Checked a, Checked b) {
    Checked r;
    if constexpr (std::is_signed<Int>::value) {
      r.ok_ = a.ok_ && b.ok_ && b.v_ != std::numeric_limits<Int>::min() &&
              checked_add(a.v_, static_cast<Int>(-b.v_), &r.v_);
    } else {
      r.ok_ = a.ok_ && b.ok_ && a.v_ >= b.v_;
      if (r.ok_) r.v_ = a.v_ - b.v_;
    }
    return r;
  }

 private:
  Int v_;
  bool ok_ = true;
};

}  // namespace cdam
