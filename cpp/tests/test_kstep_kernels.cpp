// C++ tests of the k-step rollout's sensitivity product (cdam/host/kstep_kernels.hpp): both
// compiled paths against Eigen's product on odd sizes (rows not a multiple of the 8-row tile,
// 1..5 columns: every remainder branch), with leading dimensions larger than the rows, in the
// overwrite and the accumulate mode.
#include <doctest/doctest.h>

#include <Eigen/Core>

#include "cdam/host/kstep_kernels.hpp"
#include "cdam/rng.hpp"

using namespace cdam;
using cdam::host::KernelPath;
using cdam::host::sensitivity_product;

TEST_CASE("sensitivity_product equals Eigen's G (+)= X M^T on odd sizes and both paths") {
  for (Index R : {1, 3, 4, 7, 8, 13, 357})
    for (Index C : {1, 2, 3, 4, 5, 13})
      for (Index S : {1, 3, 13})
        for (bool add : {false, true})
          for (KernelPath p : {KernelPath::Auto, KernelPath::Generic}) {
            Rng rng(static_cast<std::uint32_t>(R * 10000 + C * 100 + S));
            const Index ldx = R + 3, ldg = R + 1, ldm = S + 2;
            Eigen::MatrixXd X(ldx, S), G0(ldg, C);
            for (Index k = 0; k < X.size(); ++k) X.data()[k] = rng.uniform(-2.0, 2.0);
            for (Index k = 0; k < G0.size(); ++k) G0.data()[k] = rng.uniform(-1.0, 1.0);
            // M(c, s) at M[c ldm + s]: a row-major C x S block inside rows of ldm values
            Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> Mr(C, ldm);
            for (Index k = 0; k < Mr.size(); ++k) Mr.data()[k] = rng.uniform(-1.0, 1.0);
            Eigen::MatrixXd expect = X.topRows(R) * Mr.leftCols(S).transpose();
            if (add) expect += G0.topRows(R);
            Eigen::MatrixXd G = G0;
            sensitivity_product(G.data(), ldg, X.data(), ldx, Mr.data(), ldm, R, C, S, add, p);
            for (Index c = 0; c < C; ++c) {
              for (Index r = 0; r < R; ++r)
                REQUIRE(G(r, c) == doctest::Approx(expect(r, c)).epsilon(1e-14).scale(4.0 * S));
              CHECK(G(R, c) == G0(R, c));   // the row past R (padding) untouched
            }
          }
}
