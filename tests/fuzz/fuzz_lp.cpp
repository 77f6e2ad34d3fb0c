// libFuzzer target: the RTI .lp parser (ParseRtiLightsText: count line, entries, comments, CRLF,
// BOM, file names with spaces; docs/formats.md, "RTI captures"), no filesystem involved. Every
// input must keep the contract of parser_contract.h, including the write-back round trip. Seed
// corpus: corpus/fuzz_lp/; dictionary: fuzz_lp.dict.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "fuzz_check.h"
#include "parser_contract.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  digitize::fuzz::AbortUnless(digitize::fuzz::CheckLpText(text, digitize::fuzz::kLpSource));
  return 0;
}
