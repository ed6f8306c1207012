// Bindings: the grey-box rollout (python/cdam_core/models/greybox/augmented.py). The model's
// accelerations arrive as a tape of operations recorded from its numpy equations
// (models/greybox/trace.py); this file evaluates the tape for every lane (window or parameter
// perturbation), sample, substep and stage: semi-implicit Euler (the model kind's integrator,
// as on the firmware) or classical Runge-Kutta 4 with the inputs held over the sample and the
// switching terms (sign and comparisons) evaluated once per step, at the step's start state,
// and held over its four stages (the zero-order hold of a switching term, as a firmware step
// takes it): RK4's stages would otherwise see -Fc, +Fc, -Fc, +Fc where the motion sticks and
// their weights 1, 2, 2, 1 cancel the dry friction. In RK4 the coordinates flagged `sticky`
// (a switching term jumps at their zero velocity: a dry friction) stick and slip as
// models/greybox/stickslip.py describes and computes (the same operations in the same order):
// a motion that would cross zero stops there, a coordinate at rest stays while its friction
// can hold it (Filippov's weights between the two one-sided fields) and breaks away otherwise.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <string>
#include <vector>

#include "common.hpp"

namespace py = pybind11;
using cdam::bind::value_error;

namespace {

// keep in the order of trace.OPS
enum Op : int {
  kC, kX, kV, kS, kT, kP, kAdd, kSub, kMul, kDiv, kNeg, kSign, kTanh, kSin, kCos, kAbs, kMax,
  kMin, kGt, kLt, kGe, kLe, kPow, kExp, kSqrt, kNumOps
};

inline void sin_cos(double x, double* s, double* c) {
#if defined(__GLIBC__)
  ::sincos(x, s, c);
#else
  *s = std::sin(x);
  *c = std::cos(x);
#endif
}

double sign_of(double x) { return x > 0 ? 1.0 : (x < 0 ? -1.0 : (x == 0 ? 0.0 : x)); }
double max_of(double a, double b) { return (a != a || b != b) ? NAN : (a >= b ? a : b); }
double min_of(double a, double b) { return (a != a || b != b) ? NAN : (a <= b ? a : b); }

struct Tape {
  const int* op;
  const int* a;
  const int* b;
  const double* c;
  int nodes;
  const int* out;   // equation error nodes, one per position
  int n;            // positions
  // sin and cos of one operand, evaluated together (sincos, the same values bit for bit in
  // glibc): trig[i] >= 0 at the first of the two names the second, -2 at the second (done)
  const int* trig;
};

constexpr int kChunk = 32;   // lanes evaluated together (inner loops over lanes)

// The one-sided limit of a velocity at rest (models/greybox/stickslip.py LIMIT): only the
// switching terms see its sign, every continuous term changes by ~1e-150 of its coefficient.
constexpr double kLimit = 1e-150;

bool switching(int op) { return op == kSign || op == kGt || op == kLt || op == kGe || op == kLe; }

enum Hold : int { kFree, kRecord, kReplay };

// Accelerations of a chunk of B lanes at (x, v) (structure of arrays: x[i * kChunk + l]).
// reg holds nodes x kChunk values; srow[l] the series row of lane l, th[l] its parameters and
// inv[l] its inertia inverse (n x n, row-major). hold: kRecord copies the switching nodes'
// values into held (nodes x kChunk), kReplay takes them from there instead of evaluating.
void accel(const Tape& tp, int B, const double* x, const double* v, const double* const* srow,
           const double* t, const double* const* th, const double* const* inv, double* reg,
           double* acc, Hold hold = kFree, double* held = nullptr) {
  for (int i = 0; i < tp.nodes; ++i) {
    double* y = reg + static_cast<std::size_t>(i) * kChunk;
    double* hy = held ? held + static_cast<std::size_t>(i) * kChunk : nullptr;
    if (hold == kReplay && switching(tp.op[i])) {
      for (int l = 0; l < B; ++l) y[l] = hy[l];
      continue;
    }
    const double* ra = tp.a[i] >= 0 ? reg + static_cast<std::size_t>(tp.a[i]) * kChunk : nullptr;
    const double* rb = tp.b[i] >= 0 ? reg + static_cast<std::size_t>(tp.b[i]) * kChunk : nullptr;
    const int ci = static_cast<int>(tp.c[i]);
    switch (tp.op[i]) {
      case kC: for (int l = 0; l < B; ++l) y[l] = tp.c[i]; break;
      case kX: for (int l = 0; l < B; ++l) y[l] = x[ci * kChunk + l]; break;
      case kV: for (int l = 0; l < B; ++l) y[l] = v[ci * kChunk + l]; break;
      case kS: for (int l = 0; l < B; ++l) y[l] = srow[l][ci]; break;
      case kT: for (int l = 0; l < B; ++l) y[l] = t[l]; break;
      case kP: for (int l = 0; l < B; ++l) y[l] = th[l][ci]; break;
      case kAdd: for (int l = 0; l < B; ++l) y[l] = ra[l] + rb[l]; break;
      case kSub: for (int l = 0; l < B; ++l) y[l] = ra[l] - rb[l]; break;
      case kMul: for (int l = 0; l < B; ++l) y[l] = ra[l] * rb[l]; break;
      case kDiv: for (int l = 0; l < B; ++l) y[l] = ra[l] / rb[l]; break;
      case kNeg: for (int l = 0; l < B; ++l) y[l] = -ra[l]; break;
      case kSign: for (int l = 0; l < B; ++l) y[l] = sign_of(ra[l]); break;
      case kTanh: for (int l = 0; l < B; ++l) y[l] = std::tanh(ra[l]); break;
      case kSin:
      case kCos:
        if (tp.trig[i] == -2) break;            // its pair's first node filled it
        if (tp.trig[i] >= 0) {
          double* y2 = reg + static_cast<std::size_t>(tp.trig[i]) * kChunk;
          double* ys = tp.op[i] == kSin ? y : y2;
          double* yc = tp.op[i] == kSin ? y2 : y;
          for (int l = 0; l < B; ++l) sin_cos(ra[l], ys + l, yc + l);
        } else if (tp.op[i] == kSin) {
          for (int l = 0; l < B; ++l) y[l] = std::sin(ra[l]);
        } else {
          for (int l = 0; l < B; ++l) y[l] = std::cos(ra[l]);
        }
        break;
      case kAbs: for (int l = 0; l < B; ++l) y[l] = std::fabs(ra[l]); break;
      case kMax: for (int l = 0; l < B; ++l) y[l] = max_of(ra[l], rb[l]); break;
      case kMin: for (int l = 0; l < B; ++l) y[l] = min_of(ra[l], rb[l]); break;
      case kGt: for (int l = 0; l < B; ++l) y[l] = ra[l] > rb[l] ? 1.0 : 0.0; break;
      case kLt: for (int l = 0; l < B; ++l) y[l] = ra[l] < rb[l] ? 1.0 : 0.0; break;
      case kGe: for (int l = 0; l < B; ++l) y[l] = ra[l] >= rb[l] ? 1.0 : 0.0; break;
      case kLe: for (int l = 0; l < B; ++l) y[l] = ra[l] <= rb[l] ? 1.0 : 0.0; break;
      case kPow: for (int l = 0; l < B; ++l) y[l] = std::pow(ra[l], rb[l]); break;
      case kExp: for (int l = 0; l < B; ++l) y[l] = std::exp(ra[l]); break;
      case kSqrt: for (int l = 0; l < B; ++l) y[l] = std::sqrt(ra[l]); break;
      default: for (int l = 0; l < B; ++l) y[l] = NAN;
    }
    if (hold == kRecord && switching(tp.op[i]))
      for (int l = 0; l < B; ++l) hy[l] = y[l];
  }
  const int n = tp.n;
  for (int i = 0; i < n; ++i)
    for (int l = 0; l < B; ++l) {
      double s = 0.0;
      for (int j = 0; j < n; ++j)
        s += inv[l][i * n + j] * reg[static_cast<std::size_t>(tp.out[j]) * kChunk + l];
      acc[i * kChunk + l] = s;
    }
}

}  // namespace

