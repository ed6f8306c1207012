// Smallest image with the model: startup + scaling + forward + back-scaling, nothing else. Its
// text/data/bss are the "model plus inference" figures.
#include "fw/model_runner.hpp"

volatile float g_in[fw::kIn];
volatile float g_out[fw::kOut];

int main() {
  for (;;) {
    float x[fw::kIn], y[fw::kOut];
    for (int k = 0; k < fw::kIn; ++k) x[k] = g_in[k];
    fw::predict(x, y);
    for (int k = 0; k < fw::kOut; ++k) g_out[k] = y[k];
  }
}
