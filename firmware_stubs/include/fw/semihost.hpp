// ARM semihosting (bkpt 0xAB), heap-free: console text, host files and the exit code. Used by
// the check images under QEMU (-semihosting-config enable=on,target=native); a real board
// without a debugger attached must not call these (the loop image does not).
#pragma once
#include <cstddef>
#include <cstdint>

namespace fw::semihost {

enum Op : std::uint32_t {
  kOpen = 0x01, kClose = 0x02, kWrite0 = 0x04, kWrite = 0x05, kRead = 0x06, kExitExtended = 0x20
};

std::uint32_t call(std::uint32_t op, const void* arg);

inline void puts(const char* s) { call(kWrite0, s); }

// mode: 1 "rb", 5 "wb". Returns the handle or -1.
inline int open(const char* path, std::uint32_t mode) {
  std::size_t n = 0;
  while (path[n]) ++n;
  const std::uint32_t block[3] = {reinterpret_cast<std::uint32_t>(path), mode, n};
  return static_cast<int>(call(kOpen, block));
}
inline void close(int fd) {
  const std::uint32_t block[1] = {static_cast<std::uint32_t>(fd)};
  call(kClose, block);
}
// Bytes actually read / written.
inline std::size_t read(int fd, void* buf, std::size_t n) {
  const std::uint32_t block[3] = {static_cast<std::uint32_t>(fd),
                                  reinterpret_cast<std::uint32_t>(buf), n};
  return n - call(kRead, block);
}
inline std::size_t write(int fd, const void* buf, std::size_t n) {
  const std::uint32_t block[3] = {static_cast<std::uint32_t>(fd),
                                  reinterpret_cast<std::uint32_t>(buf), n};
  return n - call(kWrite, block);
}
[[noreturn]] void exit(int code);

// Decimal / hex text of integers for the console, no printf.
inline void put_uint(std::uint32_t v) {
  char buf[12];
  int k = 11;
  buf[k] = 0;
  do {
    buf[--k] = static_cast<char>('0' + v % 10);
    v /= 10;
  } while (v);
  puts(buf + k);
}
inline void put_hex(std::uint32_t v) {
  char buf[11] = "0x";
  for (int k = 0; k < 8; ++k) buf[2 + k] = "0123456789abcdef"[(v >> (28 - 4 * k)) & 0xF];
  buf[10] = 0;
  puts(buf);
}
// "key=value\n"
inline void kv(const char* key, std::uint32_t v, bool hex = false) {
  puts(key);
  puts("=");
  hex ? put_hex(v) : put_uint(v);
  puts("\n");
}

}  // namespace fw::semihost
