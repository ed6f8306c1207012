// Status codes returned by the core (the core never throws; bindings turn codes into errors).
#pragma once

namespace cdam {

enum class Status {
  Ok = 0,
  Empty,             // no samples, no channels or no parameters
  TooFewSamples,     // fewer samples than the algorithm needs (e.g. < 5 for smoothing)
  SizeMismatch,      // arrays that must agree in a dimension do not
  NonFinite,         // NaN or Inf in an input
  InvalidArgument,   // an argument outside its domain (negative passes, zero hidden nodes, ...)
  NotPositiveDefinite,  // a normal-equation matrix could not be factorised
  Overflow,          // a size, lag or count does not fit its integer type (safe_size.hpp)
  Diverged,          // an integration produced NaN or Inf from finite inputs
  Cancelled,         // a poll hook asked the loop to stop (e.g. Ctrl-C in Python)
};

// The default poll hook of long loops (passes, epochs, iterations): never stops them. A hook is
// any callable bool() returning false to stop; the loop then returns Status::Cancelled.
struct NeverCancel {
  constexpr bool operator()() const { return true; }
};

inline const char* to_string(Status s) {
  switch (s) {
    case Status::Ok: return "ok";
    case Status::Empty: return "empty input";
    case Status::TooFewSamples: return "too few samples";
    case Status::SizeMismatch: return "size mismatch";
    case Status::NonFinite: return "contains NaN or Inf";
    case Status::InvalidArgument: return "invalid argument";
    case Status::NotPositiveDefinite: return "matrix not positive definite";
    case Status::Overflow: return "size overflows";
    case Status::Diverged: return "diverged (NaN or Inf)";
    case Status::Cancelled: return "cancelled";
  }
  return "unknown status";
}

}  // namespace cdam
