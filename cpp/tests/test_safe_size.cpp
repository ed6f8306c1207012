// Checked size arithmetic (cdam/safe_size.hpp) and its users at the limits: the NARX orders
// (t0, regressor length) and the network's parameter count. Expected results come from exact
// 128-bit arithmetic (__int128, independent of the helper) or from the closed forms.
#include <doctest/doctest.h>

#include <climits>
#include <cmath>
#include <cstdint>
#include <limits>

#include "cdam/mlp.hpp"
#include "cdam/narx.hpp"
#include "cdam/safe_size.hpp"

using namespace cdam;

namespace {

using I128 = __int128;

template <typename Int>
bool in_range(I128 v) {
  return v >= static_cast<I128>(std::numeric_limits<Int>::min()) &&
         v <= static_cast<I128>(std::numeric_limits<Int>::max());
}

// Edge values of a signed type: 0, +-1, +-2, the extremes and their neighbours, sqrt(max).
template <typename Int>
void edge_values(Int* v, int* n) {
  using L = std::numeric_limits<Int>;
  const Int r = static_cast<Int>(std::sqrt(static_cast<double>(L::max())));
  const Int vals[] = {0, 1, -1, 2, -2, 3, r, static_cast<Int>(r + 1), static_cast<Int>(-r),
                      static_cast<Int>(-r - 1), L::max(), static_cast<Int>(L::max() - 1),
                      L::min(), static_cast<Int>(L::min() + 1), static_cast<Int>(L::max() / 2),
                      static_cast<Int>(L::min() / 2)};
  *n = 0;
  for (Int x : vals) v[(*n)++] = x;
}

template <typename Int>
void check_all_pairs() {
  Int v[32];
  int n = 0;
  edge_values(v, &n);
  for (int a = 0; a < n; ++a)
    for (int b = 0; b < n; ++b) {
      const I128 sum = static_cast<I128>(v[a]) + v[b], prod = static_cast<I128>(v[a]) * v[b];
      Int out = 7;
      CHECK(checked_add(v[a], v[b], &out) == in_range<Int>(sum));
      if (in_range<Int>(sum)) CHECK(static_cast<I128>(out) == sum);
      out = 7;
      const bool ok = checked_mul(v[a], v[b], &out);
      CHECK(ok == in_range<Int>(prod));
      if (ok) CHECK(static_cast<I128>(out) == prod);
      else CHECK(out == 7);  // untouched on overflow
    }
}

}  // namespace

TEST_CASE("safe_size: checked add and mul agree with exact 128-bit arithmetic at the limits") {
  check_all_pairs<int>();
  check_all_pairs<long long>();
  check_all_pairs<std::int16_t>();
  std::uint32_t u = 0;
  CHECK(checked_add<std::uint32_t>(0xFFFFFFFFu, 0u, &u));
  CHECK_FALSE(checked_add<std::uint32_t>(0xFFFFFFFFu, 1u, &u));
  CHECK(checked_mul<std::uint32_t>(0x10000u, 0xFFFFu, &u));
  CHECK(u == 0xFFFF0000u);
  CHECK_FALSE(checked_mul<std::uint32_t>(0x10000u, 0x10000u, &u));
}

TEST_CASE("safe_size: fits and Checked chains") {
  CHECK(fits<int>(static_cast<long long>(INT_MAX)));
  CHECK_FALSE(fits<int>(static_cast<long long>(INT_MAX) + 1));
  CHECK(fits<int>(static_cast<long long>(INT_MIN)));
  CHECK_FALSE(fits<int>(static_cast<long long>(INT_MIN) - 1));
  CHECK_FALSE(fits<std::uint32_t>(-1));
  CHECK(fits<std::uint32_t>(4294967295LL));
  CHECK_FALSE(fits<std::uint32_t>(4294967296LL));
  CHECK_FALSE(fits<int>(std::numeric_limits<unsigned long long>::max()));
  // INT_MAX + 1 - 1 overflows on the way, even though the end value would fit
  CHECK_FALSE((Checked<int>(INT_MAX) + 1 - 1).ok());
  CHECK((Checked<int>(INT_MAX) - 1 + 1).ok());
  CHECK((Checked<int>(INT_MAX) - 1 + 1).value() == INT_MAX);
  CHECK_FALSE((Checked<int>(INT_MIN) - 1).ok());
  CHECK_FALSE((Checked<int>(0) - INT_MIN).ok());
  long long out = 0;
  CHECK((Checked<long long>(3) * 4 + 5).get(&out) == Status::Ok);
  CHECK(out == 17);
  CHECK((Checked<long long>(LLONG_MAX) * 2 + 0).get(&out) == Status::Overflow);
  CHECK(out == 17);
  static_assert((Checked<int>(46340) * 46340).ok(), "46340^2 < 2^31");
  static_assert(!(Checked<int>(46341) * 46341).ok(), "46341^2 > 2^31 - 1");
}

