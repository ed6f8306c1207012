// Smallest image with a dynamic model (arx, hybrid, greybox): startup + one step per loop on
// volatile inputs (and the residual monitor with a correct, when the model file has one), the
// measured row observed (fw::StepModel::observe: arm_coupling's columns), nothing else. Its
// text/data/bss are the "model plus step" figures.
#include "fw/step_model.hpp"
#include "fw/monitor.hpp"

volatile float g_in[fw::kU];
volatile float g_out[fw::kY];
fw::StepModel g_model;
volatile float g_meas[fw::kY];   // the measured row (fw::StepModel::observe, every kind)
#if CDAM_MODEL_HAS_MONITOR   // with the residual monitor: step, monitor, correct each row
volatile std::uint8_t g_flags[fw::kY];
fw::Monitor<fw::kY> g_monitor;
#endif

int main() {
  for (;;) {
    float u[fw::kU], y[fw::kY];
    for (int k = 0; k < fw::kU; ++k) u[k] = g_in[k];
    g_model.step(u, y);
    for (int k = 0; k < fw::kY; ++k) g_out[k] = y[k];
    float ym[fw::kY];
    for (int k = 0; k < fw::kY; ++k) ym[k] = g_meas[k];
#if CDAM_MODEL_HAS_MONITOR
    std::uint8_t flags[fw::kY];
    g_monitor.update(ym, y, flags);
    for (int k = 0; k < fw::kY; ++k) g_flags[k] = flags[k];
    g_model.correct(ym);
#endif
    g_model.observe(ym);
  }
}
