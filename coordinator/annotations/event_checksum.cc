#include "coordinator/annotations/event_checksum.h"

namespace sandtable::coordinator {
namespace {

constexpr uint64_t kFnvPrime = 0x100000001b3ull;

uint64_t MixInteger(uint64_t state, uint64_t value) {
  for (int i = 0; i < 8; ++i) {
    state ^= (value >> (8 * i)) & 0xff;
    state *= kFnvPrime;
  }
  return state;
}

}  // namespace

uint64_t Fnv1a64(std::string_view bytes, uint64_t state) {
  for (unsigned char c : bytes) {
    state ^= c;
    state *= kFnvPrime;
  }
  return state;
}

uint64_t EventChecksum(int64_t sequence, int64_t time_ns, std::string_view kind,
                       std::string_view body) {
  uint64_t state = Fnv1a64({});
  state = MixInteger(state, static_cast<uint64_t>(sequence));
  state = MixInteger(state, static_cast<uint64_t>(time_ns));
  state = Fnv1a64(kind, state);
  state = Fnv1a64(std::string_view("\0", 1), state);
  return Fnv1a64(body, state);
}

}  // namespace sandtable::coordinator