TEST_CASE("safe_size: round_saturate never converts NaN or an out-of-range float") {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  using I16 = std::int16_t;
  CHECK(round_saturate<I16>(nan, I16(-10000), I16(10000)) == 0);
  CHECK(round_saturate<I16>(inf, I16(-10000), I16(10000)) == 10000);
  CHECK(round_saturate<I16>(-inf, I16(-10000), I16(10000)) == -10000);
  CHECK(round_saturate<I16>(1e30f, I16(-10000), I16(10000)) == 10000);
  CHECK(round_saturate<I16>(-1e30f, I16(-10000), I16(10000)) == -10000);
  CHECK(round_saturate<I16>(9999.6f, I16(-10000), I16(10000)) == 10000);
  CHECK(round_saturate<I16>(2.5f, I16(-10000), I16(10000)) == 3);    // half away from zero
  CHECK(round_saturate<I16>(-2.5f, I16(-10000), I16(10000)) == -3);
  CHECK(round_saturate<I16>(2.49f, I16(-10000), I16(10000)) == 2);
  CHECK(round_saturate<I16>(-0.4f, I16(-10000), I16(10000)) == 0);
  CHECK(round_saturate<int>(nan, 1, INT_MAX) == 1);  // NaN -> 0, clamped into [1, max]
  CHECK(round_saturate<int>(1e300, 1, INT_MAX) == INT_MAX);
  CHECK(round_saturate<int>(static_cast<double>(INT_MAX) - 0.4, 1, INT_MAX) == INT_MAX);
  CHECK(round_saturate<int>(3.0, 1, INT_MAX) == 3);
}

TEST_CASE("NARX orders: t0 and the regressor length are checked at INT_MAX") {
  // the case: na = 1, nb = 2, nk = 2^31 - 1 (nk + nb - 1 = 2^31 wrapped to INT_MIN)
  CHECK(NarxOrders{1, 2, INT_MAX}.check() == Status::Overflow);
  CHECK(NarxOrders{0, INT_MAX, 2}.check() == Status::Overflow);
  // the largest representable t0: nk + nb - 1 = INT_MAX exactly
  const NarxOrders edge{1, 1, INT_MAX};
  REQUIRE(edge.check() == Status::Ok);
  CHECK(edge.t0() == INT_MAX);
  REQUIRE(NarxOrders{INT_MAX, 0, INT_MAX}.check() == Status::Ok);  // nb = 0: t0 = na
  CHECK(NarxOrders{INT_MAX, 0, INT_MAX}.t0() == INT_MAX);
  CHECK(NarxOrders{-1, 1, 0}.check() == Status::InvalidArgument);
  CHECK(NarxOrders{0, 0, 5}.check() == Status::InvalidArgument);
  // na m + nb i in Index: INT_MAX * 2^33 overflows 63 bits, INT_MAX * 2^32 does not
  const NarxOrders big{INT_MAX, INT_MAX, 0};
  CHECK(big.check(1, 1) == Status::Ok);
  CHECK(big.regressors(1, 1) == 2 * static_cast<Index>(INT_MAX));
  CHECK(big.check(Index(1) << 32, 0) == Status::Ok);
  CHECK(big.check(Index(1) << 33, 0) == Status::Overflow);
  CHECK(big.check(0, Index(1) << 33) == Status::Overflow);
  // and the kernels refuse them before reading anything
  double u[4] = {0, 1, 2, 3}, y[4] = {0, 1, 2, 3}, x[64];
  CHECK(narx_regressors(u, 1, y, 1, 4, NarxOrders{1, 2, INT_MAX}, x) == Status::Overflow);
  CHECK(narx_regressors(u, 1, y, 1, 4, edge, x) == Status::TooFewSamples);
}

TEST_CASE("mlp_num_params: D = i h + h + h m + m, checked") {
  Index D = 0;
  REQUIRE(mlp_num_params(6, 20, 8, &D) == Status::Ok);
  CHECK(D == 6 * 20 + 20 + 20 * 8 + 8);
  CHECK(mlp_num_params(0, 20, 8, &D) == Status::InvalidArgument);
  CHECK(mlp_num_params(6, -1, 8, &D) == Status::InvalidArgument);
  // the case: i = 2^62, h = 8, m = 4 wrapped to 44
  CHECK(mlp_num_params(Index(1) << 62, 8, 4, &D) == Status::Overflow);
  // the exact border: (i + 1 + m) h + m = 2^63 - 1 fits, one more hidden node does not
  const I128 lim = static_cast<I128>(std::numeric_limits<Index>::max());
  const Index h = Index(1) << 40, m = 1;
  const Index i = static_cast<Index>((lim - m) / h) - 1 - m;  // largest i with D <= max
  REQUIRE(mlp_num_params(i, h, m, &D) == Status::Ok);
  CHECK(static_cast<I128>(D) == static_cast<I128>(i) * h + h + static_cast<I128>(h) * m + m);
  CHECK(mlp_num_params(i + 1, h, m, &D) == Status::Overflow);
}
