// Smallest image with a dynamic model (arx, hybrid, greybox): startup + one step per loop on
// volatile inputs, nothing else. Its text/data/bss are the "model plus step" figures.
#include "fw/step_model.hpp"

volatile float g_in[fw::kU];
volatile float g_out[fw::kY];
fw::StepModel g_model;

int main() {
  for (;;) {
    float u[fw::kU], y[fw::kY];
    for (int k = 0; k < fw::kU; ++k) u[k] = g_in[k];
    g_model.step(u, y);
    for (int k = 0; k < fw::kY; ++k) g_out[k] = y[k];
  }
}
