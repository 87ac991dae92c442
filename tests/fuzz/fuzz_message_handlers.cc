// libFuzzer target (clang -fsanitize=fuzzer) over the message handlers; see deploy/fuzz.sh.
#include "tests/fuzz/message_handlers.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static sandtable::fuzz::HandlerState* state = new sandtable::fuzz::HandlerState();
  sandtable::fuzz::HandleUntrustedMessage(data, size, state);
  return 0;
}
