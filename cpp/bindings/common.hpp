// Shared helpers of the binding layer: dtype dispatch, shape and finiteness checks that raise
// ValueError naming the argument and the problem. The core never sees Python; only this layer
// turns cdam::Status into exceptions.
#pragma once
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <atomic>
#include <chrono>
#include <climits>
#include <cmath>
#include <string>

#include "cdam/activation.hpp"
#include "cdam/mlp.hpp"
#include "cdam/safe_size.hpp"
#include "cdam/status.hpp"

namespace cdam::bind {

namespace py = pybind11;

[[noreturn]] inline void value_error(const std::string& msg) { throw py::value_error(msg); }

inline void check_status(Status s, const std::string& what) {
  if (s != Status::Ok) value_error(what + ": " + to_string(s));
}

enum class Dtype { F32, F64 };

// float32 or float64 (by kind and size, not by the dtype object's identity: an unpickled
// array, a memmap or a dtype with metadata carries an equal but other object, and a
// non-native byte order is converted by c_array), else ValueError naming the argument.
inline Dtype float_dtype(const py::array& a, const char* name) {
  const py::dtype dt = a.dtype();
  if (dt.kind() == 'f' && dt.itemsize() == 8) return Dtype::F64;
  if (dt.kind() == 'f' && dt.itemsize() == 4) return Dtype::F32;
  value_error(std::string(name) + ": dtype " + std::string(py::str(dt)) +
              " is not supported; pass float32 or float64");
}

// A C-contiguous array of T (copying from Fortran order or strided views when needed).
template <typename T>
py::array_t<T, py::array::c_style> c_array(const py::array& a) {
  return py::array_t<T, py::array::c_style | py::array::forcecast>::ensure(a);
}

template <typename T>
void check_finite(const py::array_t<T, py::array::c_style>& a, const char* name) {
  const T* p = a.data();
  for (py::ssize_t k = 0, n = a.size(); k < n; ++k)
    if (!std::isfinite(p[k])) value_error(std::string(name) + ": contains NaN or Inf");
}

// A checked 2-D (samples x channels) array; cols < 0 means any number of columns.
template <typename T>
py::array_t<T, py::array::c_style> matrix(const py::array& a, const char* name, py::ssize_t cols = -1,
                                          py::ssize_t rows = -1) {
  if (a.ndim() != 2)
    value_error(std::string(name) + ": expected a 2-D array (samples x channels), got " +
                std::to_string(a.ndim()) + "-D");
  auto c = c_array<T>(a);
  if (c.shape(0) == 0 || c.shape(1) == 0) value_error(std::string(name) + ": empty array");
  if (cols >= 0 && c.shape(1) != cols)
    value_error(std::string(name) + ": expected " + std::to_string(cols) + " columns, got " +
                std::to_string(c.shape(1)));
  if (rows >= 0 && c.shape(0) != rows)
    value_error(std::string(name) + ": expected " + std::to_string(rows) + " rows (samples), got " +
                std::to_string(c.shape(0)));
  check_finite(c, name);
  return c;
}

template <typename T>
py::array_t<T, py::array::c_style> vector(const py::array& a, const char* name, py::ssize_t len = -1) {
  if (a.ndim() != 1) value_error(std::string(name) + ": expected a 1-D array");
  auto c = c_array<T>(a);
  if (c.shape(0) == 0) value_error(std::string(name) + ": empty array");
  if (len >= 0 && c.shape(0) != len)
    value_error(std::string(name) + ": expected length " + std::to_string(len) + ", got " +
                std::to_string(c.shape(0)));
  check_finite(c, name);
  return c;
}

inline Activation activation_from(const std::string& s) {
  if (s == "tansig" || s == "tanh") return Activation::Tansig;
  if (s == "logsig" || s == "sigmoid") return Activation::Logsig;
  value_error("activation: unknown '" + s + "'; use 'tansig' or 'logsig'");
}

inline void check_positive(long long v, const char* name) {
  if (v < 1) value_error(std::string(name) + ": must be at least 1, got " + std::to_string(v));
}

// An integer argument that the core takes as int (lags, passes, epochs, threads, ...): Python
// passes any 64-bit value; outside lo .. hi it is a ValueError naming the argument.
inline int int_arg(long long v, const char* name, long long lo = 0, long long hi = INT_MAX) {
  if (v < lo || v > hi)
    value_error(std::string(name) + ": must be in " + std::to_string(lo) + " .. " +
                std::to_string(hi) + ", got " + std::to_string(v));
  return static_cast<int>(v);
}

// The value of a checked size expression (safe_size.hpp), or ValueError "<what>: too large".
inline Index size_or_raise(const Checked<Index>& c, const std::string& what) {
  if (!c.ok()) value_error(what + ": too large (the size overflows 64-bit arithmetic)");
  return c.value();
}

// An array of `elements` values of T: elements * sizeof(T) must fit in Index, else ValueError.
template <typename T>
Index alloc_elements(const Checked<Index>& elements, const std::string& what) {
  size_or_raise(elements * Index(sizeof(T)), what);
  return elements.value();
}

// D = i h + h + h m + m of an i-h-m network, checked (each size >= 1, no overflow); the
// ValueError names the largest of the three sizes.
inline Index mlp_params_or_raise(long long i, long long h, long long m) {
  check_positive(i, "inputs");
  check_positive(h, "hidden");
  check_positive(m, "outputs");
  Index D = 0;
  if (mlp_num_params(i, h, m, &D) != Status::Ok) {
    const char* name = h >= i && h >= m ? "hidden" : (i >= m ? "inputs" : "outputs");
    value_error(std::string(name) + ": network too large (parameter count i h + h + h m + m "
                "overflows for i = " + std::to_string(i) + ", h = " + std::to_string(h) +
                ", m = " + std::to_string(m) + ")");
  }
  return D;
}

// The poll hook (cdam/status.hpp) of a long native loop running without the GIL: every
// `stride` calls, and at most every 20 ms, it re-acquires the GIL and runs Python's signal
// handlers (PyErr_CheckSignals). When a handler raises (Ctrl-C: KeyboardInterrupt) it returns
// false, the loop ends with Status::Cancelled, and raise_if_interrupted() (GIL held) re-raises
// the handler's exception, which stays set on this thread meanwhile.
//
// A loop running in a thread other than the main one never sees Ctrl-C (Python runs signal
// handlers in the main thread only). cancel_requested() is the process-wide request the main
// thread sets (_core.cancel_native_loops(), e.g. by `cdam batch` on Ctrl-C before it shuts
// its workers down): every hook then ends its loop without touching the GIL, and the call
// raises RuntimeError (a worker's task fails like any other; a KeyboardInterrupt would wedge
// it). So no worker thread is still inside native code, or waiting for the GIL, when the
// interpreter finalizes (a thread that takes the GIL during finalization is ended by
// pthread_exit, whose unwinding through the bindings' noexcept frames aborts the process).
// A loop also ends if the interpreter is already finalizing.
inline std::atomic<bool>& cancel_requested() {
  static std::atomic<bool> flag{false};
  return flag;
}

inline bool interpreter_finalizing() {
#if PY_VERSION_HEX >= 0x030D0000
  return Py_IsFinalizing() != 0;
#else
  return _Py_IsFinalizing() != 0;
#endif
}

class SignalPoll {
 public:
  explicit SignalPoll(long long stride = 1) : stride_(stride < 1 ? 1 : stride) {}
  bool operator()() {
    if (interrupted_) return false;
    if (cancel_requested().load(std::memory_order_relaxed)) {
      interrupted_ = requested_ = true;
      return false;
    }
    if (++calls_ < stride_) return true;
    calls_ = 0;
    const auto now = std::chrono::steady_clock::now();
    if (now - last_ < std::chrono::milliseconds(20)) return true;
    last_ = now;
    if (interpreter_finalizing()) {
      interrupted_ = requested_ = true;
      return false;
    }
    py::gil_scoped_acquire gil;
    if (PyErr_CheckSignals() != 0) interrupted_ = true;
    return !interrupted_;
  }
  bool interrupted() const { return interrupted_; }
  void raise_if_interrupted() const {
    if (!interrupted_) return;
    if (requested_ && !PyErr_Occurred())   // an ordinary exception: a task that failed
      PyErr_SetString(PyExc_RuntimeError, "cancelled: the native loop was asked to stop "
                      "(cancel_native_loops, or the interpreter is shutting down)");
    throw py::error_already_set();
  }
  // A copyable hook for the core's by-value Poll parameters.
  auto hook() {
    return [this] { return (*this)(); };
  }

 private:
  long long stride_, calls_ = 0;
  bool interrupted_ = false;
  bool requested_ = false;   // ended by cancel_requested() or finalization, not by a handler
  std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};

// Runs f.template operator()<T>() for the array's float dtype.
template <typename F>
auto dispatch(const py::array& a, const char* name, F&& f) {
  return float_dtype(a, name) == Dtype::F64 ? f(double{}) : f(float{});
}

}  // namespace cdam::bind