void register_greybox(py::module_& m) {
  m.attr("GREYBOX_TAPE_OPS") = static_cast<int>(kNumOps);
  m.attr("GREYBOX_STICK_SLIP") = 1;   // greybox_rollout takes `sticky` (stickslip.py)
  m.def(
      "greybox_rollout",
      [](py::array_t<int, py::array::c_style | py::array::forcecast> op,
         py::array_t<int, py::array::c_style | py::array::forcecast> a,
         py::array_t<int, py::array::c_style | py::array::forcecast> b,
         py::array_t<double, py::array::c_style | py::array::forcecast> c,
         py::array_t<int, py::array::c_style | py::array::forcecast> outputs,
         py::array_t<double, py::array::c_style | py::array::forcecast> series,
         py::array_t<double, py::array::c_style | py::array::forcecast> theta,
         py::array_t<double, py::array::c_style | py::array::forcecast> inverse,
         py::array_t<double, py::array::c_style | py::array::forcecast> x0,
         py::array_t<double, py::array::c_style | py::array::forcecast> v0,
         py::array_t<long long, py::array::c_style | py::array::forcecast> starts, long long steps,
         long long substeps, bool rk4, double dt, double t_start, bool path,
         py::array_t<int, py::array::c_style | py::array::forcecast> sticky) {
        const py::ssize_t nodes = op.size();
        if (nodes == 0 || a.size() != nodes || b.size() != nodes || c.size() != nodes)
          value_error("tape: op, a, b and c must be non-empty and of one length");
        if (x0.ndim() != 2 || v0.ndim() != 2 || x0.shape(0) != v0.shape(0) ||
            x0.shape(1) != v0.shape(1))
          value_error("x0, v0: expected two arrays of shape (lanes, positions)");
        const int L = static_cast<int>(x0.shape(0)), n = static_cast<int>(x0.shape(1));
        if (L < 1 || n < 1) value_error("x0: no lanes or no positions");
        if (outputs.size() != n) value_error("outputs: one equation per position expected");
        if (series.ndim() != 2 || series.shape(0) < 1) value_error("series: expected (rows, columns)");
        if (theta.ndim() != 2 || theta.shape(0) < 1 || L % theta.shape(0) != 0)
          value_error("theta: expected (groups, parameters) with lanes a multiple of groups");
        const int G = static_cast<int>(theta.shape(0)), P = static_cast<int>(theta.shape(1));
        if (inverse.ndim() != 3 || inverse.shape(0) != G || inverse.shape(1) != n ||
            inverse.shape(2) != n)
          value_error("inverse: expected (groups, positions, positions)");
        if (starts.size() != L) value_error("starts: one row per lane expected");
        if (sticky.size() != 0 && sticky.size() != n)
          value_error("sticky: one flag per position (or none) expected");
        std::vector<int> stick_at;   // the coordinates a dry friction can stop (stickslip.py)
        for (py::ssize_t q = 0; q < sticky.size(); ++q)
          if (sticky.data()[q]) stick_at.push_back(static_cast<int>(q));
        if (steps < 1 || substeps < 1 || substeps > 100000) value_error("steps/substeps: >= 1");
        if (!(dt > 0) || !std::isfinite(dt)) value_error("dt: must be positive and finite");
        const py::ssize_t N = series.shape(0), S = series.shape(1);
        const int* opp = op.data();
        const int* ap = a.data();
        const int* bp = b.data();
        const double* cp = c.data();
        for (py::ssize_t i = 0; i < nodes; ++i) {
          if (opp[i] < 0 || opp[i] >= kNumOps) value_error("tape: unknown operation");
          const bool leaf = opp[i] <= kP;
          if (!leaf && (ap[i] < 0 || ap[i] >= i || bp[i] >= i)) value_error("tape: bad operand");
          const double lim = opp[i] == kX || opp[i] == kV ? n : opp[i] == kS ? S : opp[i] == kP ? P : 1;
          if ((opp[i] == kX || opp[i] == kV || opp[i] == kS || opp[i] == kP) &&
              !(cp[i] >= 0 && cp[i] < lim))
            value_error("tape: leaf index out of range");
          if (opp[i] >= kAdd && opp[i] != kNeg && opp[i] < kNumOps && opp[i] != kSign &&
              opp[i] != kTanh && opp[i] != kSin && opp[i] != kCos && opp[i] != kAbs &&
              opp[i] != kExp && opp[i] != kSqrt && bp[i] < 0)
            value_error("tape: binary operation without a second operand");
        }
        for (py::ssize_t q = 0; q < n; ++q)
          if (outputs.data()[q] < 0 || outputs.data()[q] >= nodes) value_error("outputs: bad node");
        const long long* st = starts.data();
        for (int l = 0; l < L; ++l)
          if (st[l] < 0 || st[l] + steps > N) value_error("starts/steps: rows outside the series");
        std::vector<int> trig(static_cast<std::size_t>(nodes), -1);
        for (py::ssize_t i = 0; i < nodes; ++i) {
          if ((opp[i] != kSin && opp[i] != kCos) || trig[i] != -1) continue;
          const int want = opp[i] == kSin ? kCos : kSin;
          for (py::ssize_t j = i + 1; j < nodes; ++j)
            if (opp[j] == want && ap[j] == ap[i] && trig[j] == -1) {
              trig[i] = static_cast<int>(j);
              trig[j] = -2;
              break;
            }
        }
        const Tape tp{opp, ap, bp, cp, static_cast<int>(nodes), outputs.data(), n, trig.data()};
        const int per = L / G;
        py::array_t<double> result =
            path ? py::array_t<double>({static_cast<py::ssize_t>(steps), static_cast<py::ssize_t>(L),
                                        static_cast<py::ssize_t>(n)})
                 : py::array_t<double>({static_cast<py::ssize_t>(L), static_cast<py::ssize_t>(n)});
        double* res = result.mutable_data();
        const double* X0 = x0.data();
        const double* V0 = v0.data();
        const double* ser = series.data();
        const double h = dt / static_cast<double>(substeps);
        long long diverged = -1, limit = steps;   // the first step at which a lane diverged
        const std::size_t cn = static_cast<std::size_t>(n) * kChunk;
        const std::size_t nh = rk4 ? static_cast<std::size_t>(nodes) * kChunk : 0;
        std::vector<double> reg(static_cast<std::size_t>(nodes) * kChunk), held(nh),
            held_p(stick_at.empty() ? 0 : nh), held_m(stick_at.empty() ? 0 : nh);
        std::vector<double> x(cn), v(cn), xs(cn), vs(cn), k1(cn), k2(cn), k3(cn), k4(cn), l2(cn),
            l3(cn), tt(kChunk), x0s(cn), v0s(cn), side(cn), vp(cn), vm(cn), acc_p(cn),
            acc_m(cn), left(cn);
        std::vector<char> zero(cn), stuck(cn), crossed(cn), held0(cn);
        std::vector<double> lim_p(cn), lim_m(cn), lim_p0(cn), lim_m0(cn);
        std::vector<int> switch_nodes;
        for (int i = 0; i < static_cast<int>(nodes); ++i)
          if (switching(opp[i])) switch_nodes.push_back(i);
        std::vector<const double*> srow(kChunk), th(kChunk), inv(kChunk);
        for (int l0 = 0; l0 < L; l0 += kChunk) {
          const int B = std::min(kChunk, L - l0);
          for (int l = 0; l < B; ++l) {
            th[l] = theta.data() + ((l0 + l) / per) * P;
            inv[l] = inverse.data() + ((l0 + l) / per) * n * n;
            for (int i = 0; i < n; ++i) {
              x[i * kChunk + l] = X0[(l0 + l) * n + i];
              v[i * kChunk + l] = V0[(l0 + l) * n + i];
            }
          }
          for (long long j = 0; j < limit; ++j) {
            for (int l = 0; l < B; ++l) {
              const long long k = st[l0 + l] + j;
              srow[l] = ser + k * S;
              tt[l] = t_start + static_cast<double>(k) * dt;
            }
            // the first stage of a step whose coordinates in `zero` are at rest
            // (stickslip.start): accelerations into a1, the held switches interpolated,
            // stuck and side set; returns whether any coordinate sticks
            auto start = [&](const double* xx, double* a1) {
              bool stuck_any = false;
              vp = v;
              for (int i : stick_at)
                for (int l = 0; l < B; ++l)
                  if (zero[i * kChunk + l]) vp[i * kChunk + l] = kLimit;
              accel(tp, B, xx, vp.data(), srow.data(), tt.data(), th.data(), inv.data(),
                    reg.data(), acc_p.data(), kRecord, held_p.data());
              std::copy(acc_p.begin(), acc_p.end(), a1);
              for (int i : stick_at)
                for (int l = 0; l < B; ++l) {
                  const std::size_t q = i * kChunk + l;
                  lim_p[q] = zero[q] ? acc_p[q] : 0.0;
                  lim_m[q] = 0.0;
                }
              held = held_p;
              std::fill(stuck.begin(), stuck.end(), 0);
              for (int j : stick_at) {
                bool here = false;
                for (int l = 0; l < B; ++l) here = here || zero[j * kChunk + l];
                if (!here) continue;
                vm = vp;
                for (int l = 0; l < B; ++l)
                  if (zero[j * kChunk + l]) vm[j * kChunk + l] = -kLimit;
                accel(tp, B, xx, vm.data(), srow.data(), tt.data(), th.data(), inv.data(),
                      reg.data(), acc_m.data(), kRecord, held_m.data());
                for (int l = 0; l < B; ++l) {
                  const std::size_t qj = j * kChunk + l;
                  if (!zero[qj]) continue;
                  const double apj = acc_p[qj], amj = acc_m[qj];
                  const bool st = apj <= 0.0 && amj >= 0.0;
                  const double gap = amj - apj;
                  const double lam = gap > 0.0 ? amj / gap : 0.5;   // the + side's weight
                  const bool plus = apj + amj >= 0.0;
                  const double w = st ? 1.0 - lam : (plus ? 0.0 : 1.0);
                  for (int i = 0; i < n; ++i) {
                    const std::size_t q = i * kChunk + l;
                    a1[q] = a1[q] + w * (acc_m[q] - acc_p[q]);
                  }
                  for (int node : switch_nodes) {
                    const std::size_t q = static_cast<std::size_t>(node) * kChunk + l;
                    held[q] = held[q] + w * (held_m[q] - held_p[q]);
                  }
                  stuck[qj] = st;
                  lim_m[qj] = amj;
                  stuck_any = stuck_any || st;
                  side[qj] = st ? 0.0 : (plus ? 1.0 : -1.0);
                }
              }
              if (stuck_any)
                for (std::size_t q = 0; q < cn; ++q)
                  if (stuck[q]) a1[q] = 0.0;
              return stuck_any;
            };
            for (long long s = 0; s < substeps; ++s) {
              if (!rk4) {   // semi-implicit Euler: v += h a(x, v); x += h v
                accel(tp, B, x.data(), v.data(), srow.data(), tt.data(), th.data(), inv.data(),
                      reg.data(), k1.data());
                for (int i = 0; i < n; ++i)
                  for (int l = 0; l < B; ++l) {
                    const std::size_t q = i * kChunk + l;
                    v[q] = v[q] + h * k1[q];
                    x[q] = x[q] + h * v[q];
                  }
                continue;
              }
              // RK4 on (x, v)' = (v, a(x, v)), the inputs held over the sample, the switching
              // terms at the step's start state; coordinates at rest stick or break away
              // (models/greybox/stickslip.py: the same operations in the same order)
              bool any_zero = false, any_stuck = false;
              for (int i : stick_at)
                for (int l = 0; l < B; ++l) {
                  const std::size_t q = i * kChunk + l;
                  zero[q] = v[q] == 0.0;
                  any_zero = any_zero || zero[q];
                }
              x0s = x;
              v0s = v;
              for (std::size_t q = 0; q < cn; ++q)
                side[q] = v[q] > 0 ? 1.0 : (v[q] < 0 ? -1.0 : 0.0);
              if (!any_zero) {
                accel(tp, B, x.data(), v.data(), srow.data(), tt.data(), th.data(), inv.data(),
                      reg.data(), k1.data(), kRecord, held.data());
              } else {
                any_stuck = start(x.data(), k1.data());
              }
              for (std::size_t q = 0; q < cn; ++q) {
                xs[q] = x[q] + 0.5 * h * v[q];
                vs[q] = v[q] + 0.5 * h * k1[q];
              }
              l2 = vs;
              accel(tp, B, xs.data(), vs.data(), srow.data(), tt.data(), th.data(), inv.data(),
                    reg.data(), k2.data(), kReplay, held.data());
              if (any_stuck)
                for (std::size_t q = 0; q < cn; ++q)
                  if (stuck[q]) k2[q] = 0.0;
              for (std::size_t q = 0; q < cn; ++q) {
                xs[q] = x[q] + 0.5 * h * l2[q];
                vs[q] = v[q] + 0.5 * h * k2[q];
              }
              l3 = vs;
              accel(tp, B, xs.data(), vs.data(), srow.data(), tt.data(), th.data(), inv.data(),
                    reg.data(), k3.data(), kReplay, held.data());
              if (any_stuck)
                for (std::size_t q = 0; q < cn; ++q)
                  if (stuck[q]) k3[q] = 0.0;
              for (std::size_t q = 0; q < cn; ++q) {
                xs[q] = x[q] + h * l3[q];
                vs[q] = v[q] + h * k3[q];
              }
              accel(tp, B, xs.data(), vs.data(), srow.data(), tt.data(), th.data(), inv.data(),
                    reg.data(), k4.data(), kReplay, held.data());
              if (any_stuck)
                for (std::size_t q = 0; q < cn; ++q)
                  if (stuck[q]) k4[q] = 0.0;
              for (std::size_t q = 0; q < cn; ++q) {
                x[q] = x[q] + h / 6.0 * (v[q] + 2.0 * l2[q] + 2.0 * l3[q] + vs[q]);
                v[q] = v[q] + h / 6.0 * (k1[q] + 2.0 * k2[q] + 2.0 * k3[q] + k4[q]);
              }
              bool any_cross = false;   // a dry friction cannot reverse the motion
              for (std::size_t q = 0; q < cn; ++q) zero[q] = 0;
              for (int i : stick_at)
                for (int l = 0; l < B; ++l) {
                  const std::size_t q = i * kChunk + l;
                  if (side[q] * v[q] < 0.0) {   // stopped within the step (stickslip.stop)
                    const double gap = v0s[q] - v[q];
                    x[q] = x0s[q] + 0.5 * h * v0s[q] * v0s[q] / gap;
                    left[q] = -h * v[q] / gap;
                    v[q] = 0.0;
                    zero[q] = 1;
                    any_cross = true;
                  }
                }
              if (any_cross || any_stuck) {   // the step's end (stickslip.finish)
                crossed = zero;
                if (any_stuck)
                  held0 = stuck;
                else
                  std::fill(held0.begin(), held0.end(), 0);
                if (any_stuck) {
                  lim_p0 = lim_p;
                  lim_m0 = lim_m;
                }
                for (int i : stick_at)
                  for (int l = 0; l < B; ++l) {
                    const std::size_t q = i * kChunk + l;
                    zero[q] = crossed[q] || held0[q];
                  }
                start(x.data(), k2.data());
                for (int i : stick_at)
                  for (int l = 0; l < B; ++l) {
                    const std::size_t q = i * kChunk + l;
                    const double a = k2[q];
                    if (crossed[q]) {
                      x[q] = x[q] + 0.5 * a * left[q] * left[q];
                      v[q] = a * left[q];
                    } else if (held0[q] && !stuck[q]) {
                      const double a0 = side[q] > 0.0 ? lim_p0[q] : lim_m0[q];
                      const double tau = h * a / (a - a0);
                      x[q] = x[q] + a * tau * tau / 6.0;
                      v[q] = 0.5 * a * tau;
                    }
                  }
              }
            }
            for (int i = 0; i < n; ++i)
              for (int l = 0; l < B; ++l) {
                const double xi = x[i * kChunk + l];
                if (!std::isfinite(xi) || std::fabs(xi) > 1e9) limit = j;
                if (path) res[(j * L + l0 + l) * n + i] = xi;
              }
          }
          if (!path)
            for (int l = 0; l < B; ++l)
              for (int i = 0; i < n; ++i) res[(l0 + l) * n + i] = x[i * kChunk + l];
        }
        if (limit < steps) diverged = st[0] + limit + 1;
        return py::make_tuple(result, diverged);
      },
      py::arg("op"), py::arg("a"), py::arg("b"), py::arg("c"), py::arg("outputs"),
      py::arg("series"), py::arg("theta"), py::arg("inverse"), py::arg("x0"), py::arg("v0"),
      py::arg("starts"), py::arg("steps"), py::arg("substeps"), py::arg("rk4"), py::arg("dt"),
      py::arg("t_start"), py::arg("path"), py::arg("sticky") = py::array_t<int>(0),
      "Integrate a grey-box model given as a tape (models/greybox/trace.py) over every lane "
      "(rk4: the switching nodes, sign and comparisons, held over each step's stages; the "
      "coordinates flagged in `sticky` stick and slip, models/greybox/stickslip.py); "
      "returns (positions, diverged row or -1): (steps, lanes, positions) with path, else "
      "(lanes, positions).");
}
