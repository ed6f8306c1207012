// Must NOT link: the heap guard (--wrap=malloc with no __wrap_malloc) turns this into an
// undefined reference. Built only on demand (target fw_heap_probe.elf) by the tests.
#include <cstdlib>

int main() {
  void* volatile p = std::malloc(16);
  std::free(p);
  return 0;
}
